"""What MicroDrilling-v0 does beyond the conventions every env keeps (``tests/envs``): its info
values, the voltage and feed action maps, input checks, keyword overrides, the ends of an
episode, the feed mode's retract and hidden quantities."""

import gymnasium as gym
import numpy as np
import pytest

from machining_envs import DrillingScenario
from tests.helpers import DRILLING, run_until_done


def test_info_values_and_units_at_reset_and_after_a_step():
    env = gym.make(DRILLING, scenario="paper_0.8")
    _, info0 = env.reset(seed=0)
    assert info0["spindle_hz"] == pytest.approx(545.0, abs=0.1)
    assert info0["spindle_rpm"] == pytest.approx(32700.0, abs=6.0)  # Table 1: 545 Hz
    _, _, _, _, info = env.step(np.array([0.0], dtype=np.float32))
    assert info["t_s"] == pytest.approx(0.01)
    assert info["command"] == pytest.approx(5.0) and info["voltage_V"] == pytest.approx(5.0)
    assert info["feed_velocity_mm_s"] == pytest.approx(0.32)
    assert info["depth_mm"] == pytest.approx(0.0032) and info["cutting"]
    assert info["torque_limit_Nmm"] == pytest.approx(env.unwrapped.params.nominal_torque_Nmm(0.8))
    assert info["breakage_torque_Nmm"] == pytest.approx(5.0 * 0.8**3)


def test_action_map_round_trip_both_modes():
    env = gym.make(DRILLING).unwrapped
    u = np.array([0.0, 5.0, 10.0])
    np.testing.assert_allclose(env.action_to_command(env.command_to_action(u)), u)
    assert env.action_to_command(0.0) == 5.0
    feed = gym.make(DRILLING, control="feed").unwrapped
    assert feed.action_to_command(-1.0) == -3.0 and feed.action_to_command(1.0) == 3.0
    assert feed.command_to_action(0.32) == pytest.approx(0.32 / 3.0)


def test_kwargs_override_parameters():
    env = gym.make(DRILLING, torque_noise_Nmm=0.02, nominal_voltage=6.0, scenario="paper_0.6")
    _, info = env.reset(seed=0)
    p = env.unwrapped.params
    assert p.torque_noise_Nmm == 0.02 and p.nominal_voltage == 6.0
    assert info["spindle_hz"] == pytest.approx(p.free_speed_hz(6.0))
    assert info["command"] == pytest.approx(6.0)


def test_episode_ends_when_hole_is_drilled():
    env = gym.make(DRILLING)
    sc = DrillingScenario("short", 0.6, aspect_ratio=1.0)
    env.reset(seed=0, options={"scenario": sc})
    n, term, _, info, _ = run_until_done(env, [0.0])
    assert term and info["finished"] and not info["breakage"]
    # 0.6 mm at 0.32 mm/s: 1.875 s, to within a sample.
    assert info["drilling_time_s"] == pytest.approx(0.6 / 0.32, abs=1e-9)
    assert n == int(np.ceil(0.6 / 0.32 / 0.01 - 1e-9))


def test_episode_ends_on_breakage_when_spindle_is_starved():
    env = gym.make(DRILLING, scenario="paper_0.5")
    env.reset(seed=0)
    _, term, _, info, r = run_until_done(env, [-1.0])  # 0 V
    assert term and info["breakage"] and not info["finished"]
    assert info["peak_torque_Nmm"] > info["breakage_torque_Nmm"] == pytest.approx(0.625)
    assert r < -50.0


def test_feed_mode_retract_clears_chips_and_stage_limit_holds():
    env = gym.make(DRILLING, control="feed", scenario="paper_0.8")
    env.reset(seed=0)
    for _ in range(500):  # 1.6 mm at the nominal feed
        _, _, _, _, info = env.step(np.array([0.32 / 3.0], dtype=np.float32))
    assert info["packed_chip_mm"] == pytest.approx(1.6, abs=1e-6)
    assert info["voltage_V"] == 5.0
    for _ in range(200):  # full retract speed for 2 s: out of the hole, to the stage's top
        _, _, _, _, info = env.step(np.array([-1.0], dtype=np.float32))
    assert info["position_mm"] == pytest.approx(-2.0)
    assert info["packed_chip_mm"] == 0.0 and info["depth_mm"] == pytest.approx(1.6, abs=1e-6)
    assert info["torque_Nmm"] == 0.0 and not info["cutting"]


def test_hidden_quantities_stay_out_of_the_observation():
    """Holes differing only in hidden cutting constant and chips give the same first obs."""
    env = gym.make(DRILLING)
    a = DrillingScenario("a", 0.7, noise_scale=0.0)
    b = DrillingScenario("b", 0.7, cutting_scale=1.2, chip_scale=2.5, noise_scale=0.0)
    oa, _ = env.reset(seed=0, options={"scenario": a})
    ob, _ = env.reset(seed=0, options={"scenario": b})
    assert oa.tobytes() == ob.tobytes()


