"""The ``shopfloor`` split of ContouringFeed-v0: the training paths with a real CNC's handling
of the feed override (``SHOPFLOOR_OVERRIDE``), held out; Contouring-v0, which commands the
axes directly, refuses it."""

import gymnasium as gym
import numpy as np
import pytest

from machining_envs.contouring.scenarios import SHOPFLOOR_OVERRIDE
from machining_envs.core.splits import HELD_OUT, check_not_held_out
from tests.helpers import CONTOURING, CONTOURING_FEED


def test_the_shopfloor_split_runs_the_override_handling_and_is_held_out():
    env = gym.make(CONTOURING_FEED, scenario="shopfloor")
    u = env.unwrapped
    a, top, ts = SHOPFLOOR_OVERRIDE, u.override_max, u.decision_interval_s
    env.reset(seed=0)
    assert u.scenario.actuation == a
    rng = np.random.default_rng(0)
    overrides = []
    for _ in range(150):
        *_, terminated, truncated, info = env.step(rng.uniform(-1.0, 1.0, 1).astype(np.float32))
        overrides.append(info["feed_override"])
        if terminated or truncated:
            break
    o = np.array(overrides)
    np.testing.assert_array_equal(o[: a.delay_steps], 0.0)  # two decisions of delay
    grid = o / (a.quantum * top)
    np.testing.assert_allclose(grid, np.round(grid), atol=1e-9)  # 1 % of the programmed feed
    steps = np.diff(np.concatenate([[0.0, 0.0], o]))
    assert np.abs(steps).max() <= a.max_rate_per_s * top * ts + 1e-9
    assert np.abs(np.diff(steps)).max() <= a.max_accel_per_s2 * top * ts**2 + 1e-9
    assert "shopfloor" in HELD_OUT
    with pytest.raises(ValueError, match="shopfloor"):
        check_not_held_out(["shopfloor"], "training")


def test_contouring_commands_the_axes_and_refuses_an_override_actuation():
    env = gym.make(CONTOURING, scenario="shopfloor")
    with pytest.raises(ValueError, match="ContouringFeed-v0"):
        env.reset(seed=0)
