"""The task every regulation env shares: the limit is observed, ``info["cost"]`` marks the
steps over it, ``info["score_bound"]`` is a floor no counting episode beats (checked
against an independent quadrature), and every classical agent's free parameters
(``TUNABLE``) are accepted, checked, and move its set point as a share of the limit."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from agents import (
    PD,
    ConstantFeed,
    ConstantOverride,
    ContourAFC,
    FixedGainIntegral,
    FixedGainPI,
    HInf2DOF,
    IntegralACC,
    LookAheadFeed,
    MillingConstantFeed,
    NoControl,
    PIPosition,
    SlidingMode,
    VariableGainPI,
)
from agents.eval import evaluate
from tests.helpers import CONTOURING, DRILLING, MILLING, TURNING

FEED = "machining_envs/ContouringFeed-v0"


def _turning_speed(env, sc, truth, a):
    """Feed velocity at the force limit (eq. 8 inverted), capped at the servo's top."""
    f = truth.feed_for_force(sc.force_limit_N, np.maximum(a, 1e-300))
    return np.where(
        a > 0,
        np.minimum(truth.max_feed_velocity_mm_s, f * sc.spindle_rpm / 60.0),
        truth.max_feed_velocity_mm_s,
    )


def _milling_speed(env, sc, truth, a):
    """Feed velocity at the torque limit (the torque law inverted, eq. 6), capped."""
    rpm = sc.spindle_rpm(env.unwrapped.params)
    ft = truth.feed_per_tooth_for_torque(sc.torque_limit_Nmm(truth), np.maximum(a, 1e-300))
    v = truth.feed_velocity_for_feed(ft, rpm)
    return np.where(
        a > 0, np.minimum(truth.max_feed_velocity_mm_s, v), truth.max_feed_velocity_mm_s
    )


#: env id -> (limit info key, signal info key, agent classes, speed at the limit, time key)
CASES = {
    TURNING: (
        "force_limit_N",
        "force_N",
        (ConstantFeed, FixedGainPI, VariableGainPI),
        _turning_speed,
    ),
    MILLING: (
        "torque_limit_Nmm",
        "torque_Nmm",
        (MillingConstantFeed, FixedGainIntegral, IntegralACC),
        _milling_speed,
    ),
}


def _flat_turning():
    from machining_envs import TurningScenario
    from machining_envs.core.workpieces import DepthProfile

    return TurningScenario("flat", DepthProfile.steps((2.0,), 40.0), 405.0, force_limit_N=1200.0)


def _flat_milling():
    from machining_envs.core.workpieces import DepthProfile
    from machining_envs.milling.scenarios import MillingScenario

    return MillingScenario("flat", DepthProfile.steps((2.0,), 40.0), torque_limit_scale=1.2)


#: A flat cut whose limit is 1.2x the nominal one.
FLAT = {TURNING: _flat_turning, MILLING: _flat_milling}
AGENT_CASES = [(env_id, cls) for env_id, c in CASES.items() for cls in c[2]]
#: Every classical agent with free parameters, for the TUNABLE check.
TUNABLE_CASES = AGENT_CASES + [
    (DRILLING, NoControl),
    (DRILLING, PD),
    (DRILLING, SlidingMode),
    (CONTOURING, PIPosition),
    (CONTOURING, HInf2DOF),
    (FEED, ConstantOverride),
    (FEED, LookAheadFeed),
    (FEED, ContourAFC),
]


@pytest.mark.parametrize("env_id", CASES)
def test_cost_is_one_exactly_where_the_signal_is_over_the_limit(env_id):
    limit_key, signal_key = CASES[env_id][:2]
    env = gym.make(env_id)
    obs, info = env.reset(seed=3, options={"scenario": "ood"})
    limit = info[limit_key]
    assert info["cost"] == 0.0 and np.isfinite(info["score_bound"])
    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(400):
        obs, _, term, trunc, info = env.step(rng.uniform(-1, 0.8, 1).astype(np.float32))
        assert info["cost"] == (1.0 if info[signal_key] > limit else 0.0)
        assert info[limit_key] == limit
        seen.add(info["cost"])
        if term or trunc:
            break
    assert seen == {0.0, 1.0}


