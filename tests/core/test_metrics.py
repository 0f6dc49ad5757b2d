"""The regulation metrics (``machining_envs.core.metrics``) against hand-made trajectories."""

import numpy as np
import pytest

from machining_envs.core.metrics import regulation_metrics, sample_period


def _traj(force, segment=None, dt=0.1, finished_at=None):
    n = len(force)
    t = dt * np.arange(n)
    fin = np.zeros(n, dtype=bool)
    mt = np.full(n, np.nan)
    if finished_at is not None:
        fin[-1] = True
        mt[-1] = finished_at
    return {
        "t_s": t,
        "force_N": np.asarray(force, dtype=float),
        "force_limit_N": np.full(n, 1000.0),
        # The env's cost: the force above the limit.
        "cost": (np.asarray(force, dtype=float) > 1000.0).astype(float),
        "depth_mm": np.ones(n),
        "segment": np.zeros(n) if segment is None else np.asarray(segment),
        "finished": fin,
        "machining_time_s": mt,
        "breakage": np.zeros(n, dtype=bool),
        "diverged": np.zeros(n, dtype=bool),
    }


def test_metrics_of_a_constant_error():
    m = regulation_metrics(_traj([0.0] + [900.0] * 100, finished_at=9.95))
    assert m["iae"] == pytest.approx(0.1 * 100 * 0.1)
    assert m["itae"] == pytest.approx(0.1 * 0.1 * sum(0.1 * k for k in range(1, 101)))
    assert m["steady_state_error"] == pytest.approx(0.1)
    assert m["oscillation"] == pytest.approx(0.0, abs=1e-12)
    assert m["n_unsettled"] == 1.0 and m["time_over_limit"] == 0.0
    assert m["machining_time_s"] == 9.95 and m["finished"] == 1.0
    assert np.isnan(m["score_bound"])  # the record has none


def test_metrics_of_a_step_response():
    # Settles into the band at sample 11, overshoots the 1 kN limit by 20 % once, then
    # stays at it (a cost only on the overshoot).
    f = [0.0] + [500.0] * 10 + [1000.0, 1200.0] + [1000.0] * 60
    m = regulation_metrics(_traj(f))
    assert m["max_overshoot"] == pytest.approx(0.2)
    assert m["settling_time_s"] == pytest.approx(1.2)
    assert m["time_over_limit"] == pytest.approx(1 / 72)


def test_oscillation_is_measured_and_drift_is_not():
    k = np.arange(200)
    osc = 1000.0 + 300.0 * (-1.0) ** k  # 0.2 s period: the 1 s mean removes it exactly
    drift = np.linspace(500.0, 1500.0, 200)
    assert regulation_metrics(_traj(osc))["oscillation"] == pytest.approx(0.3, rel=1e-9)
    assert regulation_metrics(_traj(drift))["oscillation"] < 0.01


def test_the_sample_period_is_the_median_step_and_zero_for_one_sample():
    assert sample_period(np.array([0.0, 0.1, 0.2, 0.35])) == pytest.approx(0.1)
    assert sample_period(np.array([0.0])) == 0.0
    assert sample_period(np.array([])) == 0.0
