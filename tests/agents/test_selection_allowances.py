"""The best-model choice at every allowance (ValidationCallback's ``allowances``)."""

from __future__ import annotations

import pytest

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

    path = tmp_path / "ppo.yml"
    path.write_text(
        "machining_envs/Turning-v0:\n"
        "  policy: MlpPolicy\n"
        "  n_timesteps: 1000\n"
        "  callback:\n"
        "    - agents.rl.callbacks.ValidationCallback:\n"
        "        {eval_freq: 500, allowances: [0.005, 0.01, 0.02]}\n"
    )
    cfg = load_config("machining_envs/Turning-v0", "ppo", path)
    assert cfg.eval_allowances == [0.005, 0.01, 0.02]
    assert load_config("machining_envs/Turning-v0", "ppo", None).eval_allowances is None
    path.write_text(path.read_text().replace("0.005, 0.01, 0.02", "2"))
    with pytest.raises(ConfigError, match="allowances"):
        load_config("machining_envs/Turning-v0", "ppo", path)
