"""Bad input to every env, the same way: keywords out of range, actions that are not real
numbers, options that are not a dict, and a bool where a parameter or a reward weight takes
a number, are refused with a message that names the env or the field."""

from __future__ import annotations

import copy
import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import machining_envs
from tests.helpers import CONTOURING, CONTOURING_FEED, DRILLING, MILLING, TURNING

NOT_REAL = ["0.3", b"0.3", np.array(["0.3"]), [0.3 + 1j], "abc", {}, True, [None]]


#: (env id, keywords it is made with, what the message must name)
BAD_VALUES = [
    (TURNING, {"spindle_rpm": -405}, "spindle_rpm"),
    (TURNING, {"scenario": "paper_999"}, "scenario"),
    (MILLING, {"spindle_rpm": -400}, "spindle_rpm"),
    (MILLING, {"force_model": "mechanistic"}, "force_model"),
    (MILLING, {"scenario": "paper_wedge"}, "scenario"),
    (MILLING, {"params": {"servo_gain": 0.02}}, "params"),
    (DRILLING, {"control": "pressure"}, "control"),
    (DRILLING, {"valve_damping": -0.7}, "valve_damping"),
    (DRILLING, {"nominal_voltage": 12.0}, "nominal_voltage"),
    (DRILLING, {"scenario": "paper_0.9"}, "scenario"),
    (DRILLING, {"max_episode_time_s": -1}, "max_episode_time_s"),
    (CONTOURING, {"inertia_x_kgm2": -1.0}, "inertia_x_kgm2"),
    (CONTOURING, {"scenario": "paper_square"}, "scenario"),
    (CONTOURING, {"in_position_mm": -1.0}, "in_position_mm"),
    (CONTOURING_FEED, {"servo": "pid"}, "servo"),
    (CONTOURING_FEED, {"tolerance_mm": 0.0}, "tolerance_mm"),
    (CONTOURING_FEED, {"decision_interval_s": 0.00033}, "decision_interval_s"),
]


