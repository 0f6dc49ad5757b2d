"""Learning curves: IQM over seeds of the recorded validation scores, against the reference
scored on the same validation episodes."""

import csv
import json
import math

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("rliable")

from agents.bench.curves import learning_curve, plot_learning_curves  # noqa: E402
from agents.eval import task_of  # noqa: E402
from agents.eval.harness import evaluate_validation  # noqa: E402
from agents.turning import VariableGainPI  # noqa: E402
from machining_envs.core.splits import split_seeds  # noqa: E402
from tests.helpers import TURNING  # noqa: E402

N_EPISODES = 3


def _fake_runs(tmp_path, table: dict[int, list[float]], **config):
    """Seed folders with a config.json (``config``: more of its settings) and an eval.csv of
    the given scores."""
    seeds = []
    for seed, scores in table.items():
        d = tmp_path / f"seed_{seed}"
        d.mkdir()
        (d / "config.json").write_text(
            json.dumps({"seed": seed, "config": {"eval_episodes": N_EPISODES, **config}})
        )
        with open(d / "eval.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["timesteps", "wall_s", "score", "valid", "itae"])
            for k, s in enumerate(scores):
                w.writerow([1000 * (k + 1) + seed, 10.0 * (k + 1) + seed, s, 1.0, 0.0])
        seeds.append((seed, d / "best_model.zip"))
    return seeds


def _task():
    env = gym.make(TURNING)
    try:
        score = task_of(env).score
        return score, score.failed_value(env)
    finally:
        env.close()


def test_the_curve_is_the_seeds_iqm_and_finds_the_first_match(tmp_path):
    score, failed = _task()
    factory = VariableGainPI.from_env
    ev = evaluate_validation(factory, TURNING, N_EPISODES)
    # The validation protocol's episodes: the split's first seeds, its scenario.
    assert [r["seed"] for r in ev.rows] == list(split_seeds("validation", N_EPISODES))
    assert {r["scenario"] for r in ev.rows} == {"validation"}
    ref = float(score(ev.rows, failed)["score"])
    assert math.isfinite(ref)
    # five seeds: far above the reference, then just above, then below at evaluation 3
    table = {
        s: [ref * 4 + s, ref * 1.5 + s, ref * 1.01 + 0.1 * s, ref * 0.5 + 0.1 * s] for s in range(5)
    }
    c = learning_curve(
        "fake", _fake_runs(tmp_path, table), TURNING, {}, score, failed, ("adaptive PI", factory)
    )
    assert c.reference_score == pytest.approx(ref, rel=1e-12)
    assert c.first_match == 3
    np.testing.assert_allclose(c.steps, [1002, 2002, 3002, 4002])
    np.testing.assert_allclose(c.wall_s, [12.0, 22.0, 32.0, 42.0])
    # IQM of five values: the mean of the middle three (25 % trimmed on each side, rliable)
    np.testing.assert_allclose(c.iqm[0], np.mean(sorted(table[s][0] for s in range(5))[1:4]))
    assert np.all(c.low <= c.iqm) and np.all(c.iqm <= c.high)
    assert "first matches it at 4002 env steps" in c.summary(1.0, "s")
    assert plot_learning_curves([c], TURNING, 1.0, "time (s)", tmp_path / "c.png").is_file()


def test_a_curve_that_never_matches_says_so_with_its_best(tmp_path):
    score, failed = _task()
    table = {s: [1e6, 5e5 + s] for s in range(3)}
    c = learning_curve(
        "fake",
        _fake_runs(tmp_path, table),
        TURNING,
        {},
        score,
        failed,
        ("adaptive PI", VariableGainPI.from_env),
    )
    assert c.first_match is None
    assert "never matches it within 2001 env steps" in c.summary(1.0, "s")


def test_the_reference_is_scored_as_the_runs_chose_their_models(tmp_path):
    from agents.rl.callbacks import selection_score

    score, failed = _task()
    factory, allowances = VariableGainPI.from_env, [0.005, 0.01, 0.02]
    ev = evaluate_validation(factory, TURNING, N_EPISODES, first_episode=7)
    assert [r["seed"] for r in ev.rows] == list(split_seeds("validation", 10))[7:]
    want = selection_score(ev.rows, score, failed, allowances)
    runs = _fake_runs(
        tmp_path, {0: [1e6], 1: [1e6]}, eval_first_episode=7, eval_allowances=allowances
    )
    c = learning_curve("fake", runs, TURNING, {}, score, failed, ("adaptive PI", factory))
    assert c.reference_score == pytest.approx(want, rel=1e-12)
