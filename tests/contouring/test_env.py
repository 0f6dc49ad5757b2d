"""Contouring-v0 and ContouringFeed-v0 against the conventions every env keeps."""

import math
import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from machining_envs import ContouringEnv, ContouringFeedEnv, ContouringScenario, Path

CONTOURING = "machining_envs/Contouring-v0"
FEED = "machining_envs/ContouringFeed-v0"

DESIGN_INFO_KEYS = {
    "t_s",
    "command",
    "action_clipped",
    "breakage",
    "diverged",
    "x_mm",
    "y_mm",
    "x_ref_mm",
    "y_ref_mm",
    "contour_error_mm",
    "finished",
    "segment",
}


def _random_rollout(env, n_steps: int, seed: int):
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    out_obs, out_rew, out_eps = [obs], [], []
    for _ in range(n_steps):
        act = rng.uniform(-1, 1, size=env.action_space.shape).astype(np.float32)
        obs, r, term, trunc, info = env.step(act)
        out_obs.append(obs)
        out_rew.append(r)
        out_eps.append(info["contour_error_mm"])
        if term or trunc:
            obs, _ = env.reset()
            out_obs.append(obs)
    return np.array(out_obs), np.array(out_rew), np.array(out_eps)


@pytest.mark.parametrize("env_id", [CONTOURING, FEED])
def test_checkers_pass_without_warnings(env_id):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check_env(gym.make(env_id).unwrapped)
        gym_check_env(gym.make(env_id, scenario="paper_circle").unwrapped)
        sb3_check_env(gym.make(env_id).unwrapped, warn=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check_env(gym.make(FEED, servo="hinf").unwrapped)


def test_make_without_import_in_fresh_interpreter():
    code = (
        "import gymnasium as gym\n"
        "env = gym.make('machining_envs:machining_envs/Contouring-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "env2 = gym.make('machining_envs:machining_envs/ContouringFeed-v0')\n"
        "obs2, _ = env2.reset(seed=0)\n"
        "print(obs.shape, obs2.shape)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "(14,) (16,)"


@pytest.mark.parametrize("env_id,n", [(CONTOURING, 1000), (FEED, 300)])
def test_same_seed_bit_identical(env_id, n):
    a = _random_rollout(gym.make(env_id), n, seed=7)
    b = _random_rollout(gym.make(env_id), n, seed=7)
    for x, y in zip(a, b, strict=True):
        assert x.tobytes() == y.tobytes()
    c = _random_rollout(gym.make(env_id), n, seed=8)
    assert a[0].tobytes() != c[0].tobytes()


@pytest.mark.parametrize("env_id", [CONTOURING, FEED])
def test_pickle_mid_episode_continues_identically(env_id):
    env = gym.make(env_id, scenario="train")
    env.reset(seed=3)
    act = np.full(env.action_space.shape, 0.01, dtype=np.float32)
    for _ in range(20):
        env.step(act)
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(30):
        o1, r1, *_ = env.step(act)
        o2, r2, *_ = clone.step(act)
        assert o1.tobytes() == o2.tobytes() and r1 == r2


def test_async_vector_env_runs():
    for env_id, dim, act_dim in ((CONTOURING, 14, 2), (FEED, 16, 1)):
        envs = gym.vector.AsyncVectorEnv([lambda env_id=env_id: gym.make(env_id) for _ in range(2)])
        try:
            obs, _ = envs.reset(seed=[1, 2])
            assert obs.shape == (2, dim)
            for _ in range(10):
                obs, rew, term, trunc, info = envs.step(np.zeros((2, act_dim), dtype=np.float32))
            assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rew))
            assert "contour_error_mm" in info
        finally:
            envs.close()


