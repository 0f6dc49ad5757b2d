"""What Turning-v0 does beyond the conventions every env keeps (``tests/envs``): its info
values, action map, input checks, keyword overrides, episode ends and hidden quantities."""

import gymnasium as gym
import numpy as np
import pytest

from machining_envs import TurningScenario
from machining_envs.core.workpieces import DepthProfile
from tests.helpers import TURNING, run_until_done


def test_info_values_and_units_after_a_step():
    env = gym.make(TURNING, scenario="paper_405")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.0], dtype=np.float32))
    assert info["t_s"] == pytest.approx(0.1)
    assert info["command"] == pytest.approx(0.5 * env.unwrapped.params.command_max)
    assert info["spindle_rpm"] == 405.0 and info["force_limit_N"] == 1000.0


def test_action_map_round_trip():
    env = gym.make(TURNING).unwrapped
    u = np.array([0.0, 1000.0, 4095.0])
    np.testing.assert_allclose(env.action_to_command(env.command_to_action(u)), u)
    assert env.action_to_command(-1.0) == 0.0


def test_kwargs_override_parameters_and_spindle():
    env = gym.make(TURNING, spindle_rpm=245, sensor_gain=15.0, scenario="paper_700")
    _, info = env.reset(seed=0)
    assert info["spindle_rpm"] == 245.0
    assert env.unwrapped.params.sensor_gain == 15.0


def test_episode_ends_when_workpiece_is_cut_and_on_breakage():
    env = gym.make(TURNING, scenario="paper_700")
    env.reset(seed=0)
    # Full feed on a 1 mm step: the force passes 3 kN only when the deeper steps arrive.
    _, term, _, info, _ = run_until_done(env, [1.0])
    assert term and info["breakage"] and info["peak_force_N"] > 3000.0
    sc = TurningScenario("short", DepthProfile.steps((0.5,), 3.0), spindle_rpm=700.0)
    env.reset(seed=0, options={"scenario": sc})
    _, term, _, info, _ = run_until_done(env, [-0.5])
    assert term and info["finished"] and not info["breakage"]
    assert 0 < info["machining_time_s"] <= info["t_s"]


def test_hidden_quantities_stay_out_of_the_observation():
    """Two cuts differing only in hidden depth and Kf give the same first observation."""
    env = gym.make(TURNING)
    a = TurningScenario("a", DepthProfile.steps((1.0,), 20.0), 405.0, noise_scale=0.0)
    b = TurningScenario(
        "b", DepthProfile.steps((2.5,), 20.0), 405.0, force_coefficient_scale=1.2, noise_scale=0.0
    )
    oa, _ = env.reset(seed=0, options={"scenario": a})
    ob, _ = env.reset(seed=0, options={"scenario": b})
    assert oa.tobytes() == ob.tobytes()
