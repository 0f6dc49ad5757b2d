"""Shipped policies load, run under the harness, and the turning one wins the primary score."""

import numpy as np

from agents import ConstantFeed, FixedGainPI, VariableGainPI
from agents.harness import evaluate
from agents.rl import PRETRAINED_DIR, pretrained, primary_score
from tests.conftest import TURNING


def test_each_pretrained_policy_has_its_regeneration_command_and_is_small():
    for folder in PRETRAINED_DIR.iterdir():
        if folder.is_dir():
            assert "machining-bench train" in (folder / "README.md").read_text()
            size = sum(p.stat().st_size for p in folder.iterdir())
            assert size < 5 * 2**20, folder


def test_pretrained_turning_policy_beats_the_best_classical_agent():
    """Primary score on 20 held-out episodes (seeds 1000-1019, the benchmark's)."""
    scores = {}
    for factory in (
        ConstantFeed.from_env,
        FixedGainPI.from_env,
        VariableGainPI.from_env,
        pretrained("turning_ppo"),
    ):
        ev = evaluate(factory, TURNING, ["test"], n_episodes=20, seed=1000)
        scores[ev.rows[0]["agent"]] = (primary_score(ev.rows), ev.rows)
    ppo_name = next(k for k in scores if "pretrained" in k)
    ppo, ppo_rows = scores.pop(ppo_name)
    best_name = min(scores, key=lambda k: scores[k][0]["score"])
    best, best_rows = scores[best_name]
    assert ppo["score"] < best["score"], (ppo, best_name, best)
    assert all(r["breakage"] == 0.0 for r in ppo_rows)
    assert np.isfinite(ppo["itae"])