@pytest.mark.parametrize("env_id", [CONTOURING, FEED])
def test_info_keys_and_units(env_id):
    env = gym.make(env_id, scenario="paper_circle")
    _, info0 = env.reset(seed=0)
    assert DESIGN_INFO_KEYS <= set(info0)
    assert (info0["x_mm"], info0["y_mm"]) == (10.0, 0.0)  # the table starts on the path
    _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert DESIGN_INFO_KEYS <= set(info)
    assert info["circle_radius_mm"] == 10.0 and info["feed_mm_s"] == 50.0


def test_contouring_step_semantics():
    env = gym.make(CONTOURING, scenario="paper_circle").unwrapped
    _, info = env.reset(seed=0)
    ts = env.params.sample_time_s
    _, _, _, _, info = env.step(np.array([0.3, -0.2], dtype=np.float32))
    assert info["t_s"] == pytest.approx(ts)
    assert info["command_x_mm_s"] == pytest.approx(0.3 * env.params.command_max_mm_s, rel=1e-6)
    # Set point one period along the circle at 50 mm/s.
    ang = 50.0 * ts / 10.0
    assert (info["x_ref_mm"], info["y_ref_mm"]) == pytest.approx(
        (10 * math.cos(ang), 10 * math.sin(ang)), abs=1e-12
    )
    assert info["contour_error_mm"] == pytest.approx(
        abs(math.hypot(info["x_mm"], info["y_mm"]) - 10.0), abs=1e-12
    )


def test_action_map_round_trip():
    env = gym.make(CONTOURING).unwrapped
    u = np.array([-333.0, 0.0, 120.0])
    np.testing.assert_allclose(env.action_to_command(env.command_to_action(u)), u)
    feed = gym.make(FEED).unwrapped
    assert feed.action_to_command(-1.0) == 0.0 and feed.action_to_command(0.0) == 1.0


@pytest.mark.parametrize(
    "env_id,name", [(CONTOURING, "ContouringEnv"), (FEED, "ContouringFeedEnv")]
)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_raises(env_id, name, bad):
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    act = np.zeros(env.action_space.shape, dtype=np.float32)
    act[0] = bad
    with pytest.raises(ValueError, match=name):
        env.step(act)


def test_out_of_box_action_is_clipped_and_counted():
    env = gym.make(CONTOURING).unwrapped
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([5.0, 0.0]))
    assert info["action_clipped"] and info["n_action_clipped"] == 1
    assert info["command_x_mm_s"] == pytest.approx(env.params.command_max_mm_s)
    _, _, _, _, info = env.step(np.array([0.1, -3.0]))
    assert info["command_y_mm_s"] == pytest.approx(-env.params.command_max_mm_s)
    _, _, _, _, info = env.step(np.array([0.1, 0.1]))
    assert not info["action_clipped"] and info["n_action_clipped"] == 2
    with pytest.raises(ValueError, match="2 value"):
        env.step(np.zeros(3))
    feed = gym.make(FEED).unwrapped
    feed.reset(seed=0)
    _, _, _, _, info = feed.step(np.array([4.0]))
    assert info["action_clipped"] and info["feed_override"] == 2.0


