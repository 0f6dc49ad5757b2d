"""Turning-v0 against the conventions every env keeps."""

import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from machining_envs import TurningEnv, TurningScenario
from machining_envs.core.workpieces import DepthProfile
from tests.conftest import TURNING, random_rollout

DESIGN_INFO_KEYS = {
    "t_s",
    "command",
    "action_clipped",
    "breakage",
    "diverged",
    "force_N",
    "force_ref_N",
    "measured",
    "feed_mm_per_rev",
    "depth_mm",
    "spindle_rpm",
    "position_mm",
}


def test_checkers_pass_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check_env(gym.make(TURNING).unwrapped)
        gym_check_env(gym.make(TURNING, scenario="paper_245").unwrapped)
        sb3_check_env(gym.make(TURNING).unwrapped, warn=True)


def test_make_without_import_in_fresh_interpreter():
    code = (
        "import gymnasium as gym\n"
        "env = gym.make('machining_envs:machining_envs/Turning-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "print(obs.shape)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "(7,)"


def test_same_seed_bit_identical_1000_steps():
    a = random_rollout(gym.make(TURNING), 1000, seed=7)
    b = random_rollout(gym.make(TURNING), 1000, seed=7)
    for x, y in zip(a, b, strict=True):
        assert x.tobytes() == y.tobytes()
    c = random_rollout(gym.make(TURNING), 1000, seed=8)
    assert a[0].tobytes() != c[0].tobytes()


def test_pickle_mid_episode_continues_identically():
    env = gym.make(TURNING)
    env.reset(seed=3)
    for _ in range(20):
        env.step(np.array([0.1], dtype=np.float32))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(30):
        o1, r1, *_ = env.step(np.array([0.2], dtype=np.float32))
        o2, r2, *_ = clone.step(np.array([0.2], dtype=np.float32))
        assert o1.tobytes() == o2.tobytes() and r1 == r2


def test_async_vector_env_runs():
    envs = gym.vector.AsyncVectorEnv([lambda: gym.make(TURNING) for _ in range(2)])
    try:
        obs, _ = envs.reset(seed=[1, 2])
        assert obs.shape == (2, 7)
        for _ in range(20):
            obs, rew, term, trunc, info = envs.step(np.zeros((2, 1), dtype=np.float32))
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rew))
        assert "force_N" in info
    finally:
        envs.close()


def test_info_keys_and_units():
    env = gym.make(TURNING, scenario="paper_405")
    _, info0 = env.reset(seed=0)
    assert DESIGN_INFO_KEYS <= set(info0)
    _, _, _, _, info = env.step(np.array([0.0], dtype=np.float32))
    assert DESIGN_INFO_KEYS <= set(info)
    assert info["t_s"] == pytest.approx(0.1)
    assert info["command"] == pytest.approx(0.5 * env.unwrapped.params.command_max)
    assert info["spindle_rpm"] == 405.0 and info["force_ref_N"] == 1000.0


def test_action_map_round_trip():
    env = gym.make(TURNING).unwrapped
    u = np.array([0.0, 1000.0, 4095.0])
    np.testing.assert_allclose(env.action_to_command(env.command_to_action(u)), u)
    assert env.action_to_command(-1.0) == 0.0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_raises(bad):
    env = gym.make(TURNING).unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="TurningEnv"):
        env.step(np.array([bad], dtype=np.float32))


def test_out_of_box_action_is_clipped_and_counted():
    env = gym.make(TURNING).unwrapped
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
        gym.make(TURNING, spindle_rpm=-405)
    with pytest.raises(ValueError, match="sample_time_s"):
        gym.make(TURNING, sample_time_s=0.0)
    with pytest.raises(ValueError, match="scenario"):
        gym.make(TURNING, scenario="paper_999")
    env = gym.make(TURNING)
    with pytest.raises(ValueError, match="scenario"):
        env.reset(options={"scenario": "nonexistent"})
    with pytest.raises(ValueError, match="spindle_rpm"):
        TurningScenario("x", DepthProfile.steps(), spindle_rpm=-1.0)
    with pytest.raises(TypeError, match="sensor_gian.*sensor_gain"):
        gym.make(TURNING, sensor_gian=15)
    with pytest.raises(TypeError, match="trackin"):
        gym.make(TURNING, reward={"trackin": 1.0})
    with pytest.raises(ValueError, match="tracking"):
        gym.make(TURNING, reward={"tracking": -1.0})


