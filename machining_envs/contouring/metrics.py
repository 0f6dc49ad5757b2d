"""Contouring metrics of one episode, from its recorded ``info`` trajectory.

The trajectory is a dict of equal-length arrays keyed by ``info`` names, the reset's info
first (see ``agents.eval.rollout``), from ``Contouring-v0`` or ``ContouringFeed-v0``.
"""

from __future__ import annotations

import math

import numpy as np

from machining_envs.core.metrics import (
    episode_end,
    finished_at,
    reads_info,
    score_bound,
    trajectory_severity,
)
from machining_envs.core.score import PrimaryScore, Task

__all__ = [
    "CONTOURING_SCORE",
    "CONTOURING_TASK",
    "FEED_SCORE",
    "FEED_TASK",
    "contouring_metrics",
    "circle_radius_errors",
    "STEADY_FRACTION",
]

#: On a circle, radius reduction and ellipse are measured once the set point has gone this
#: share of the way round (the start-up transient from rest has died out by then: a quarter
#: turn is 0.31 s at the paper's 50 mm/s, over 10 time constants of the slowest loop here).
STEADY_FRACTION = 0.25


def circle_radius_errors(traj: dict, steady_fraction: float = STEADY_FRACTION):
    """``(radius_reduction_mm, ellipse_mm)`` of a circle run, or NaNs if not a circle.

    With ``rho = |p - c|`` the table's distance from the circle's centre over the steady
    part (set point past ``steady_fraction`` of the path and not yet at its end; on a full
    circle that is three quarters of a turn, so it holds both axes of the ellipse):
    ``radius_reduction = R - (max(rho) + min(rho)) / 2`` and
    ``ellipse = (max(rho) - min(rho)) / 2``. When the axes' steady responses differ
    (gains ``Rx, Ry``, phases ``psi_x, psi_y``) the table runs an ellipse (paper §3.2) of
    half-axes ``a, b``: these are ``R - (a + b) / 2`` (positive when the circle shrinks; for
    first-order axes of time constant T about ``F^2 T^2 / (2R)``) and ``(a - b) / 2``.
    """
    if "circle_radius_mm" not in traj:
        return math.nan, math.nan
    radius = np.asarray(traj["circle_radius_mm"], dtype=np.float64)
    if radius.size == 0 or not np.isfinite(radius[0]):
        return math.nan, math.nan
    r = float(radius[0])
    cx = float(np.asarray(traj["circle_cx_mm"])[0])
    cy = float(np.asarray(traj["circle_cy_mm"])[0])
    s = np.asarray(traj["path_s_mm"], dtype=np.float64)
    length = float(np.asarray(traj["path_length_mm"])[0])
    steady = (s >= steady_fraction * length) & (s < length)
    if not steady.any():
        return math.nan, math.nan
    x = np.asarray(traj["x_mm"], dtype=np.float64)[steady]
    y = np.asarray(traj["y_mm"], dtype=np.float64)[steady]
    rho = np.hypot(x - cx, y - cy)
    hi, lo = float(rho.max()), float(rho.min())
    return r - 0.5 * (hi + lo), 0.5 * (hi - lo)


