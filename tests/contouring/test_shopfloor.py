"""The ``shopfloor`` split of ContouringFeed-v0: the training paths with a real CNC's handling
of the feed override (``SHOPFLOOR_OVERRIDE``), held out; Contouring-v0, which commands the
axes directly, refuses it."""

import gymnasium as gym
import numpy as np
import pytest

from machining_envs.contouring.scenarios import SHOPFLOOR_OVERRIDE
from tests.helpers import CONTOURING, CONTOURING_FEED, assert_actuated, held_out_draws


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
    assert_actuated(o, a, top, ts)
    held_out_draws(CONTOURING_FEED, "shopfloor", "actuation", n=1)


def test_contouring_commands_the_axes_and_refuses_an_override_actuation():
    env = gym.make(CONTOURING, scenario="shopfloor")
    with pytest.raises(ValueError, match="ContouringFeed-v0"):
        env.reset(seed=0)
