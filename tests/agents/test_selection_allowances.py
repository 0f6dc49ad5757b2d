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