BOUND_CASES = [(TURNING, n) for n in ("paper_245", "taper_405", "train", "ood")] + [
    (MILLING, n) for n in ("paper_step", "paper_taper", "train", "ood")
]


@pytest.mark.parametrize("env_id, name", BOUND_CASES)
def test_score_bound_matches_a_fine_quadrature(env_id, name):
    """The closed form (``DepthProfile.traverse_time_s``) against the midpoint rule on
    200 000 points of the speed the process law allows at the limit. The rule is exact on
    plateaus and second order on tapers; at each depth step it errs by at most one cell
    (length / 200 000) times the jump in 1/v, about 5e-6 of the total per step: hence 2e-5."""
    speed = CASES[env_id][3]
    env = gym.make(env_id)
    for sc_name in (name,):
        for seed in range(3):
            _, info = env.reset(seed=seed, options={"scenario": sc_name})
            sc = env.unwrapped.scenario
            truth = sc.true_params(env.unwrapped.params)
            n = 200_000
            x = (np.arange(n) + 0.5) * sc.profile.length_mm / n
            v = speed(env, sc, truth, np.asarray(sc.profile(x), dtype=float))
            quad = float(np.sum(1.0 / v) * sc.profile.length_mm / n)
            assert info["score_bound"] == pytest.approx(quad, rel=2e-5), (sc_name, seed)


@pytest.mark.parametrize("env_id, cls", AGENT_CASES, ids=lambda v: getattr(v, "__name__", v))
def test_counting_episodes_never_beat_the_bound(env_id, cls):
    """The floor holds for the paper's settings and for a conservative set point."""
    env = gym.make(env_id)
    score = env.unwrapped.task.score
    for setpoint in (1.0, 0.8):
        ev = evaluate(
            lambda e, s=setpoint: cls.from_env(e, setpoint=s), env_id, ["validation"], 12, seed=5000
        )
        for r in ev.rows:
            if score.counts(r):
                # (to rounding: a constant-feed hole takes its floor exactly)
                assert r[score.value_key] >= r["score_bound"] * (1 - 1e-9), (cls.__name__, r)


@pytest.mark.parametrize("env_id, cls", TUNABLE_CASES, ids=lambda v: getattr(v, "__name__", v))
def test_tunable_parameters_are_accepted_and_checked(env_id, cls):
    """Every key of ``TUNABLE`` is a keyword of ``from_env`` kept by the agent; a value
    outside the allowed range is refused with the parameter's name."""
    env = gym.make(env_id)
    mid = {
        k: (lo * hi) ** 0.5 if log else 0.5 * (lo + hi) for k, (lo, hi, log) in cls.TUNABLE.items()
    }
    agent = cls.from_env(env, **mid)
    for k, v in mid.items():
        assert getattr(agent, k) == pytest.approx(v)
    for key in cls.TUNABLE:
        with pytest.raises(ValueError, match=key):
            cls.from_env(env, **{key: -0.5})


@pytest.mark.parametrize("env_id, cls", [(TURNING, VariableGainPI), (MILLING, IntegralACC)])
def test_the_set_point_is_a_share_of_the_observed_limit(env_id, cls):
    """An adaptive controller at set point 0.8 holds the signal near 0.8 of the limit on a
    flat cut whose limit is not the nominal one."""
    limit_key, signal_key = CASES[env_id][:2]
    sc = FLAT[env_id]()
    ev = evaluate(
        lambda e: cls.from_env(e, setpoint=0.8), env_id, [sc], 1, seed=0, keep_trajectories=True
    )
    tr = ev.trajectories[0]
    late = tr[signal_key][len(tr[signal_key]) // 2 : -2]
    assert np.median(late) == pytest.approx(0.8 * tr[limit_key][0], rel=0.03)
