r"""End-milling episode metrics: the regulation metrics plus Park & Yoon's eq. (20) and MRR.

Machining time, eq. (20): the workpiece is cut in segments ``L_i`` at feeds ``f(i)``
(mm/rev) with the spindle at ``N`` rpm, so

.. math:: T_m = \sum_i \frac{L_i}{f(i)\,N} \quad\text{(min)}

Here ``L_i`` is the length of workpiece cut during sample ``i`` (the advance of the tool,
clipped to ``[0, L]``) and ``f(i)`` the mean feed per revolution over that sample
(``info["mean_feed_mm_per_rev"]``). The metal removal rate is the volume removed over the
machining time, ``MRR = w \int_0^L d(x)\,dx / T_m`` (mm³/min), ``w`` the axial depth.
"""

from __future__ import annotations

import numpy as np

from machining_envs.core.metrics import reads_info, regulation_metrics
from machining_envs.core.score import REGULATION_SCORE, Task

__all__ = ["MILLING_TASK", "milling_metrics", "machining_time_eq20_min"]


def machining_time_eq20_min(traj: dict) -> float:
    """Machining time (min) of eq. (20) from a trajectory's positions and mean feeds.

    Samples in which the tool did not move (``L_i = 0``) add nothing, as in the paper's
    sum; so a cut that never reaches the end of the workpiece gives the time spent on the
    part it did cut.
    """
    x = np.asarray(traj["position_mm"], dtype=np.float64)
    f = np.asarray(traj["mean_feed_mm_per_rev"], dtype=np.float64)[1:]
    n = np.asarray(traj["spindle_rpm"], dtype=np.float64)[1:]
    length = float(np.asarray(traj["workpiece_length_mm"], dtype=np.float64)[0])
    li = np.diff(np.clip(x, 0.0, length))
    moved = li != 0.0
    return float(np.sum(li[moved] / (f[moved] * n[moved])))


@reads_info(
    *(regulation_metrics.info_keys - {"force_N", "force_limit_N"}),
    "torque_Nmm",
    "torque_limit_Nmm",
    "position_mm",
    "mean_feed_mm_per_rev",
    "spindle_rpm",
    "workpiece_length_mm",
    "removed_volume_mm3",
)
def milling_metrics(traj: dict) -> dict[str, float]:
    """Regulation metrics of the torque (see ``regulation_metrics``) plus:

    - ``machining_time_min``: eq. (20) (see module doc);
    - ``mrr_mm3_per_min``: volume removed / ``machining_time_min``;
    - ``removed_volume_mm3``: volume removed by the end of the episode.
    """
    out = regulation_metrics(traj, signal="torque_Nmm", limit="torque_limit_Nmm")
    tm = machining_time_eq20_min(traj)
    vol = float(np.asarray(traj["removed_volume_mm3"], dtype=np.float64)[-1])
    out["machining_time_min"] = tm
    out["removed_volume_mm3"] = vol
    out["mrr_mm3_per_min"] = vol / tm if tm > 0 else 0.0
    return out


#: EndMilling-v0's episode metrics and primary score: the machining time of the workpiece,
#: counted only where the torque kept its limit.
MILLING_TASK = Task(milling_metrics, REGULATION_SCORE, ("torque_Nmm", "torque_limit_Nmm"))