def test_voltage_feed_mode_maps_both_commands_and_observes_both_actions():
    """``control="voltage_feed"``: action ``[voltage, feed]`` on the maps of the two
    single modes; observation 4 is the voltage's previous action, 12 the feed's."""
    env = gym.make(DRILLING, control="voltage_feed", scenario="paper_0.8")
    u = env.unwrapped
    assert env.action_space.shape == (2,) and env.observation_space.shape == (13,)
    np.testing.assert_allclose(u.action_to_command([-1.0, 1.0]), [0.0, 3.0])
    np.testing.assert_allclose(u.command_to_action([5.0, 0.32]), [0.0, 0.32 / 3.0])
    obs, info = env.reset(seed=0)
    np.testing.assert_allclose(info["command"], [5.0, 0.32])  # the nominal cut
    assert obs[4] == 0.0 and obs[12] == pytest.approx(0.32 / 3.0)
    a = np.array([0.6, 0.5], dtype=np.float32)
    obs, _, _, _, info = env.step(a)
    np.testing.assert_allclose(info["command"], [8.0, 1.5], rtol=1e-6)
    assert info["voltage_V"] == pytest.approx(8.0)
    assert info["feed_velocity_mm_s"] == pytest.approx(1.5, rel=1e-6)
    assert obs[4] == pytest.approx(0.6) and obs[12] == pytest.approx(0.5)
    for bad in ([0.0], [0.0, 0.0, 0.0], [0.0, np.nan]):
        with pytest.raises(ValueError, match="MicroDrillingEnv"):
            env.step(np.array(bad, dtype=np.float32))


def test_voltage_feed_mode_retract_clears_chips_while_the_spindle_runs_fast():
    env = gym.make(DRILLING, control="voltage_feed", scenario="paper_0.8")
    env.reset(seed=0)
    fast = float(env.unwrapped.command_to_action([10.0, 0.0])[0])
    for _ in range(500):  # 1.6 mm at the nominal feed, 10 V
        _, _, _, _, info = env.step(np.array([fast, 0.32 / 3.0], dtype=np.float32))
    assert info["packed_chip_mm"] == pytest.approx(1.6, abs=1e-6)
    assert info["voltage_V"] == 10.0 and info["spindle_hz"] > 800.0
    for _ in range(200):
        _, _, _, _, info = env.step(np.array([fast, -1.0], dtype=np.float32))
    assert info["position_mm"] == pytest.approx(-2.0) and info["packed_chip_mm"] == 0.0
    assert info["voltage_V"] == 10.0


def test_unknown_control_mode_is_refused_naming_the_modes():
    with pytest.raises(ValueError, match="control must be one of.*voltage_feed"):
        gym.make(DRILLING, control="feed_voltage")


def test_voltage_feed_score_bound_is_the_fast_spindle_s_floor():
    """The bound: the entry at the stage's top speed, the rest at the feed whose chip-free
    torque at the top spindle speed is the limit; below the voltage mode's travel at the
    programmed feed, and no drill that keeps the torque under the limit beats it."""
    from machining_envs.drilling.lanes import floor_feed_mm_s

    env = gym.make(DRILLING, control="voltage_feed", scenario="paper_0.8")
    _, info = env.reset(seed=0)
    base = env.unwrapped
    p, sc = base.params, base.scenario
    truth = sc.true_params(p)
    c = truth.coefficients(0.8)
    v = floor_feed_mm_s(truth, c.torque_per_feed, info["torque_limit_Nmm"])
    assert v == pytest.approx(
        info["torque_limit_Nmm"] * p.free_speed_hz(10.0) / c.torque_per_feed, rel=1e-12
    )
    entry = c.full_engagement_mm
    assert info["score_bound"] == pytest.approx(entry / 3.0 + (8.0 - entry) / v, rel=1e-9)
    _, plain = gym.make(DRILLING, scenario="paper_0.8").reset(seed=0)
    assert info["score_bound"] < plain["score_bound"] == pytest.approx(8.0 / 0.32)
    # At 10 V, once the spindle has run up to its top speed (it starts at 545 Hz), a hole
    # without chip friction drilled at 0.85x the floor's feed keeps under the limit, at
    # 1.15x it is over it: the floor's feed is where the limit binds.
    hole = DrillingScenario("clean", 0.8, aspect_ratio=3.0, chip_scale=0.0, noise_scale=0.0)
    over = []
    for share in (0.85, 1.15):
        _, info = env.reset(seed=0, options={"scenario": hole})
        truth = base.scenario.true_params(p)
        top = truth.free_speed_hz(10.0)
        v = floor_feed_mm_s(
            truth, truth.coefficients(0.8).torque_per_feed, info["torque_limit_Nmm"]
        )
        a = base.command_to_action([10.0, share * v]).astype(np.float32)
        costs, done = [], False
        while not done:
            _, _, term, trunc, last = env.step(a)
            done = term or trunc
            if last["engagement"] >= 1.0 and last["spindle_hz"] > 0.97 * top:
                costs.append(last["cost"])
        assert last["finished"] and len(costs) > 20
        assert (last["drilling_time_s"] > last["score_bound"]) == (share < 1.0)
        over.append(np.mean(costs))
    assert over[0] == 0.0 and over[1] == 1.0
