"""The best-model choice at every allowance (ValidationCallback's ``allowances``)."""

from __future__ import annotations

import pytest
import yaml

pytest.importorskip("stable_baselines3")

from agents.rl.callbacks import ValidationCallback, selection_score  # noqa: E402
from machining_envs.core.score import PrimaryScore  # noqa: E402

SCORE = PrimaryScore("machining_time_s", "time (s)")


def _row(t, over):
    return {"machining_time_s": t, "time_over_limit": over, "finished": 1.0, "overloaded": 0.0}


def test_an_episode_over_the_strict_allowance_is_charged_the_failure_there_only():
    rows = [_row(10.0, 0.0), _row(20.0, 0.007)]  # the second counts at 1 % and 2 %, not 0.5 %
    failed = 100.0
    # 0.5 %: (10 + 100) / 2; 1 % and 2 %: (10 + 20) / 2
    want = (55.0 + 15.0 + 15.0) / 3
    assert selection_score(rows, SCORE, failed, [0.005, 0.01, 0.02]) == pytest.approx(want)
    assert selection_score(rows, SCORE, failed, [0.02]) == pytest.approx(15.0)


@pytest.mark.parametrize("bad", [[], [0.0], [1.0], [0.01, "x"], 0.01, [True]])
def test_bad_allowances_are_refused_naming_them(bad):
    with pytest.raises(ValueError, match="allowances"):
        ValidationCallback(allowances=bad)


def test_a_training_configuration_carries_them_to_the_run(tmp_path):
    from agents.rl.config import ConfigError, load_config

    env_id, path = "machining_envs/Turning-v0", tmp_path / "ppo.yml"

    def entry(allowances):
        cb = {"agents.rl.callbacks.ValidationCallback": {"allowances": allowances}}
        path.write_text(yaml.safe_dump({env_id: {"n_timesteps": 1000, "callback": [cb]}}))
        return path

    cfg = load_config(env_id, "ppo", entry([0.005, 0.01, 0.02]))
    assert cfg.eval_allowances == [0.005, 0.01, 0.02]
    assert load_config(env_id, "ppo", None).eval_allowances is None
    with pytest.raises(ConfigError, match="allowances"):
        load_config(env_id, "ppo", entry(2))


@pytest.mark.parametrize("bad", [-1, 4981, 2.5, True, "100"])
def test_a_first_episode_outside_the_split_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match=r"first_episode must be an integer in \[0, 4980\]"):
        ValidationCallback(n_episodes=20, first_episode=bad)


def test_the_choice_can_use_validation_episodes_apart_from_the_first(tmp_path):
    from agents import ConstantFeed
    from agents.eval.harness import evaluate_validation
    from agents.rl.config import load_config

    assert ValidationCallback(n_episodes=50, first_episode=100).first_episode == 100
    assert ValidationCallback(first_episode=100.0).first_episode == 100  # YAML's 1e2
    env_id, path = "machining_envs/Turning-v0", tmp_path / "ppo.yml"
    cb = {"agents.rl.callbacks.ValidationCallback": {"n_episodes": 5, "first_episode": 100}}
    path.write_text(yaml.safe_dump({env_id: {"n_timesteps": 1000, "callback": [cb]}}))
    assert load_config(env_id, "ppo", path).eval_first_episode == 100
    assert load_config(env_id, "ppo", None).eval_first_episode == 0
    # episodes 3 and 4 of the split: the seeds 5003 and 5004, as evaluate gives them
    ev = evaluate_validation(ConstantFeed.from_env, env_id, 2, first_episode=3)
    assert [r["seed"] for r in ev.rows] == [5003, 5004]
    first = evaluate_validation(ConstantFeed.from_env, env_id, 5)
    assert [r["seed"] for r in first.rows][3:] == [5003, 5004]
    assert [r["machining_time_s"] for r in first.rows][3:] == [
        r["machining_time_s"] for r in ev.rows
    ]
