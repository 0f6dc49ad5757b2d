"""What Contouring-v0 and ContouringFeed-v0 do beyond the conventions every env keeps
(``tests/envs``): the set point and contour error of a step, the action maps, input checks,
keyword overrides, the ends of an episode, the feed override and hidden quantities."""

import math

import gymnasium as gym
import numpy as np
import pytest

from machining_envs import ContouringScenario, Path
from tests.helpers import CONTOURING, CONTOURING_FEED, run_until_done

FEED = CONTOURING_FEED


@pytest.mark.parametrize("env_id", [CONTOURING, FEED])
def test_info_values_at_reset_and_after_a_step(env_id):
    env = gym.make(env_id, scenario="paper_circle")
    _, info0 = env.reset(seed=0)
    assert (info0["x_mm"], info0["y_mm"]) == (10.0, 0.0)  # the table starts on the path
    _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert info["circle_radius_mm"] == 10.0 and info["feed_mm_s"] == 50.0


def test_an_action_of_the_wrong_size_is_refused():
    env = gym.make(CONTOURING).unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="2 value"):
        env.step(np.zeros(3))


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


def test_the_feed_env_refuses_a_step_command():
    with pytest.raises(ValueError, match="step command"):
        gym.make(FEED).reset(options={"scenario": "paper_step"})


def test_kwargs_override_parameters():
    env = gym.make(CONTOURING, screw_lead_mm=5.0, inertia_y_kgm2=0.02)
    env.reset(seed=0)
    assert env.unwrapped.params.screw_lead_mm == 5.0
    assert env.unwrapped.params.command_max_mm_s == pytest.approx(2000 / 60 * 5)
    assert env.unwrapped.plant.params.inertia_y_kgm2 != 0.0


def test_episode_ends_when_the_path_is_done_or_diverged_and_a_feed_hold_is_truncated():
    """(Truncation at ``max_episode_time_s`` is a convention: ``tests/envs``.)"""
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
    _, term, _, info, r = run_until_done(env, [1.0, 1.0])
    assert term and info["diverged"] and info["tracking_error_mm"] > 50.0 and r < -100
    # Feed hold in ContouringFeed-v0: truncated at five times the programmed time (+0.5 s).
    feed = gym.make(FEED, scenario="paper_circle")
    feed.reset(seed=0)
    n, term, trunc, info, _ = run_until_done(feed, [-1.0])
    assert trunc and not term and info["path_s_mm"] == 0.0
    assert n == math.ceil((5 * 20 * math.pi / 50 + 0.5) / 0.01)


def test_a_feed_lane_whose_loops_are_not_finite_diverges_alone_as_its_single_env():
    """A ContouringFeed-v0 lane whose closed loops turn NaN or infinite in a block (set
    here in its state) ends diverged, with a finite observation and reward, and only that
    lane: in a vector env of two groups of eight lanes (the loops run eight at a time)
    and in the single env with the lane's seed, the same numbers."""
    n = 16
    vec = gym.make_vec(FEED, num_envs=n, autoreset_mode="SAME_STEP")  # final_obs, final_info
    vec.reset(seed=0)
    actions = np.linspace(-0.5, 1.0, n, dtype=np.float32)[:, None]
    for _ in range(3):
        vec.step(actions)
    bad = {3: np.nan, 9: np.inf, 15: -np.inf}
    core = vec.unwrapped._core
    for lane, v in bad.items():
        core.state[lane, lane % core.state.shape[1]] = v
    obs, reward, term, _, info = vec.step(actions)
    hit = np.zeros(n, dtype=bool)
    hit[list(bad)] = True
    np.testing.assert_array_equal(info["final_info"]["diverged"] & hit, hit)
    np.testing.assert_array_equal(term, hit)
    assert np.isfinite(reward).all() and np.isfinite(obs).all()
    for lane, v in bad.items():
        env = gym.make(FEED).unwrapped
        env.reset(seed=lane)
        for _ in range(3):
            env.step(actions[lane])
        env._core.state[0, lane % env._core.state.shape[1]] = v
        o, r, t, _, i = env.step(actions[lane])
        assert t and i["diverged"]
        assert np.array_equal(o, info["final_obs"][lane]) and r == reward[lane]
    vec.close()


def test_feed_override_moves_the_set_point_and_finishes():
    env = gym.make(FEED, scenario="paper_circle")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.0], dtype=np.float32))  # override 1
    assert info["path_s_mm"] == pytest.approx(0.5)  # 50 mm/s for 10 ms
    _, _, _, _, info = env.step(np.array([1.0], dtype=np.float32))  # override 2
    assert info["path_s_mm"] == pytest.approx(1.5) and info["path_speed_mm_s"] == 100.0
    _, term, _, info, _ = run_until_done(env, [0.0])
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
