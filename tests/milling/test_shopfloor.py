"""The ``shopfloor`` split of EndMilling-v0: the benchmark's (`test`) ranges on a real CNC's feed
override (``SHOPFLOOR_ACTUATION``), held out, and every command the servo gets obeys it."""

import gymnasium as gym
import numpy as np

from machining_envs.core.actuation import SHOPFLOOR_ACTUATION
from tests.helpers import MILLING, assert_actuated, held_out_draws


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
        assert_actuated(commands, a, cmax, env.unwrapped.params.sample_time_s)
    assert held_out_draws(MILLING, "shopfloor", "actuation", n=3) == [a] * 3


def test_a_scenario_without_its_own_actuation_runs_the_envs_option():
    env = gym.make(MILLING, scenario="train", actuation={"delay_steps": 4})
    env.reset(seed=0)
    commands = [env.step(np.array([0.0], np.float32))[4]["command"] for _ in range(6)]
    np.testing.assert_array_equal(commands[:4], 0.0)
    assert commands[4] > 0.0
