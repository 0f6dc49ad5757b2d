"""The contouring tasks: ContouringFeed-v0's cost marks the steps past the tolerance, its
bound (the path at the largest override) is never beaten, and the look-ahead planner slows
for curves (the agents' free parameters are checked in ``tests/envs/test_task.py``)."""

import gymnasium as gym
import numpy as np
import pytest

from agents import ConstantOverride, LookAheadFeed
from agents.eval import evaluate

FEED = "machining_envs/ContouringFeed-v0"


def test_feed_cost_and_bound():
    env = gym.make(FEED)
    _, info = env.reset(seed=2, options={"scenario": "ood"})
    base = env.unwrapped
    assert info["score_bound"] == pytest.approx(
        info["path_length_mm"] / (base.override_max * info["feed_mm_s"])
    )
    seen = set()
    for _ in range(300):
        _, _, term, trunc, info = env.step(np.array([1.0], dtype=np.float32))
        assert info["cost"] == (
            1.0 if info["peak_contour_error_mm"] > info["contour_tolerance_mm"] else 0.0
        )
        seen.add(info["cost"])
        if term or trunc:
            break
    assert seen == {0.0, 1.0}


@pytest.mark.parametrize("factory", [ConstantOverride.from_env, LookAheadFeed.from_env])
def test_no_counting_run_beats_the_bound(factory):
    score = gym.make(FEED).unwrapped.task.score
    ev = evaluate(factory, FEED, ["validation"], 12, seed=5000)
    for r in ev.rows:
        if score.counts(r):
            assert r["cycle_time_s"] >= r["score_bound"], r


def test_look_ahead_slows_down_before_a_turn_not_on_a_straight():
    env = gym.make(FEED)
    agent = LookAheadFeed.from_env(env, centripetal_mm_s2=500.0, tangential_mm_s2=500.0)
    obs = np.zeros((2, 16), dtype=np.float32)
    obs[:, 12] = 0.5  # programmed feed 50 mm/s
    obs[:, 6] = 1.0  # 100 mm of path left
    obs[1, 7:12] = np.array([1.0, 2.0, 3.0, 3.0, 3.0]) / np.pi  # an arc of R 0.5 mm ahead
    action, _ = agent.predict(obs)
    override = (action[:, 0] + 1.0) / 2.0 * env.unwrapped.override_max
    assert override[0] == pytest.approx(1.0)  # the cap: the programmed feed
    assert 0.02 <= override[1] < 0.5