@pytest.mark.parametrize("env_id, kwargs, match", BAD_VALUES)
def test_bad_values_are_refused_naming_them(env_id, kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make(env_id, **kwargs)


@pytest.fixture(scope="module", params=machining_envs.ENV_IDS)
def env(request):
    env = gym.make(request.param)
    env.reset(seed=0)
    yield env
    env.close()


@pytest.mark.parametrize("action", NOT_REAL, ids=repr)
def test_actions_must_be_real_numbers(env, action):
    name = type(env.unwrapped).__name__
    with pytest.raises(ValueError, match=f"{name}: action must be real numbers"):
        env.step(action)


@pytest.mark.parametrize("value", ["0.3", 0.3 + 1j, True], ids=repr)
def test_vector_actions_must_be_real_numbers(env, value):
    venv = gym.make_vec(env.spec.id, num_envs=2)
    venv.reset(seed=0)
    bad = np.full(venv.action_space.shape, value)
    with pytest.raises(ValueError, match="action.* real numbers"):
        venv.step(bad)


@pytest.mark.parametrize("options", ["train", 5, [("scenario", "train")]], ids=repr)
def test_reset_options_must_be_a_dict(env, options):
    with pytest.raises(TypeError, match="options"):
        env.reset(options=options)


def test_a_bool_is_not_a_number_for_any_parameter_or_reward_weight(env):
    base = env.unwrapped
    numeric = [
        f.name
        for f in dataclasses.fields(base.params)
        if isinstance(getattr(base.params, f.name), (int, float))
        and not isinstance(getattr(base.params, f.name), bool)
    ]
    assert numeric
    for name in numeric:
        with pytest.raises((TypeError, ValueError), match=name):
            gym.make(env.spec.id, **{name: True})
    reward_cls = type(base.reward_weights)
    for f in dataclasses.fields(reward_cls):
        if isinstance(getattr(base.reward_weights, f.name), (int, float)):
            with pytest.raises(ValueError, match=f.name):
                reward_cls(**{f.name: True})


# A few control periods of each env, so that an episode is truncated within tens of steps.
SHORT_EPISODE_S = {
    "machining_envs/Turning-v0": 2.0,
    "machining_envs/EndMilling-v0": 2.0,
    "machining_envs/MicroDrilling-v0": 0.5,
    "machining_envs/Contouring-v0": 0.01,
    "machining_envs/ContouringFeed-v0": 0.1,
}


@pytest.mark.parametrize("action_value", [1.0, -1.0])
def test_stepping_after_the_episode_ended_is_refused_until_reset(env, action_value):
    """One behaviour for every id: once a step returned terminated or truncated, the next
    step raises RuntimeError naming the env, and a reset starts a new episode."""
    short = gym.make(env.spec.id, max_episode_time_s=SHORT_EPISODE_S[env.spec.id])
    name = type(short.unwrapped).__name__
    action = np.full(short.action_space.shape, action_value, dtype=np.float32)
    short.reset(seed=1)
    for _ in range(10_000):
        _, _, terminated, truncated, _ = short.step(action)
        if terminated or truncated:
            break
    assert terminated or truncated
    obs_before = short.unwrapped._core.obs[0].copy()
    with pytest.raises(RuntimeError, match=f"{name}: the episode has ended"):
        short.step(action)
    assert np.array_equal(short.unwrapped._core.obs[0], obs_before)  # nothing was stepped
    short.reset(seed=2)
    short.step(action)
    short.close()


def test_a_step_needs_a_reset_and_refused_options_change_nothing(env):
    """Before the first reset there is no episode to step (RuntimeError naming the env);
    a reset whose options are refused changes nothing: the episode goes on."""
    fresh = gym.make(env.spec.id, render_mode="rgb_array", disable_env_checker=True).unwrapped
    action = np.zeros(fresh.action_space.shape, dtype=np.float32)
    for call in (lambda: fresh.step(action), fresh.render):
        with pytest.raises(RuntimeError, match=f"{type(fresh).__name__}: call reset"):
            call()
    fresh.reset(seed=0)
    fresh.step(action)
    twin = copy.deepcopy(fresh)
    with pytest.raises(ValueError, match="scenario"):
        fresh.reset(options={"scenario": "nonexistent"})
    np.testing.assert_array_equal(fresh.step(action)[0], twin.step(action)[0])


def test_a_start_that_raises_part_way_leaves_no_episode_to_step():
    """A scenario the parameters refuse (a limit above the tool's breakage force) raises in
    the start, after the lane has taken some of the new episode: nothing steps until a
    reset goes through."""
    env = gym.make("machining_envs/Turning-v0", breakage_force_N=1500.0).unwrapped
    action = np.zeros(1, dtype=np.float32)
    env.reset(seed=0, options={"scenario": "paper_405"})  # 1 kN limit
    env.step(action)
    high = dataclasses.replace(env.scenario, force_limit_N=2000.0)
    with pytest.raises(ValueError, match="below the tool's breakage_force_N"):
        env.reset(options={"scenario": high})
    with pytest.raises(RuntimeError, match="TurningEnv: call reset"):
        env.step(action)
    env.reset(seed=1, options={"scenario": "paper_405"})
    env.step(action)


# ---- checks across fields: each message names both fields ----------------------------------
def test_a_turning_limit_above_the_tools_breakage_force_is_refused():
    env = gym.make("machining_envs/Turning-v0", scenario="paper_405", breakage_force_N=900.0)
    with pytest.raises(ValueError, match="force_limit_N .* below the tool's breakage_force_N"):
        env.reset(seed=0)
    gym.make("machining_envs/Turning-v0", scenario="paper_405").reset(seed=0)  # 1 kN < 3 kN


def test_an_end_milling_limit_above_the_tools_breakage_torque_is_refused():
    from machining_envs import DepthProfile, MillingScenario

    sc = MillingScenario("high", DepthProfile.steps((1.0,), 30.0), torque_limit_scale=4.0)
    env = gym.make("machining_envs/EndMilling-v0", scenario=sc)
    limit = sc.torque_limit_Nmm(env.unwrapped.params)
    if limit < env.unwrapped.params.breakage_torque_Nmm:  # make it break below the limit
        env = gym.make("machining_envs/EndMilling-v0", scenario=sc, breakage_torque_Nmm=0.9 * limit)
    with pytest.raises(ValueError, match="torque limit .* below the tool's breakage_torque_Nmm"):
        env.reset(seed=0)


def test_a_drilling_limit_above_the_drills_breakage_torque_is_refused():
    from machining_envs import DrillingScenario

    sc = DrillingScenario("strong", 0.5, 10.0, torque_limit_Nmm=0.7)  # T_b = 0.625 N mm
    env = gym.make("machining_envs/MicroDrilling-v0", scenario=sc)
    with pytest.raises(ValueError, match="torque limit .* below the 0.5 mm drill's breakage"):
        env.reset(seed=0)


def test_a_drilling_feed_above_the_stages_top_speed_is_refused():
    from machining_envs import DrillingParams

    with pytest.raises(
        ValueError, match=r"feed_velocity_mm_s \(5\) must be at most feed_speed_max"
    ):
        DrillingParams(feed_velocity_mm_s=5.0)
    with pytest.raises(ValueError, match="feed_velocity_mm_s .* feed_speed_max_mm_s"):
        gym.make("machining_envs/MicroDrilling-v0", feed_speed_max_mm_s=0.2)


@pytest.mark.parametrize(
    "env_id", ["machining_envs/Contouring-v0", "machining_envs/ContouringFeed-v0"]
)
def test_a_feed_above_the_drives_top_speed_is_refused(env_id):
    from machining_envs import ContouringScenario, Path

    fast = ContouringScenario("fast600", Path.line((0, 0), (600, 0)), 1000.0)
    env = gym.make(env_id, scenario=fast)
    with pytest.raises(ValueError, match=r"feed_mm_s \(1000\) must be at most the drives' top"):
        env.reset(seed=0)
    ok = ContouringScenario("ok600", Path.line((0, 0), (600, 0)), 300.0)  # below 333 mm/s
    gym.make(env_id, scenario=ok).reset(seed=0)
