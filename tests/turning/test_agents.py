"""The agent protocol: SB3's predict signature, state, episode starts, batching."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

from agents import ConstantFeed, FixedGainPI, VariableGainPI
from tests.helpers import (
    TURNING,
    agents_built_on_train_and_test,
    assert_batched_predict_equals_single,
    assert_sb3_evaluate_policy_runs,
)

FACTORIES = [ConstantFeed.from_env, FixedGainPI.from_env, VariableGainPI.from_env]


@pytest.mark.parametrize("factory", FACTORIES)
def test_sb3_evaluate_policy_runs_agents_unchanged(factory):
    assert_sb3_evaluate_policy_runs(factory, TURNING, {"scenario": "paper_700"})


@pytest.mark.parametrize("factory", FACTORIES)
def test_batched_predict_equals_single(factory):
    agent = factory(gym.make(TURNING))
    assert_batched_predict_equals_single(agent, lambda: gym.make(TURNING), n_steps=40)


def test_state_carries_the_integrator_and_episode_start_resets_it():
    env = gym.make(TURNING, scenario="paper_405")
    pi = FixedGainPI.from_env(env, kh=0.02)
    obs, _ = env.reset(seed=0)
    a0, s0 = pi.predict(obs)
    a1, s1 = pi.predict(obs, state=s0)  # same error again: the integral grows
    assert a1[0] > a0[0]
    a2, _ = pi.predict(obs, state=s1, episode_start=np.array([True]))
    assert a2[0] == a0[0]


def test_pi_law_matches_eq_13_by_hand():
    env = gym.make(TURNING)
    pi = FixedGainPI.from_env(env, kh=0.02, kgh=1.9)
    ke = env.unwrapped.params.sensor_gain
    umax = env.unwrapped.params.command_max
    obs = np.zeros(7, dtype=np.float32)
    obs[1] = 1.0  # reference 1 kN, measured 0
    obs[3] = 0.405
    a, s = pi.predict(obs)
    e0 = ke * 1000.0
    u0 = 0.02 * 1.9 * e0
    assert a[0] == pytest.approx(2 * u0 / umax - 1, rel=1e-6)
    obs[0] = 0.5
    a, s = pi.predict(obs, state=s)
    e1 = ke * 500.0
    assert s[0, 0] == pytest.approx(u0 + 0.02 * (1.9 * e1 - e0))


def test_adaptive_start_up_has_no_division_by_zero():
    env = gym.make(TURNING)
    ad = VariableGainPI.from_env(env)
    obs = np.zeros(7, dtype=np.float32)
    obs[1], obs[3] = 1.0, 0.405
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a, s = ad.predict(obs)
        for _ in range(5):
            a, s = ad.predict(obs, state=s)  # force stays 0: the estimate is held
    assert np.all(np.isfinite(s)) and np.isfinite(a).all()
    assert s[0, 1] == pytest.approx(
        ad.nominal_process_gain(np.array([405.0]), np.array([1000.0]))[0]
    )


def test_adaptive_estimate_is_the_papers_in_steady_state():
    """With force and command constant, Kp_hat converges to Fc / U (eq. 16)."""
    env = gym.make(TURNING)
    ad = VariableGainPI.from_env(env)
    ke = env.unwrapped.params.sensor_gain
    obs = np.zeros(7, dtype=np.float32)
    obs[1], obs[3] = 1.0, 0.405
    obs[0] = 1.0  # measured = reference: the command then stays put
    _, s = ad.predict(obs)
    s[:, 2:5] = 2000.0  # a steady command history
    s[:, 5:8] = 2000.0  # and the model output it settled to
    _, s = ad.predict(obs, state=s)
    assert s[0, 1] == pytest.approx(ke * 1000.0 / 2000.0, rel=1e-9)


def test_from_env_accepts_wrapped_envs_and_rejects_others():
    wrapped = gym.wrappers.RecordEpisodeStatistics(gym.make(TURNING))
    assert FixedGainPI.from_env(wrapped).io.sensor_gain == 17.0
    with pytest.raises(TypeError, match="TurningEnv"):
        FixedGainPI.from_env(gym.make("Pendulum-v1"))
    with pytest.raises(ValueError, match="kh"):
        FixedGainPI.from_env(gym.make(TURNING), kh=-1.0)


def test_agents_read_nominal_parameters_only():
    """A scenario's hidden Kf does not change what from_env builds."""
    a, b = agents_built_on_train_and_test(VariableGainPI.from_env, TURNING)
    assert a.io == b.io


def test_constant_feed_holds_feed_per_rev():
    env = gym.make(TURNING, scenario="paper_405")
    cf = ConstantFeed.from_env(env, feed_mm_per_rev=0.2)
    obs, _ = env.reset(seed=0)
    state = None
    for _ in range(50):
        act, state = cf.predict(obs, state)
        obs, _, _, _, info = env.step(act)
    assert info["feed_mm_per_rev"] == pytest.approx(0.2, rel=1e-3)