def test_bad_constructor_and_scenario_input():
    with pytest.raises(ValueError, match="inertia_x_kgm2"):
        gym.make(CONTOURING, inertia_x_kgm2=-1.0)
    with pytest.raises(ValueError, match="sample_time_s"):
        gym.make(CONTOURING, sample_time_s=0.0)
    with pytest.raises(ValueError, match="scenario"):
        gym.make(CONTOURING, scenario="paper_square")
    with pytest.raises(ValueError, match="in_position_mm"):
        gym.make(CONTOURING, in_position_mm=-1.0)
    env = gym.make(CONTOURING)
    with pytest.raises(ValueError, match="scenario"):
        env.reset(options={"scenario": "nonexistent"})
    with pytest.raises(ValueError, match="feed_mm_s"):
        ContouringScenario("x", Path.paper_circle(), feed_mm_s=-5.0)
    with pytest.raises(ValueError, match="inertia_scale"):
        ContouringScenario("x", Path.paper_circle(), 50.0, inertia_scale=(3.0, 1.0))
    with pytest.raises(ValueError, match="load_steps"):
        ContouringScenario("x", Path.paper_circle(), 50.0, load_steps=((0.1, 50.0, 0.0),))
    with pytest.raises(TypeError, match="screw_led_mm.*screw_lead_mm"):
        gym.make(CONTOURING, screw_led_mm=5.0)
    with pytest.raises(TypeError, match="contur"):
        gym.make(CONTOURING, reward={"contur": 1.0})
    with pytest.raises(ValueError, match="contour"):
        gym.make(CONTOURING, reward={"contour": -1.0})
    with pytest.raises(ValueError, match="servo"):
        gym.make(FEED, servo="pid")
    with pytest.raises(ValueError, match="tolerance_mm"):
        gym.make(FEED, tolerance_mm=0.0)
    with pytest.raises(ValueError, match="decision_interval_s"):
        gym.make(FEED, decision_interval_s=0.00033)
    with pytest.raises(ValueError, match="step command"):
        gym.make(FEED).reset(options={"scenario": "paper_step"})


def test_kwargs_override_parameters():
    env = gym.make(CONTOURING, screw_lead_mm=5.0, inertia_y_kgm2=0.02)
    env.reset(seed=0)
    assert env.unwrapped.params.screw_lead_mm == 5.0
    assert env.unwrapped.params.command_max_mm_s == pytest.approx(2000 / 60 * 5)
    assert env.unwrapped.plant.params.inertia_y_kgm2 != 0.0


def test_scenarios_by_name_and_object_and_train_vs_test():
    env = gym.make(CONTOURING)
    _, info = env.reset(seed=0, options={"scenario": "paper_corner"})
    assert info["scenario"] == "paper_corner" and info["path_length_mm"] == pytest.approx(100.0)
    sc = ContouringScenario("mine", Path.line((1.0, 1.0), (5.0, 4.0)), feed_mm_s=20.0)
    _, info = env.reset(options={"scenario": sc})
    assert info["scenario"] == "mine" and (info["x_mm"], info["y_mm"]) == (1.0, 1.0)
    feeds = {"train": [], "test": []}
    for name in feeds:
        for s in range(100):
            env.reset(seed=s, options={"scenario": name})
            feeds[name].append(env.unwrapped.scenario.feed_mm_s)
    assert min(feeds["train"]) >= 20.0 and max(feeds["train"]) <= 60.0
    assert min(feeds["test"]) < 20.0 and max(feeds["test"]) > 60.0


def test_episode_ends_when_the_path_is_done_diverged_or_time_is_up():
    # A simple P loop on the tracking error finishes a short line.
    env = gym.make(CONTOURING)
    sc = ContouringScenario("short", Path.line((0.0, 0.0), (1.0, 0.0)), feed_mm_s=10.0)
    obs, _ = env.reset(seed=0, options={"scenario": sc})
    umax = env.unwrapped.params.command_max_mm_s
    done = False
    while not done:
        obs, _, term, trunc, info = env.step((30.0 * obs[:2] / umax).astype(np.float32))
        done = term or trunc
    assert term and info["finished"] and not info["diverged"]
    assert 0.1 < info["machining_time_s"] == info["t_s"]
    # Full speed away from the path diverges.
    env.reset(seed=0, options={"scenario": "paper_circle"})
    done = False
    while not done:
        _, r, term, trunc, info = env.step(np.array([1.0, 1.0], dtype=np.float32))
        done = term or trunc
    assert term and info["diverged"] and info["tracking_error_mm"] > 50.0 and r < -100
    # Standing still is truncated at the time limit.
    env = gym.make(CONTOURING, max_episode_time_s=0.01)
    env.reset(seed=0, options={"scenario": "paper_circle"})
    for k in range(50):
        _, _, term, trunc, _ = env.step(np.zeros(2, dtype=np.float32))
        assert not term and trunc == (k == 49)
    # Feed hold in ContouringFeed-v0: truncated at five times the programmed time (+0.5 s).
    feed = gym.make(FEED, scenario="paper_circle")
    feed.reset(seed=0)
    n = 0
    done = False
    while not done:
        _, r, term, trunc, info = feed.step(np.array([-1.0], dtype=np.float32))
        n += 1
        done = term or trunc
    assert trunc and not term and info["path_s_mm"] == 0.0
    assert n == math.ceil((5 * 20 * math.pi / 50 + 0.5) / 0.01)


