"""The milling agents: the paper's laws by hand, the SB3 protocol, batching, nominal design."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

from agents import FixedGainIntegral, IntegralACC, MillingConstantFeed
from agents.eval import rollout
from machining_envs import MillingParams
from tests.helpers import (
    MILLING,
    TURNING,
    agents_built_on_train_and_test,
    assert_batched_predict_equals_single,
    assert_sb3_evaluate_policy_runs,
)

FACTORIES = [MillingConstantFeed.from_env, FixedGainIntegral.from_env, IntegralACC.from_env]


def _obs(measured: float, reference: float = 1.0, rpm: float = 400.0) -> np.ndarray:
    o = np.zeros(7, dtype=np.float32)
    o[0], o[1], o[3] = measured, reference, rpm / 1000.0
    return o


@pytest.mark.parametrize("factory", FACTORIES)
def test_sb3_evaluate_policy_runs_agents_unchanged(factory):
    assert_sb3_evaluate_policy_runs(
        factory, MILLING, {"scenario": "train", "max_episode_time_s": 60.0}
    )


@pytest.mark.parametrize("factory", FACTORIES)
def test_batched_predict_equals_single(factory):
    agent = factory(gym.make(MILLING))
    assert_batched_predict_equals_single(agent, lambda: gym.make(MILLING), n_steps=60)


def test_integral_law_matches_eq_1_to_4_by_hand():
    env = gym.make(MILLING)
    ag = FixedGainIntegral.from_env(env, kc=0.2)
    p = env.unwrapped.params
    k = p.sensor_gain * p.torque_limit_Nmm  # counts per unit of observed torque
    a, s = ag.predict(_obs(0.0))
    w0 = 0.1 * k  # W(0) = Ts E(0), E = Tr - Tc in counts
    assert s[0, 0] == pytest.approx(w0)
    assert env.unwrapped.action_to_command(a[0]) == pytest.approx(0.2 * w0, rel=1e-6)  # U = Kc W
    a, s = ag.predict(_obs(0.6), state=s)
    assert s[0, 0] == pytest.approx(w0 + 0.1 * 0.4 * k)
    # Clipped at U = 0: W restarts from 0 (W = U / Kc), no windup below the range.
    a, s = ag.predict(_obs(9.0), state=s)
    assert a[0] == -1.0 and s[0, 0] == 0.0


def test_acc_estimator_follows_eq_14_to_19_by_hand():
    env = gym.make(MILLING)
    ag = IntegralACC.from_env(env)
    p = env.unwrapped.params
    ts = p.sample_time_s
    k = p.sensor_gain * p.torque_limit_Nmm
    _, s = ag.predict(_obs(0.0))
    km0, kc0 = s[0, 4], s[0, 5]
    # Design: Kc = 0.2 is the adapted gain at 1 mm, 400 rpm, the reference torque (the
    # observation is float32, hence 1e-6).
    assert kc0 == pytest.approx(0.2, rel=1e-6)
    assert km0 == pytest.approx(float(p.process_gain(1.0)), rel=1e-6)
    assert ag.k == pytest.approx(0.2 * km0 / ts)
    # One sample of a cut: Tc = 0.9 Tr with the command U held.
    s[0, 0], s[0, 3] = 100.0, 20.0
    w, km, kc, u = s[0, :4].copy()
    _, s2 = ag.predict(_obs(0.9), state=s)
    tc, tr = float(np.float32(0.9)) * k, k  # the observation is float32
    km_new = km + 1e-3 * (tc - u * km)  # eq. 14-15
    kc_new = kc + 1e-3 * (ts * ag.k - kc * km)  # eq. 18-19
    w_new = w + ts * (tr - tc)  # eq. 3
    assert s2[0, 1] == pytest.approx(km_new, rel=1e-12)
    assert s2[0, 2] == pytest.approx(kc_new, rel=1e-12)
    assert s2[0, 3] == pytest.approx(kc_new * w_new, rel=1e-12)  # eq. 2: U = Kc W


def test_acc_estimator_converges_to_tc_over_u_and_holds_k():
    """Steady torque and command: Km -> Tc / U (eq. 12) and Kc Km -> Ts K (eq. 16)."""
    env = gym.make(MILLING)
    ag = IntegralACC.from_env(env)
    _, s = ag.predict(_obs(1.0))
    for _ in range(20000):
        s[0, 0] = 30.0 / s[0, 2]  # hold U = 30 counts while the torque stays at Tr
        s[0, 3] = 30.0
        _, s = ag.predict(_obs(1.0), state=s)
    k = env.unwrapped.params.sensor_gain * env.unwrapped.params.torque_limit_Nmm
    assert s[0, 1] == pytest.approx(k / 30.0, rel=1e-6)
    assert s[0, 1] * s[0, 2] == pytest.approx(0.1 * ag.k, rel=1e-6)


def test_acc_holds_its_gains_while_cutting_air():
    env = gym.make(MILLING)
    ag = IntegralACC.from_env(env)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a, s = ag.predict(_obs(0.0))
        for _ in range(200):  # no torque: the command saturates, the gains stay put
            a, s = ag.predict(_obs(0.0), state=s)
    assert a[0] == 1.0
    assert s[0, 1] == s[0, 4] and s[0, 2] == s[0, 5]


def test_acc_keeps_the_loop_gain_where_the_fixed_gain_oscillates():
    """Kn = 0.025: Kc = 0.2 fixed oscillates on the 3 mm step; the ACC does not (Fig. 5, 13-14)."""
    out = {}
    for name, factory in (("fixed", FixedGainIntegral.from_env), ("acc", IntegralACC.from_env)):
        env = gym.make(MILLING, scenario="paper_step", servo_gain=0.025)
        tr = rollout(factory(env), env, seed=0)
        last = (tr["depth_mm"] == 3.0) & (tr["t_s"] > tr["t_s"][-1] - 30.0)
        out[name] = np.ptp(tr["torque_Nmm"][last]) / tr["torque_limit_Nmm"][0]
    assert out["fixed"] > 0.5 and out["acc"] < 0.1, out


def test_from_env_accepts_wrapped_envs_and_rejects_others():
    wrapped = gym.wrappers.RecordEpisodeStatistics(gym.make(MILLING))
    assert FixedGainIntegral.from_env(wrapped).io.sensor_gain == MillingParams().sensor_gain
    with pytest.raises(TypeError, match="EndMillingEnv"):
        IntegralACC.from_env(gym.make(TURNING))
    with pytest.raises(ValueError, match="kc"):
        FixedGainIntegral.from_env(gym.make(MILLING), kc=0.0)
    with pytest.raises(ValueError, match="c1"):
        IntegralACC.from_env(gym.make(MILLING), c1=-1e-3)
    with pytest.raises(ValueError, match="feed_mm_per_min"):
        MillingConstantFeed.from_env(gym.make(MILLING), feed_mm_per_min=1e4)
    with pytest.raises(ValueError, match="workpiece"):
        MillingConstantFeed.paper(gym.make(MILLING), "paper_wedge")


def test_agents_read_nominal_parameters_only():
    """A scenario's hidden Ks does not change what from_env builds."""
    a, b = agents_built_on_train_and_test(IntegralACC.from_env, MILLING)
    assert a.io == b.io and a.k == b.k


def test_constant_feed_holds_the_programmed_feed():
    env = gym.make(MILLING, scenario="paper_step")
    cf = MillingConstantFeed.paper(env, "paper_step")
    assert cf.feed_mm_per_min == pytest.approx(40.0 / 11.797)
    obs, _ = env.reset(seed=0)
    state = None
    for _ in range(50):
        act, state = cf.predict(obs, state)
        obs, _, _, _, info = env.step(act)
    assert 60.0 * info["feed_velocity_mm_s"] == pytest.approx(40.0 / 11.797, rel=1e-4)
    # The default planner's feed gives setpoint x the observed limit at 3 mm with the
    # nominal law.
    p = env.unwrapped.params
    for setpoint in (1.0, 0.7):
        d = MillingConstantFeed.from_env(env, setpoint=setpoint)
        act, _ = d.predict(obs)
        vf = p.servo_gain * env.unwrapped.action_to_command(act[0])
        ft = 60.0 * vf / (p.n_teeth * p.spindle_rpm)
        torque = float(p.steady_torque_Nmm(3.0, ft))
        assert torque == pytest.approx(setpoint * p.torque_limit_Nmm, rel=1e-6)
