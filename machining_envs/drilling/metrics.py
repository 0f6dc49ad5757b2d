"""Episode metrics of a micro-drilling run, computed from its recorded ``info`` trajectory.

A trajectory is a dict of equal-length arrays keyed by ``info`` names, the reset's info
first (see ``agents.eval.rollout``); the metrics ignore the reward.
"""

from __future__ import annotations

import numpy as np

from machining_envs.core.metrics import (
    episode_end,
    finished_at,
    reads_info,
    score_bound,
    trajectory_severity,
)
from machining_envs.core.score import PrimaryScore, Task

__all__ = ["DRILLING_SCORE", "DRILLING_TASK", "drilling_metrics", "drilling_mask"]


def drilling_mask(traj: dict) -> np.ndarray:
    """Samples (after the reset) at which the whole drill was cutting.

    The drill point's entry (the lips engaging from the chisel outwards, ``engagement < 1``)
    and the time spent out of the cut (pecks, retracts) are left out, so that torque and
    thrust statistics describe the drilling itself, as in the paper's Fig. 18-21.
    """
    cutting = np.asarray(traj["cutting"], dtype=bool)[1:]
    engaged = np.asarray(traj["engagement"], dtype=np.float64)[1:] >= 1.0 - 1e-12
    return cutting & engaged


@reads_info(
    "t_s",
    "cutting",
    "engagement",
    "torque_Nmm",
    "thrust_N",
    "torque_limit_Nmm",
    "cost",
    "spindle_hz",
    "peak_torque_Nmm",
    "breakage_torque_Nmm",
    "finished",
    "drilling_time_s",
    "position_mm",
    "depth_mm",
    "score_bound",
    "breakage",
    "diverged",
    "overload_ratio",
)
def drilling_metrics(traj: dict) -> dict[str, float]:
    """Metrics of one micro-drilling episode.

    Over the fully engaged drilling samples (:func:`drilling_mask`):

    - ``torque_mean_Nmm``, ``torque_std_Nmm``: mean and standard deviation of the true
      torque (the paper's "nominal cutting force" and its "fluctuation");
    - ``torque_mean_rel``, ``torque_std_rel``: the same over the torque limit;
    - ``thrust_mean_N``, ``thrust_std_N``: mean and standard deviation of the thrust;
    - ``time_over_limit``: share of those samples with a constraint cost (torque above the
      limit, ``info["cost"]``); ``peak_excess``, ``over_impulse_s`` and ``overloaded``
      over the same samples (``machining_envs.core.metrics.severity``);
    - ``spindle_min_hz``, ``spindle_max_hz``, ``spindle_range_hz``: the spindle frequency's
      range while drilling;

    and over the whole episode:

    - ``peak_torque_Nmm``: the largest torque at any sub-step; ``peak_torque_rel``: over the
      drill's breakage torque;
    - ``drilling_time_s``: when the hole reached its depth (the episode's length if never);
    - ``n_retracts``: times the drill point left the hole after it had started it;
    - ``finished``, ``breakage``, ``diverged`` (1.0 / 0.0); ``n_steps``.

    Statistics of an episode with no engaged sample (a drill broken on entry) are NaN.
    """
    t = np.asarray(traj["t_s"], dtype=np.float64)
    mask = drilling_mask(traj)
    tq = np.asarray(traj["torque_Nmm"], dtype=np.float64)[1:][mask]
    th = np.asarray(traj["thrust_N"], dtype=np.float64)[1:][mask]
    ref = np.asarray(traj["torque_limit_Nmm"], dtype=np.float64)[1:][mask]
    cost = np.asarray(traj["cost"], dtype=np.float64)[1:][mask]
    hz = np.asarray(traj["spindle_hz"], dtype=np.float64)[1:][mask]
    out: dict[str, float] = trajectory_severity(traj, t, tq, ref, cost)
    if tq.size:
        r = float(np.mean(ref))
        out["torque_mean_Nmm"] = float(np.mean(tq))
        out["torque_std_Nmm"] = float(np.std(tq))
        out["torque_mean_rel"] = out["torque_mean_Nmm"] / r
        out["torque_std_rel"] = out["torque_std_Nmm"] / r
        out["thrust_mean_N"] = float(np.mean(th))
        out["thrust_std_N"] = float(np.std(th))
        out["time_over_limit"] = float(np.mean(cost > 0.0))
        out["spindle_min_hz"] = float(np.min(hz))
        out["spindle_max_hz"] = float(np.max(hz))
        out["spindle_range_hz"] = float(np.ptp(hz))
    else:
        for k in (
            "torque_mean_Nmm",
            "torque_std_Nmm",
            "torque_mean_rel",
            "torque_std_rel",
            "thrust_mean_N",
            "thrust_std_N",
            "time_over_limit",
            "spindle_min_hz",
            "spindle_max_hz",
            "spindle_range_hz",
        ):
            out[k] = float("nan")
    peak = np.asarray(traj["peak_torque_Nmm"], dtype=np.float64)
    out["peak_torque_Nmm"] = float(np.max(peak))
    tb = np.asarray(traj["breakage_torque_Nmm"], dtype=np.float64)
    out["peak_torque_rel"] = out["peak_torque_Nmm"] / float(tb[0])
    finished, out["drilling_time_s"] = finished_at(traj, "drilling_time_s", t)
    pos = np.asarray(traj["position_mm"], dtype=np.float64)
    depth = np.asarray(traj["depth_mm"], dtype=np.float64)
    out_of_hole = (pos < 0.0) & (depth > 0.0)
    out["n_retracts"] = float(np.sum(out_of_hole[1:] & ~out_of_hole[:-1]))
    out["score_bound"] = score_bound(traj)
    out.update(episode_end(traj, finished, t))
    return out


#: MicroDrilling-v0: drilling time of the hole. With the paper's constant feed (voltage
#: control) every hole that counts takes the same time, so the score ranks the share of
#: holes kept under the torque limit; the torque fluctuation beside it tells the rest.
DRILLING_SCORE = PrimaryScore(
    "drilling_time_s",
    "drilling time (s)",
    secondary_key="torque_std_rel",
    secondary_label="torque std / limit",
)
#: MicroDrilling-v0's episode metrics and primary score.
DRILLING_TASK = Task(drilling_metrics, DRILLING_SCORE, ("torque_Nmm", "torque_limit_Nmm"))
