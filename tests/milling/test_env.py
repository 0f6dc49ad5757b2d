"""EndMilling-v0 against the conventions every env keeps."""

import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import machining_envs
from machining_envs import EndMillingEnv, MillingParams, MillingScenario
from machining_envs.core.workpieces import DepthProfile
from machining_envs.milling.scenarios import cut_area_mm2

MILLING = "machining_envs/EndMilling-v0"

DESIGN_INFO_KEYS = {
    "t_s",
    "command",
    "action_clipped",
    "breakage",
    "diverged",
    "torque_Nmm",
    "torque_ref_Nmm",
    "measured",
    "feed_mm_per_rev",
    "depth_mm",
    "spindle_rpm",
    "position_mm",
    "finished",
    "segment",
}


def _random_rollout(env, n_steps, seed):
    """Random actions from a seeded generator, resetting on episode end (the torque twin of
    ``tests.conftest.random_rollout``, which reads ``force_N``)."""
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    out_obs, out_rew, out_torque = [obs], [], []
    for _ in range(n_steps):
        obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, size=1).astype(np.float32))
        out_obs.append(obs)
        out_rew.append(r)
        out_torque.append(info["torque_Nmm"])
        if term or trunc:
            obs, _ = env.reset()
            out_obs.append(obs)
    return np.array(out_obs), np.array(out_rew), np.array(out_torque)


def test_registered_and_listed():
    assert MILLING in machining_envs.ENV_IDS
    assert MILLING in gym.registry


def test_checkers_pass_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check_env(gym.make(MILLING).unwrapped)
        gym_check_env(gym.make(MILLING, scenario="paper_taper").unwrapped)
        gym_check_env(gym.make(MILLING, force_model="average_force").unwrapped)
        sb3_check_env(gym.make(MILLING).unwrapped, warn=True)


def test_make_without_import_in_fresh_interpreter():
    code = (
        "import gymnasium as gym\n"
        "env = gym.make('machining_envs:machining_envs/EndMilling-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "print(obs.shape)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "(7,)"


def test_same_seed_bit_identical_1000_steps():
    a = _random_rollout(gym.make(MILLING), 1000, seed=7)
    b = _random_rollout(gym.make(MILLING), 1000, seed=7)
    for x, y in zip(a, b, strict=True):
        assert x.tobytes() == y.tobytes()
    c = _random_rollout(gym.make(MILLING), 1000, seed=8)
    assert a[0].tobytes() != c[0].tobytes()


def test_pickle_mid_episode_continues_identically():
    env = gym.make(MILLING)
    env.reset(seed=3)
    for _ in range(20):
        env.step(np.array([-0.8], dtype=np.float32))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(30):
        o1, r1, *_ = env.step(np.array([-0.7], dtype=np.float32))
        o2, r2, *_ = clone.step(np.array([-0.7], dtype=np.float32))
        assert o1.tobytes() == o2.tobytes() and r1 == r2


def test_async_vector_env_runs():
    envs = gym.vector.AsyncVectorEnv([lambda: gym.make(MILLING) for _ in range(2)])
    try:
        obs, _ = envs.reset(seed=[1, 2])
        assert obs.shape == (2, 7)
        for _ in range(20):
            obs, rew, term, trunc, info = envs.step(np.full((2, 1), -0.8, dtype=np.float32))
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rew))
        assert "torque_Nmm" in info
    finally:
        envs.close()


def test_info_keys_and_units():
    env = gym.make(MILLING, scenario="paper_step")
    _, info0 = env.reset(seed=0)
    assert DESIGN_INFO_KEYS <= set(info0)
    _, _, _, _, info = env.step(np.array([0.0], dtype=np.float32))
    assert DESIGN_INFO_KEYS <= set(info)
    assert info["t_s"] == pytest.approx(0.1)
    cmax = env.unwrapped.params.command_max
    assert info["command"] == pytest.approx(cmax * (1000**0.5 - 1) / 999)  # log map, action 0
    assert info["spindle_rpm"] == 400.0 and info["torque_ref_Nmm"] == 3600.0
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


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_raises(bad):
    env = gym.make(MILLING).unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="EndMillingEnv"):
        env.step(np.array([bad], dtype=np.float32))


def test_out_of_box_action_is_clipped_and_counted():
    env = gym.make(MILLING).unwrapped
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([5.0]))
    assert info["action_clipped"] and info["n_action_clipped"] == 1
    assert info["command"] == pytest.approx(env.params.command_max)
    _, _, _, _, info = env.step(np.array([-3.0]))
    assert info["command"] == 0.0 and info["n_action_clipped"] == 2
    _, _, _, _, info = env.step(np.array([0.3]))
    assert not info["action_clipped"] and info["n_action_clipped"] == 2


def test_bad_constructor_and_scenario_input():
    with pytest.raises(ValueError, match="spindle_rpm"):
        gym.make(MILLING, spindle_rpm=-400)
    with pytest.raises(ValueError, match="sample_time_s"):
        gym.make(MILLING, sample_time_s=0.0)
    with pytest.raises(ValueError, match="force_model"):
        gym.make(MILLING, force_model="mechanistic")
    with pytest.raises(ValueError, match="scenario"):
        gym.make(MILLING, scenario="paper_wedge")
    env = gym.make(MILLING)
    with pytest.raises(ValueError, match="scenario"):
        env.reset(options={"scenario": "nonexistent"})
    with pytest.raises(ValueError, match="reset options"):
        env.reset(options={"scenario": "train", "depth": 2})
    with pytest.raises(ValueError, match="spindle_scale"):
        MillingScenario("x", DepthProfile.steps(), spindle_scale=-1.0)
    with pytest.raises(ValueError, match="profile"):
        MillingScenario("x", [1.0, 2.0])
    with pytest.raises(TypeError, match="servo_gian.*servo_gain"):
        gym.make(MILLING, servo_gian=0.025)
    with pytest.raises(TypeError, match="trackin"):
        gym.make(MILLING, reward={"trackin": 1.0})
    with pytest.raises(ValueError, match="tracking"):
        gym.make(MILLING, reward={"tracking": -1.0})
    with pytest.raises(ValueError, match="max_episode_time_s"):
        gym.make(MILLING, max_episode_time_s=0)
    with pytest.raises(ValueError, match="params"):
        gym.make(MILLING, params={"servo_gain": 0.02})
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
    assert info["torque_ref_Nmm"] == pytest.approx(222.8)


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


