"""What EndMilling-v0 does beyond the conventions every env keeps (``tests/envs``): its info
values, log and linear action maps, input checks, keyword overrides, force models, episode
ends and hidden quantities."""

import gymnasium as gym
import numpy as np
import pytest

from machining_envs import MillingParams, MillingScenario
from machining_envs.core.workpieces import DepthProfile
from tests.helpers import MILLING, run_until_done


def test_info_values_and_units_after_a_step():
    env = gym.make(MILLING, scenario="paper_step")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.0], dtype=np.float32))
    assert info["t_s"] == pytest.approx(0.1)
    cmax = env.unwrapped.params.command_max
    assert info["command"] == pytest.approx(cmax * (1000**0.5 - 1) / 999)  # log map, action 0
    assert info["spindle_rpm"] == 400.0 and info["torque_limit_Nmm"] == 3600.0
    assert info["workpiece_length_mm"] == 40.0
    assert info["workpiece_volume_mm3"] == pytest.approx(32.0 * 40.0 * 2.0)
    assert info["feed_per_tooth_mm"] == pytest.approx(info["feed_mm_per_rev"] / 4)
    assert info["feed_mm_per_rev"] == pytest.approx(60 * info["feed_velocity_mm_s"] / 400.0)


@pytest.mark.parametrize("action_map", ["log", "linear"])
def test_action_map_round_trip(action_map):
    env = gym.make(MILLING, action_map=action_map).unwrapped
    u = np.array([0.0, 0.3, 20.0, 150.0])
    np.testing.assert_allclose(env.action_to_command(env.command_to_action(u)), u, atol=1e-12)
    assert env.action_to_command(-1.0) == 0.0
    assert env.action_to_command(1.0) == pytest.approx(150.0)
    assert env.action_to_command(0.0) == pytest.approx(
        75.0 if action_map == "linear" else 4.598, rel=1e-3
    )


def test_log_action_map_gives_equal_relative_steps():
    """Above a few counts each 2/3 of action multiplies the command by ~10 (three decades)."""
    env = gym.make(MILLING).unwrapped
    u = env.action_to_command(np.array([-1 / 3, 1 / 3, 1.0]))
    np.testing.assert_allclose(u[1:] / u[:-1], 10.0, rtol=0.1)


def test_unknown_action_map_is_rejected_with_the_allowed_values():
    with pytest.raises(ValueError, match="action_map must be one of"):
        gym.make(MILLING, action_map="exp")


def test_classical_agent_is_unaffected_by_the_action_map():
    """IntegralACC goes through the env's map: same commands and torques on either map."""
    from agents.milling import IntegralACC

    runs = {}
    for action_map in ("log", "linear"):
        env = gym.make(MILLING, scenario="paper_step", action_map=action_map)
        agent = IntegralACC.from_env(env)
        obs, _ = env.reset(seed=0)
        cmds = []
        for _ in range(200):
            a, _ = agent.predict(obs)
            obs, _, term, trunc, info = env.step(a)
            cmds.append(info["command"])
        runs[action_map] = np.array(cmds)
    np.testing.assert_allclose(runs["log"], runs["linear"], rtol=1e-4, atol=1e-4)


def test_bad_reset_input_is_refused():
    with pytest.raises(ValueError, match="reset options"):
        gym.make(MILLING).reset(options={"scenario": "train", "depth": 2})
    # A scaled spindle outside the machine's range, and a cut deeper than the tool is wide.
    with pytest.raises(ValueError, match="spindle_rpm"):
        gym.make(MILLING, spindle_rpm=5000.0).reset(
            options={"scenario": MillingScenario("fast", DepthProfile.steps(), spindle_scale=2.0)}
        )
    with pytest.raises(ValueError, match="radial depth"):
        gym.make(MILLING, tool_diameter_mm=2.0).reset(options={"scenario": "paper_step"})


def test_kwargs_override_parameters():
    env = gym.make(MILLING, spindle_rpm=500, servo_gain=0.025, scenario="paper_step")
    _, info = env.reset(seed=0)
    assert info["spindle_rpm"] == 500.0
    assert env.unwrapped.params.servo_gain == 0.025
    al = gym.make(MILLING, params=MillingParams.ahn_choi_al6061(), scenario="paper_step")
    _, info = al.reset(seed=0)
    assert info["spindle_rpm"] == 1000.0
    assert info["torque_limit_Nmm"] == pytest.approx(222.8)


def test_force_models_give_different_torques_on_one_cut():
    torques = {}
    for model in ("power_law", "average_force"):
        env = gym.make(MILLING, force_model=model, scenario="paper_step", noise_std_Nmm=0.0)
        env.reset(seed=0)
        for _ in range(30):
            _, _, _, _, info = env.step(np.array([-0.8], dtype=np.float32))
        torques[model] = info["torque_Nmm"]
    assert torques["power_law"] > 0 and torques["average_force"] > 0
    assert abs(torques["power_law"] / torques["average_force"] - 1.0) > 0.05


def test_episode_ends_when_workpiece_is_cut_and_on_breakage():
    sc = MillingScenario("short", DepthProfile.steps((1.0,), 2.0))
    env = gym.make(MILLING)
    env.reset(seed=0, options={"scenario": sc})
    _, term, _, info, _ = run_until_done(env, [-0.5])
    assert term and info["finished"] and not info["breakage"]
    assert 0 < info["machining_time_s"] <= info["t_s"]
    assert info["removed_volume_mm3"] == pytest.approx(info["workpiece_volume_mm3"])
    # Full feed into a 5 mm radial cut with a soft tool: the torque passes the limit.
    env = gym.make(MILLING, breakage_torque_Nmm=6000.0)
    env.reset(seed=0, options={"scenario": MillingScenario("deep", DepthProfile.steps((5.0,)))})
    _, term, _, info, _ = run_until_done(env, [1.0])
    assert term and info["breakage"] and info["peak_torque_Nmm"] > 6000.0


def test_hidden_quantities_stay_out_of_the_observation():
    """Two cuts differing only in hidden depth and Ks give the same first observation."""
    env = gym.make(MILLING)
    a = MillingScenario("a", DepthProfile.steps((1.0,), 20.0), noise_scale=0.0)
    b = MillingScenario(
        "b", DepthProfile.steps((2.5,), 20.0), torque_coefficient_scale=1.2, noise_scale=0.0
    )
    oa, _ = env.reset(seed=0, options={"scenario": a})
    ob, _ = env.reset(seed=0, options={"scenario": b})
    assert oa.tobytes() == ob.tobytes()
    oa, *_ = env.step(np.array([-0.8], dtype=np.float32))
    assert oa[0] > 0  # the torque is measured, so the cuts differ from here on
