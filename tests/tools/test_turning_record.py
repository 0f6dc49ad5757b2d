"""A turning force record (CSV) in, the hidden plant out: the fit, its intervals, its replay."""

import csv

import gymnasium as gym
import numpy as np
import pytest

from machining_envs.core.workpieces import DepthProfile
from machining_envs.identification import (
    TURNING_RECORD_COLUMNS,
    IdentificationError,
    fit_turning_record,
    read_turning_record,
)
from machining_envs.turning import TurningParams
from machining_envs.turning.scenarios import TurningScenario
from tests.helpers import TURNING

HIDDEN = TurningParams().replace(force_coefficient=2400.0, feed_exponent=0.72)
#: Open-loop feed commands (actions), 1.5 s each: the record a shop would take.
LEVELS = (-0.6, -0.3, -0.7, -0.45, -0.2, -0.55)


def _record(params, scenario, seed=1):
    """Run the commands on ``params``; the record a data logger would write (measured force
    with the env's nominal sensor noise)."""
    env = gym.make(TURNING, params=params).unwrapped
    obs, _ = env.reset(seed=seed, options={"scenario": scenario})
    p, rows, k = env.params, [], 0
    while True:
        a = LEVELS[(k // 15) % len(LEVELS)]
        obs, _, terminated, truncated, info = env.step(np.array([a]))
        rows.append(
            (
                k * p.sample_time_s,
                (a + 1) / 2 * p.command_max,
                obs[0] * p.force_scale_N,
                scenario.spindle_rpm,
                info["depth_mm"],
            )
        )
        k += 1
        if terminated or truncated:
            return rows


def _columns(rows) -> dict:
    table = np.array(rows, dtype=np.float64)
    return {c: table[:, j] for j, c in enumerate(TURNING_RECORD_COLUMNS)}


def _write(path, rows):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(TURNING_RECORD_COLUMNS)
        w.writerows(rows)


SCENARIO = TurningScenario("rec", DepthProfile.steps((1.0, 2.0, 1.5, 2.5), 15.0), 405.0)


def test_a_record_recovers_the_hidden_plant_within_its_intervals(tmp_path):
    path = tmp_path / "cut.csv"
    _write(path, _record(HIDDEN, SCENARIO))
    fit = fit_turning_record(path)
    # nominal sensor noise (about 1 % of the force): within 1 %, and inside the 95 % intervals
    assert fit.params.force_coefficient == pytest.approx(2400.0, rel=0.01)
    assert fit.params.feed_exponent == pytest.approx(0.72, rel=0.01)
    lo, hi = fit.interval("force_coefficient")
    assert lo < 2400.0 < hi
    lo, hi = fit.interval("feed_exponent")
    assert lo < 0.72 < hi
    assert fit.fit.r_squared > 0.99 and fit.used.sum() > 200
    for z in (0.0, np.nan, True):
        with pytest.raises(ValueError, match="z must be a positive number"):
            fit.interval("feed_exponent", z)
    assert fit.plot(tmp_path / "fit.png") is not None and (tmp_path / "fit.png").is_file()


def test_the_fitted_scenario_replays_the_record_on_the_fitted_plant(tmp_path):
    rows = _record(HIDDEN, SCENARIO)
    fit = fit_turning_record(_columns(rows))
    scenario = fit.scenario()
    assert scenario.spindle_rpm == 405.0
    assert scenario.profile.start_depths_mm == (1.0, 2.0, 1.5, 2.5)
    # the servo model's position: within 2 % of the true 15 mm plateaus
    np.testing.assert_allclose(scenario.profile.edges_mm, [0, 15, 30, 45, 60], rtol=0.02)
    replay = _record(fit.params, scenario, seed=2)
    n = min(len(rows), len(replay))
    measured = np.array([r[2] for r in rows[:n]])
    replayed = np.array([r[2] for r in replay[:n]])
    cutting = measured > 100.0
    assert np.median(np.abs(replayed[cutting] / measured[cutting] - 1.0)) < 0.02


def test_records_it_cannot_fit_are_refused_saying_why(tmp_path):
    rows = _record(HIDDEN, SCENARIO)
    cols = _columns(rows)
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,command,force_N\n0,1,2\n")
    with pytest.raises(IdentificationError, match="missing columns .*spindle_rpm"):
        read_turning_record(bad)
    uneven = {**cols, "time_s": cols["time_s"] ** 1.1}
    with pytest.raises(IdentificationError, match="equal steps"):
        fit_turning_record(uneven)
    no_depth = {k: v for k, v in cols.items() if k != "depth_mm"}
    with pytest.raises(IdentificationError, match="depth_mm"):
        fit_turning_record(no_depth)
    ramp = {**cols, "command": np.linspace(1.0, 900.0, cols["time_s"].size)}
    with pytest.raises(IdentificationError, match="quasi-steady"):
        fit_turning_record(ramp, steady_tolerance=1e-6)
    for tol in (0.0, -1.0, 5.0, np.nan, True):
        with pytest.raises(IdentificationError, match=r"steady_tolerance must lie in \(0, 1\)"):
            fit_turning_record(cols, steady_tolerance=tol)
    for depth in (0.0, np.nan, True, "1"):
        with pytest.raises(IdentificationError, match="depth_mm must be a positive number"):
            fit_turning_record(no_depth, depth_mm=depth)