def test_feed_override_moves_the_set_point_and_finishes():
    env = gym.make(FEED, scenario="paper_circle")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.0], dtype=np.float32))  # override 1
    assert info["path_s_mm"] == pytest.approx(0.5)  # 50 mm/s for 10 ms
    _, _, _, _, info = env.step(np.array([1.0], dtype=np.float32))  # override 2
    assert info["path_s_mm"] == pytest.approx(1.5) and info["path_speed_mm_s"] == 100.0
    done = False
    while not done:
        _, _, term, trunc, info = env.step(np.array([0.0], dtype=np.float32))
        done = term or trunc
    assert term and info["finished"]
    assert info["peak_contour_error_mm"] >= info["contour_error_mm"]


def test_hidden_quantities_stay_out_of_the_observation():
    """Two runs differing only in hidden inertia and a later load give the same first obs."""
    env = gym.make(CONTOURING)
    a = ContouringScenario("a", Path.paper_circle(), 50.0)
    b = ContouringScenario(
        "b", Path.paper_circle(), 50.0, load_steps=((0.5, 1.0, 1.0),), inertia_scale=(1.3, 0.8)
    )
    oa, _ = env.reset(seed=0, options={"scenario": a})
    ob, _ = env.reset(seed=0, options={"scenario": b})
    assert oa.tobytes() == ob.tobytes()


@pytest.mark.parametrize("env_id", [CONTOURING, FEED])
def test_render_rgb_array(env_id):
    env = gym.make(env_id, render_mode="rgb_array", scenario="paper_circle")
    env.reset(seed=0)
    for _ in range(30):
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    assert img.std() > 0


def _no_nan_run(env, n_steps, scenarios, seed):
    rng = np.random.default_rng(seed)
    obs, info = env.reset(seed=seed)
    bad = 0
    shape = env.action_space.shape
    for _ in range(n_steps):
        act = rng.uniform(-1.5, 1.5, size=shape).astype(np.float32)  # sometimes clipped
        obs, r, term, trunc, info = env.step(act)
        nums = [v for v in info.values() if isinstance(v, (float, int, np.number))]
        if not (np.all(np.isfinite(obs)) and np.isfinite(r) and np.all(np.isfinite(nums))):
            bad += 1
        if not env.observation_space.contains(obs):
            bad += 1
        if term or trunc:
            obs, info = env.reset(
                options={"scenario": scenarios[int(rng.integers(len(scenarios)))]}
            )
    return bad


def test_1e5_random_steps_never_nan():
    # Short episodes (0.2 s) so that resets over every scenario kind happen often.
    env = gym.make(CONTOURING, max_episode_time_s=0.2)
    scen = ["train", "test", "paper_step_load", "paper_circle", "paper_involute", "paper_corner"]
    assert _no_nan_run(env, 100_000, scen, 0) == 0


def test_1e4_random_feed_steps_never_nan():
    # 10^4 decisions are 5 x 10^5 servo periods.
    env = gym.make(FEED, max_episode_time_s=0.5)
    scen = ["train", "test", "paper_circle", "paper_involute", "paper_corner"]
    assert _no_nan_run(env, 10_000, scen, 1) == 0


def test_env_classes_usable_directly():
    env = ContouringEnv(scenario="paper_involute")
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs)
    feed = ContouringFeedEnv(scenario="paper_involute", servo="hinf")
    obs, _ = feed.reset(seed=1)
    assert feed.observation_space.contains(obs)