def test_scenarios_by_name_and_object():
    env = gym.make(MILLING)
    _, info = env.reset(seed=0, options={"scenario": "paper_taper"})
    assert info["scenario"] == "paper_taper" and info["workpiece_length_mm"] == 40.0
    assert info["workpiece_volume_mm3"] == pytest.approx(32.0 * 40.0 * 1.5)
    sc = MillingScenario("mine", DepthProfile.steps((0.5, 1.5), 5.0), spindle_scale=1.5)
    _, info = env.reset(options={"scenario": sc})
    assert info["scenario"] == "mine" and info["spindle_rpm"] == 600.0
    # train and test differ: the held-out set reaches depths and speeds training never does.
    seen = {name: ([], []) for name in ("train", "test")}
    for name, (rpm, depth) in seen.items():
        for s in range(200):
            env.reset(seed=s, options={"scenario": name})
            rpm.append(env.unwrapped.scenario.spindle_scale)
            depth.append(env.unwrapped.scenario.profile.max_depth_mm)
    assert 0.8 <= min(seen["train"][0]) and max(seen["train"][0]) <= 1.25
    assert min(seen["test"][0]) < 0.8 and max(seen["test"][0]) > 1.25
    assert max(seen["train"][1]) <= 3.0 < max(seen["test"][1])


def test_episode_ends_when_workpiece_is_cut_and_on_breakage():
    sc = MillingScenario("short", DepthProfile.steps((1.0,), 2.0))
    env = gym.make(MILLING)
    env.reset(seed=0, options={"scenario": sc})
    done = False
    while not done:
        _, _, term, trunc, info = env.step(np.array([-0.5], dtype=np.float32))
        done = term or trunc
    assert term and info["finished"] and not info["breakage"]
    assert 0 < info["machining_time_s"] <= info["t_s"]
    assert info["removed_volume_mm3"] == pytest.approx(info["workpiece_volume_mm3"])
    # Full feed into a 5 mm radial cut with a soft tool: the torque passes the limit.
    env = gym.make(MILLING, breakage_torque_Nmm=6000.0)
    env.reset(seed=0, options={"scenario": MillingScenario("deep", DepthProfile.steps((5.0,)))})
    done = False
    while not done:
        _, _, term, trunc, info = env.step(np.array([1.0], dtype=np.float32))
        done = term or trunc
    assert term and info["breakage"] and info["peak_torque_Nmm"] > 6000.0


def test_truncation_by_time():
    env = gym.make(MILLING, max_episode_time_s=2.0)
    env.reset(seed=0)
    for k in range(20):
        _, _, term, trunc, _ = env.step(np.array([-1.0], dtype=np.float32))
        assert not term
        assert trunc == (k == 19)


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


def test_cut_area_is_the_integral_of_the_profile():
    prof = DepthProfile((0.0, 3.0, 7.0, 12.0), (1.0, 0.5, 2.0), (2.0, 0.5, 3.0))
    for end in (0.0, 1.7, 3.0, 6.2, 12.0, 20.0):
        stop = min(end, 12.0)
        mid = (np.arange(200_000) + 0.5) * stop / 200_000  # midpoint rule
        numeric = float(np.sum(prof(mid)) * stop / 200_000)
        # The midpoint rule errs by up to a cell times a jump of depth (6e-5 mm x 1.5 mm).
        assert cut_area_mm2(prof, end) == pytest.approx(numeric, abs=1e-4)


def test_render_rgb_array():
    env = gym.make(MILLING, render_mode="rgb_array", scenario="paper_step")
    env.reset(seed=0)
    for _ in range(30):
        env.step(np.array([-0.8], dtype=np.float32))
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    assert img.std() > 0


def test_1e5_random_steps_never_nan():
    env = gym.make(MILLING)
    rng = np.random.default_rng(0)
    obs, info = env.reset(seed=0)
    bad = 0
    scenarios = ["train", "test", "paper_step", "paper_taper"]
    for k in range(100_000):
        # Mostly in-box, sometimes far out of it (clipped), over random scenarios and models.
        act = rng.uniform(-1.5, 1.5, size=1).astype(np.float32)
        obs, r, term, trunc, info = env.step(act)
        nums = [v for v in info.values() if isinstance(v, (float, int, np.number))]
        if not (np.all(np.isfinite(obs)) and np.isfinite(r) and np.all(np.isfinite(nums))):
            bad += 1
        if term or trunc:
            if k > 50_000 and env.unwrapped.params.force_model == "power_law":
                env = gym.make(MILLING, force_model="average_force")
            obs, info = env.reset(options={"scenario": scenarios[int(rng.integers(4))]})
    assert bad == 0


def test_env_class_usable_directly():
    env = EndMillingEnv(scenario="paper_step")
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs)