@reads_info(
    "t_s",
    "contour_error_mm",
    "peak_contour_error_mm",
    "tracking_error_mm",
    "circle_radius_mm",
    "circle_cx_mm",
    "circle_cy_mm",
    "path_s_mm",
    "path_length_mm",
    "x_mm",
    "y_mm",
    "finished",
    "machining_time_s",
    "torque_sq_Nm2",
    "command_x_mm_s",
    "command_y_mm_s",
    "cost",
    "score_bound",
    "time_limit_s",
    "diverged",
    "contour_tolerance_mm",
    "overload_ratio",
)
def contouring_metrics(traj: dict) -> dict[str, float]:
    """Metrics of one contouring episode.

    - ``max_contour_error_mm``: largest contour error (the distance from the table to the
      path) at any servo period (``peak_contour_error_mm`` where the env records the peak
      within a longer step); ``rms_contour_error_mm``: its root mean square over the steps;
    - ``max_tracking_error_mm``, ``rms_tracking_error_mm``: the same for the distance to the
      current set point;
    - ``radius_reduction_mm``, ``ellipse_mm``: on a circle, see :func:`circle_radius_errors`
      (NaN on other paths);
    - ``cycle_time_s``: when the run finished (set point at the end and the table in
      position), else the episode's length;
    - ``effort_rms_Nm``: root mean square of the motor torques (both axes), the control
      effort; ``peak_command_mm_s``: largest velocity command;
    - ``time_over_tolerance``: share of steps with a constraint cost (``info["cost"]``: the
      contour error past the tolerance; NaN where the env reports no cost);
    - ``peak_excess``, ``over_impulse_s``, ``overloaded``: how far past the tolerance
      (``machining_envs.core.metrics.severity``; where the env reports a cost);
    - ``score_bound``: the floor of the score from the run's truth (NaN where none);
    - ``time_limit_s``: the episode's truncation time, where the env reports it
      (ContouringFeed-v0; the primary score charges it to runs that do not count);
    - ``finished``, ``diverged`` (1.0 / 0.0), ``n_steps``.
    """
    t = np.asarray(traj["t_s"], dtype=np.float64)
    eps = np.asarray(traj["contour_error_mm"], dtype=np.float64)[1:]
    peak = np.asarray(traj.get("peak_contour_error_mm", traj["contour_error_mm"]), dtype=np.float64)
    peak = peak[1:]
    trk = np.asarray(traj["tracking_error_mm"], dtype=np.float64)[1:]
    out: dict[str, float] = {}
    out["max_contour_error_mm"] = float(peak.max()) if peak.size else 0.0
    out["rms_contour_error_mm"] = float(np.sqrt(np.mean(eps**2))) if eps.size else 0.0
    out["max_tracking_error_mm"] = float(trk.max()) if trk.size else 0.0
    out["rms_tracking_error_mm"] = float(np.sqrt(np.mean(trk**2))) if trk.size else 0.0
    dr, ell = circle_radius_errors(traj)
    out["radius_reduction_mm"] = dr
    out["ellipse_mm"] = ell
    finished, out["cycle_time_s"] = finished_at(traj, "machining_time_s", t)
    tsq = np.asarray(traj["torque_sq_Nm2"], dtype=np.float64)[1:]
    out["effort_rms_Nm"] = float(np.sqrt(np.mean(tsq))) if tsq.size else 0.0
    cmd = [np.asarray(traj[k], dtype=np.float64)[1:] for k in ("command_x_mm_s", "command_y_mm_s")]
    out["peak_command_mm_s"] = float(max(np.max(np.abs(c)) for c in cmd)) if cmd[0].size else 0.0
    if "cost" in traj:
        cost = np.asarray(traj["cost"], dtype=np.float64)[1:]
        out["time_over_tolerance"] = float(np.mean(cost > 0.0)) if cost.size else 0.0
        tol = np.asarray(traj["contour_tolerance_mm"], dtype=np.float64)[1:]
        out.update(trajectory_severity(traj, t, peak, tol, cost))
    else:
        out["time_over_tolerance"] = math.nan
    out["score_bound"] = score_bound(traj)
    if "time_limit_s" in traj:
        out["time_limit_s"] = float(np.asarray(traj["time_limit_s"], dtype=np.float64)[0])
    out.update(episode_end(traj, finished, t, flags=("diverged",)))
    return out


#: Contouring-v0: the largest contour error (the cycle time is set by the path); a run that
#: diverges or does not finish is charged the env's divergence limit.
CONTOURING_SCORE = PrimaryScore(
    "max_contour_error_mm",
    "largest contour error (µm)",
    over_key=None,
    secondary_key="rms_contour_error_mm",
    secondary_label="RMS contour error (mm)",
    failed_attr="divergence_mm",
    scale=1000.0,
)
#: ContouringFeed-v0: cycle time, counting only runs whose contour error stayed within the
#: tolerance 98 % of the time; others are charged their own time limit.
FEED_SCORE = PrimaryScore(
    "cycle_time_s",
    "cycle time (s)",
    over_key="time_over_tolerance",
    secondary_key="max_contour_error_mm",
    secondary_label="largest contour error (mm)",
)
#: Contouring-v0's episode metrics and primary score.
CONTOURING_TASK = Task(
    contouring_metrics, CONTOURING_SCORE, ("contour_error_mm", "contour_tolerance_mm")
)
#: ContouringFeed-v0's episode metrics and primary score.
FEED_TASK = Task(contouring_metrics, FEED_SCORE, ("peak_contour_error_mm", "contour_tolerance_mm"))