def test_kwargs_override_parameters_and_spindle():
    env = gym.make(TURNING, spindle_rpm=245, sensor_gain=15.0, scenario="paper_700")
    _, info = env.reset(seed=0)
    assert info["spindle_rpm"] == 245.0
    assert env.unwrapped.params.sensor_gain == 15.0


def test_scenarios_by_name_and_object():
    env = gym.make(TURNING)
    _, info = env.reset(seed=0, options={"scenario": "taper_405"})
    assert info["scenario"] == "taper_405" and info["workpiece_length_mm"] == 45.0
    sc = TurningScenario("mine", DepthProfile.steps((0.5, 1.5), 5.0), spindle_rpm=600.0)
    _, info = env.reset(options={"scenario": sc})
    assert info["scenario"] == "mine" and info["spindle_rpm"] == 600.0
    # train and test differ: the held-out set reaches speeds the training set never does.
    rpms = {name: [] for name in ("train", "test")}
    for name in rpms:
        for s in range(200):
            env.reset(seed=s, options={"scenario": name})
            rpms[name].append(env.unwrapped.scenario.spindle_rpm)
    assert min(rpms["train"]) >= 245.0 and max(rpms["train"]) <= 700.0
    assert min(rpms["test"]) < 245.0 and max(rpms["test"]) > 700.0


def test_episode_ends_when_workpiece_is_cut_and_on_breakage():
    env = gym.make(TURNING, scenario="paper_700")
    env.reset(seed=0)
    # Full feed on a 1 mm step: the force passes 3 kN only when the deeper steps arrive.
    done, info = False, {}
    while not done:
        _, _, term, trunc, info = env.step(np.array([1.0], dtype=np.float32))
        done = term or trunc
    assert term and info["breakage"] and info["peak_force_N"] > 3000.0
    sc = TurningScenario("short", DepthProfile.steps((0.5,), 3.0), spindle_rpm=700.0)
    env.reset(seed=0, options={"scenario": sc})
    done = False
    while not done:
        _, _, term, trunc, info = env.step(np.array([-0.5], dtype=np.float32))
        done = term or trunc
    assert term and info["finished"] and not info["breakage"]
    assert 0 < info["machining_time_s"] <= info["t_s"]


def test_truncation_by_time():
    env = gym.make(TURNING, max_episode_time_s=2.0)
    env.reset(seed=0)
    for k in range(20):
        _, _, term, trunc, _ = env.step(np.array([-1.0], dtype=np.float32))
        assert not term
        assert trunc == (k == 19)


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


def test_render_rgb_array():
    env = gym.make(TURNING, render_mode="rgb_array", scenario="paper_405")
    env.reset(seed=0)
    for _ in range(30):
        env.step(np.array([-0.2], dtype=np.float32))
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    assert img.std() > 0


def test_1e5_random_steps_never_nan():
    env = gym.make(TURNING)
    rng = np.random.default_rng(0)
    obs, info = env.reset(seed=0)
    bad = 0
    for _ in range(100_000):
        # Mostly in-box, sometimes far out of it (clipped), over random scenarios.
        act = rng.uniform(-1.5, 1.5, size=1).astype(np.float32)
        obs, r, term, trunc, info = env.step(act)
        nums = [v for v in info.values() if isinstance(v, (float, int, np.number))]
        if not (np.all(np.isfinite(obs)) and np.isfinite(r) and np.all(np.isfinite(nums))):
            bad += 1
        if term or trunc:
            scen = ["train", "test", "paper_245", "paper_700", "step_range"][int(rng.integers(5))]
            obs, info = env.reset(options={"scenario": scen})
    assert bad == 0


def test_env_class_usable_directly():
    env = TurningEnv(scenario="paper_405")
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs)
