"""Severity of an episode (how far over the limit, for how long) and the overload ceiling,
on hand-made trajectories."""

import math

import numpy as np
import pytest

from machining_envs.core.metrics import (
    excess_ratio,
    note_severity,
    regulation_metrics,
    severity,
)
from machining_envs.core.score import REGULATION_SCORE


def _traj(force, limit=1000.0, dt=0.1, overload=1.5):
    n = len(force) + 1
    f = np.concatenate(([0.0], force))
    lim = np.full(n, limit)
    return {
        "t_s": np.arange(n) * dt,
        "force_N": f,
        "force_limit_N": lim,
        "cost": (f > lim).astype(float),
        "depth_mm": np.concatenate(([0.0], np.ones(n - 1))),
        "segment": np.zeros(n),
        "finished": np.concatenate((np.zeros(n - 1), [1.0])),
        "machining_time_s": np.concatenate((np.full(n - 1, np.nan), [(n - 1) * dt])),
        "breakage": np.zeros(n),
        "diverged": np.zeros(n),
        "overload_ratio": np.full(n, overload),
    }


def test_excess_ratio_is_zero_under_the_limit_and_never_nan():
    r = excess_ratio([900.0, 1100.0, 1570.0, 5.0], [1000.0, 1000.0, 1000.0, 0.0], [0, 1, 1, 1])
    np.testing.assert_allclose(r, [0.0, 0.1, 0.57, 0.0])
    assert np.isfinite(r).all()


def test_peak_impulse_share_and_the_ceiling_on_a_hand_made_cut():
    # 100 steps of 0.1 s: one step at 1.2x, one at 1.4x, the rest at 0.95x.
    force = np.full(100, 950.0)
    force[10], force[50] = 1200.0, 1400.0
    m = regulation_metrics(_traj(force))
    assert m["peak_excess"] == pytest.approx(0.4)
    assert m["over_impulse_s"] == pytest.approx((0.2 + 0.4) * 0.1)
    assert m["time_over_limit"] == pytest.approx(0.02)
    assert m["overloaded"] == 0.0
    # A single step at 1.6x passes the 1.5x ceiling: overloaded, does not count, although
    # it is one step in a hundred (under every allowance).
    force[50] = 1600.0
    m = regulation_metrics(_traj(force))
    assert m["overloaded"] == 1.0 and m["time_over_limit"] == pytest.approx(0.02)
    assert not REGULATION_SCORE.counts(m, allowance=0.05)
    # The same cut with a ceiling of 2x counts at an allowance above its 2 %.
    m2 = regulation_metrics(_traj(force, overload=2.0))
    assert m2["overloaded"] == 0.0 and REGULATION_SCORE.counts(m2, allowance=0.05)
    assert not REGULATION_SCORE.counts(m2, allowance=0.02)


def test_without_a_reported_ceiling_nothing_is_overloaded():
    assert severity(np.array([0.0, 3.0]), 0.1, math.inf)["overloaded"] == 0.0
    t = _traj(np.full(10, 5000.0))
    del t["overload_ratio"]
    assert regulation_metrics(t)["overloaded"] == 0.0


def test_note_severity_adds_the_step_excess_to_one_or_many_lanes():
    info = {"force_N": 1100.0, "force_limit_N": 1000.0, "cost": 1.0}
    note_severity(info, ("force_N", "force_limit_N"), 1.5)
    assert info["excess"] == pytest.approx(0.1) and info["overload_ratio"] == 1.5
    arrays = {
        "force_N": np.array([900.0, 1300.0]),
        "force_limit_N": np.full(2, 1000.0),
        "cost": np.array([0.0, 1.0]),
    }
    note_severity(arrays, ("force_N", "force_limit_N"), np.array([1.5, 2.0]))
    np.testing.assert_allclose(arrays["excess"], [0.0, 0.3])
    np.testing.assert_array_equal(arrays["overload_ratio"], [1.5, 2.0])
    plain = {"x": 1.0}
    assert note_severity(plain, None, 1.5) == {"x": 1.0}


@pytest.mark.parametrize(
    "env_id",
    [
        "machining_envs/Turning-v0",
        "machining_envs/EndMilling-v0",
        "machining_envs/MicroDrilling-v0",
        "machining_envs/Contouring-v0",
        "machining_envs/ContouringFeed-v0",
    ],
)
def test_every_constrained_env_reports_the_step_excess(env_id):
    import gymnasium as gym

    import machining_envs  # noqa: F401

    env = gym.make(env_id)
    _, info = env.reset(seed=0)
    assert info["excess"] == 0.0 or info["excess"] >= 0.0
    assert info["overload_ratio"] > 1.0
    _, _, _, _, info = env.step(env.action_space.high)
    assert np.isfinite(info["excess"]) and info["excess"] >= 0.0
    env.close()
    venv = gym.make_vec(env_id, num_envs=2)
    _, info = venv.reset(seed=0)
    assert info["excess"].shape == (2,) and (info["overload_ratio"] > 1.0).all()
    venv.close()
