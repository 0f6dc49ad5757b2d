"""The ``shopfloor`` split of EndMilling-v0: the training ranges on a real CNC's feed
override (``SHOPFLOOR_ACTUATION``), held out, and every command the servo gets obeys it."""

import gymnasium as gym
import numpy as np
import pytest

from machining_envs.core.actuation import SHOPFLOOR_ACTUATION
from machining_envs.core.splits import HELD_OUT, check_not_held_out
from tests.helpers import MILLING


def test_the_shopfloor_split_runs_the_cnc_actuation_and_is_held_out():
    env = gym.make(MILLING, scenario="shopfloor")
    cmax = env.unwrapped.params.command_max
    a = SHOPFLOOR_ACTUATION
    for seed in range(3):
        env.reset(seed=seed)
        assert env.unwrapped.scenario.actuation == a
        rng = np.random.default_rng(seed)
        commands = []
        for _ in range(80):
            action = rng.uniform(-1.0, -0.3, size=1).astype(np.float32)
            *_, terminated, truncated, info = env.step(action)
            commands.append(info["command"])
            if terminated or truncated:
                break
        c = np.array(commands)
        np.testing.assert_array_equal(c[: a.delay_steps], 0.0)  # the interpolator's delay
        grid = c / (a.quantum * cmax)
        np.testing.assert_allclose(grid, np.round(grid), atol=1e-9)  # 1 % steps
        steps = np.diff(np.concatenate([[0.0, 0.0], c]))
        ts = env.unwrapped.params.sample_time_s
        assert np.abs(steps).max() <= a.max_rate_per_s * cmax * ts + 1e-9
        assert np.abs(np.diff(steps)).max() <= a.max_accel_per_s2 * cmax * ts**2 + 1e-9
    assert "shopfloor" in HELD_OUT
    with pytest.raises(ValueError, match="shopfloor"):
        check_not_held_out(["shopfloor"], "training")


def test_a_scenario_without_its_own_actuation_runs_the_envs_option():
    env = gym.make(MILLING, scenario="train", actuation={"delay_steps": 4})
    env.reset(seed=0)
    commands = [env.step(np.array([0.0], np.float32))[4]["command"] for _ in range(6)]
    np.testing.assert_array_equal(commands[:4], 0.0)
    assert commands[4] > 0.0
