"""Turning-v0's task: the limit is observed, the cost marks the steps over it, no agent that
counts beats the physical bound, and the agents' free parameters are accepted and checked."""

import gymnasium as gym
import numpy as np
import pytest

from agents import ConstantFeed, FixedGainPI, VariableGainPI
from agents.eval import evaluate
from machining_envs.core.score import REGULATION_SCORE
from tests.helpers import TURNING

AGENTS = (ConstantFeed, FixedGainPI, VariableGainPI)


def test_cost_is_one_exactly_where_the_force_is_over_the_limit():
    env = gym.make(TURNING)
    obs, info = env.reset(seed=3, options={"scenario": "ood"})
    limit = info["force_limit_N"]
    assert obs[1] == np.float32(limit / env.unwrapped.params.force_scale_N)
    assert info["cost"] == 0.0 and np.isfinite(info["score_bound"])
    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(300):
        obs, _, term, trunc, info = env.step(rng.uniform(-1, 0.6, 1).astype(np.float32))
        assert info["cost"] == (1.0 if info["force_N"] > limit else 0.0)
        assert info["force_limit_N"] == limit
        seen.add(info["cost"])
        if term or trunc:
            break
    assert seen == {0.0, 1.0}


@pytest.mark.parametrize("cls", AGENTS, ids=lambda c: c.__name__)
def test_counting_episodes_never_beat_the_bound(cls):
    """The floor holds for the paper's settings and for a conservative set point."""
    for setpoint in (1.0, 0.8):
        ev = evaluate(
            lambda e: cls.from_env(e, setpoint=setpoint), TURNING, ["validation"], 12, seed=5000
        )
        counted = [r for r in ev.rows if REGULATION_SCORE.counts(r)]
        for r in counted:
            assert r["machining_time_s"] >= r["score_bound"], (cls.__name__, setpoint, r)


@pytest.mark.parametrize("cls", AGENTS, ids=lambda c: c.__name__)
def test_tunable_parameters_are_accepted_and_checked(cls):
    env = gym.make(TURNING)
    mid = {
        k: (lo * hi) ** 0.5 if log else 0.5 * (lo + hi) for k, (lo, hi, log) in cls.TUNABLE.items()
    }
    agent = cls.from_env(env, **mid)
    for k, v in mid.items():
        assert getattr(agent, k) == pytest.approx(v)
    with pytest.raises(ValueError, match="setpoint"):
        cls.from_env(env, setpoint=-0.5)


def test_the_set_point_is_a_share_of_the_observed_limit():
    """An adaptive PI at set point 0.8 holds the force near 0.8 of the limit, on a cut with
    another limit than the nominal."""
    from machining_envs import TurningScenario
    from machining_envs.core.workpieces import DepthProfile

    sc = TurningScenario("flat", DepthProfile.steps((2.0,), 40.0), 405.0, force_limit_N=1200.0)
    ev = evaluate(lambda e: VariableGainPI.from_env(e, setpoint=0.8), TURNING, [sc], 1, seed=0,
                  keep_trajectories=True)  # fmt: skip
    tr = ev.trajectories[0]
    late = tr["force_N"][len(tr["force_N"]) // 2 : -2]
    assert np.median(late) == pytest.approx(0.8 * 1200.0, rel=0.03)
