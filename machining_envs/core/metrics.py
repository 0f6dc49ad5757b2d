"""Episode metrics computed from recorded ``info`` trajectories, independent of any reward.

Every function takes a trajectory: a dict of equal-length arrays keyed by ``info`` names,
the reset's info first, one entry per step after it (see ``agents.eval.rollout``).

A metrics function may declare the ``info`` keys it reads with :func:`reads_info`; the
harness then records only those keys of the episodes it scores without keeping their
trajectories (``agents.eval.evaluate``), which saves most of the recording of an info
with many keys.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = [
    "reads_info",
    "excess_ratio",
    "severity",
    "trajectory_severity",
    "note_severity",
    "SEVERITY_KEYS",
    "regulation_metrics",
    "segment_bounds",
    "oscillation_amplitude",
    "episode_flag",
    "episode_end",
    "finish_time",
    "finished_at",
    "sample_period",
    "score_bound",
    "overload_ratio",
    "SETTLE_BAND",
    "OSC_WINDOW_S",
]

#: Half-width of the band that counts as settled (5 % of the limit).
SETTLE_BAND = 0.05
#: Window of the moving mean removed before measuring oscillation, s.
OSC_WINDOW_S = 1.0


def reads_info(*keys: str) -> Callable[[Callable], Callable]:
    """Mark a metrics function as reading only the ``info`` keys ``keys`` of a trajectory
    (read, or tested with ``in``), as its ``info_keys`` attribute (a frozenset): a
    trajectory without the other keys gives the same metrics. The trajectory's ``reward``
    and ``scenario`` entries are always there and need no declaring."""

    def mark(fn: Callable) -> Callable:
        fn.info_keys = frozenset(keys)
        return fn

    return mark


#: The per-step ``info`` keys :func:`note_severity` adds (a metrics function that reads
#: severity declares them).
SEVERITY_KEYS = ("excess", "overload_ratio")


def excess_ratio(signal, limit, cost) -> np.ndarray:
    """Per step, how far the constrained signal went over its limit: ``signal / limit - 1``
    on a step with a constraint cost (``cost > 0``, the env's own test of the limit), 0 on
    the others. Never NaN: a non-finite ratio (a zero limit) counts as 0."""
    y = np.asarray(signal, dtype=np.float64)
    lim = np.asarray(limit, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(np.asarray(cost, dtype=np.float64) > 0.0, y / lim - 1.0, 0.0)
    return np.where(np.isfinite(r), np.maximum(r, 0.0), 0.0)


def severity(excess: np.ndarray, dt: float, overload_ratio: float) -> dict[str, float]:
    """The episode's severity from its per-step excess ratios (the steps that count):

    - ``peak_excess``: the largest excess ratio (0.57: 57 % over the limit at worst);
    - ``over_impulse_s``: the time integral of the excess ratio, s (1 s at 10 % over and
      0.1 s at 100 % over both give 0.1 s);
    - ``overloaded``: 1.0 where the load passed the overload ceiling (``peak_excess`` above
      ``overload_ratio - 1``; the scenario's ``overload_ratio``), else 0.0. Such an episode
      does not count, whatever its share of steps over the limit
      (:meth:`machining_envs.core.score.PrimaryScore.counts`).

    The share of steps over the limit is each task's ``time_over_limit`` (or
    ``time_over_tolerance``).
    """
    e = np.asarray(excess, dtype=np.float64)
    peak = float(e.max()) if e.size else 0.0
    ceiling = float(overload_ratio) - 1.0 if math.isfinite(overload_ratio) else math.inf
    return {
        "peak_excess": peak,
        "over_impulse_s": float(e.sum() * dt),
        "overloaded": float(peak > ceiling),
    }


def trajectory_severity(traj: dict, t: np.ndarray, signal, limit, cost) -> dict[str, float]:
    """:func:`severity` of the steps of a trajectory that count: the excess ratios of their
    ``signal`` over ``limit`` (:func:`excess_ratio`, with their ``cost``), sampled at the
    period of the trajectory's times ``t`` (:func:`sample_period`), against the episode's
    overload ceiling (:func:`overload_ratio`)."""
    return severity(excess_ratio(signal, limit, cost), sample_period(t), overload_ratio(traj))


def note_severity(info: dict, keys: tuple[str, str] | None, overload_ratio) -> dict:
    """Add to a step's ``info`` (one env's, or a vector env's arrays) its ``excess`` (see
    :func:`excess_ratio`; ``keys`` = (signal, limit) info keys of the task, read with
    ``info["cost"]``) and ``overload_ratio`` (the scenario's overload ceiling, a multiple
    of the limit). Nothing is added for a task with no constrained signal (``keys`` None)
    or an info without those keys. Returns ``info``."""
    if keys is None or keys[0] not in info or keys[1] not in info or "cost" not in info:
        return info
    ex = excess_ratio(info[keys[0]], info[keys[1]], info["cost"])
    info["excess"] = float(ex) if ex.ndim == 0 else ex
    info["overload_ratio"] = (
        float(overload_ratio) if np.ndim(overload_ratio) == 0 else np.asarray(overload_ratio)
    )
    return info


def episode_flag(traj: dict, key: str) -> bool:
    """Whether the boolean ``info[key]`` (``finished``, ``breakage``, ...) was set at any
    sample of the trajectory."""
    return bool(np.any(np.asarray(traj[key], dtype=bool)))


def episode_end(
    traj: dict, finished: bool, t: np.ndarray, flags: tuple[str, ...] = ("breakage", "diverged")
) -> dict[str, float]:
    """The metrics an episode's dict ends with, in this order: ``finished`` and each of
    the boolean ``flags`` (1.0 / 0.0, :func:`episode_flag`), and ``n_steps``, the samples
    of ``t`` after the first."""
    out = {"finished": float(finished)}
    for key in flags:
        out[key] = float(episode_flag(traj, key))
    out["n_steps"] = float(t.size - 1)
    return out


def sample_period(t: np.ndarray) -> float:
    """The period of a trajectory's samples, s: the median step of its times ``t`` (0 for a
    trajectory of one sample), by which the time integrals of the metrics are taken."""
    return float(np.median(np.diff(t))) if t.size > 1 else 0.0


def finish_time(traj: dict, key: str, finished: bool, t: np.ndarray) -> float:
    """When the episode finished: the first finite ``traj[key]`` (the time the env reports
    once the work is done) if ``finished``; else, or if there is none, the episode's length
    ``t[-1]``."""
    mt = traj.get(key)
    if finished and mt is not None:
        vals = np.asarray(mt, dtype=np.float64)
        vals = vals[np.isfinite(vals)]
        if vals.size:
            return float(vals[0])
    return float(t[-1])


def finished_at(traj: dict, key: str, t: np.ndarray) -> tuple[bool, float]:
    """Whether the episode finished (``info["finished"]`` set at any sample,
    :func:`episode_flag`) and when (:func:`finish_time` of ``traj[key]``)."""
    finished = episode_flag(traj, "finished")
    return finished, finish_time(traj, key, finished, t)


def segment_bounds(segment: np.ndarray) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` index ranges over which ``segment`` is constant."""
    seg = np.asarray(segment)
    if seg.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(seg) != 0) + 1
    edges = [0, *cuts.tolist(), seg.size]
    return [(edges[i], edges[i + 1]) for i in range(len(edges) - 1)]


def oscillation_amplitude(e: np.ndarray, window: int) -> float:
    """Half the peak-to-peak of ``e`` less its moving mean, over the segment's second half."""
    if e.size < 2 * window + 4:
        return 0.0
    mean = np.convolve(e, np.ones(window) / window, mode="same")
    r = (e - mean)[window:-window]
    r = r[r.size // 2 :]
    return float(0.5 * np.ptp(r)) if r.size else 0.0


def overload_ratio(traj: dict) -> float:
    """The episode's overload ceiling (``info["overload_ratio"]``, a multiple of the limit,
    constant over an episode); inf (no ceiling) where the env reports none."""
    v = traj.get("overload_ratio")
    if v is None:
        return math.inf
    v = np.asarray(v, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(v[0]) if v.size else math.inf


def score_bound(traj: dict) -> float:
    """The episode's floor of its score (``info["score_bound"]``, constant over an
    episode), NaN where the env gives none."""
    b = traj.get("score_bound")
    if b is None:
        return float("nan")
    b = np.asarray(b, dtype=np.float64)
    b = b[np.isfinite(b)]
    return float(b[-1]) if b.size else float("nan")


@reads_info(
    "t_s",
    "force_N",
    "force_limit_N",
    "cost",
    "depth_mm",
    "segment",
    "score_bound",
    "finished",
    "machining_time_s",
    "breakage",
    "diverged",
    "overload_ratio",
)
def regulation_metrics(
    traj: dict, signal: str = "force_N", limit: str = "force_limit_N"
) -> dict[str, float]:
    """Metrics of one regulation episode.

    With the normalised gap ``e = (y - L) / L`` of the regulated signal ``y`` (true force or
    torque) to the process limit ``L``, sampled every ``dt`` (an agent regulating at 0.9 L
    has ``e = -0.1`` in steady state: these metrics read how close to the limit, and how
    steadily, a controller runs, whatever setpoint it chose):

    - ``iae``: sum |e| dt (s); ``itae``: sum t |e| dt (s^2);
    - ``max_overshoot``: largest e after the first entry into the 5 % band (0 if none), so the
      unavoidable jump when the tool enters a deeper step counts, a slow start does not;
    - ``settling_time_s``: mean over the start and every segment change of the time until
      |e| stays within 5 % for the rest of that segment (the segment's length when it never
      does; ``n_unsettled`` counts those);
    - ``steady_state_error``: mean over segments of |mean e| over the last 30 % of each;
    - ``oscillation``: largest over segments of half the peak-to-peak of e less its 1 s
      moving mean, over the segment's second half (sustained oscillation, not slow drift);
    - ``time_over_limit``: share of samples with a constraint cost (``info["cost"] > 0``,
      ``y`` above ``L``);
    - ``peak_excess``, ``over_impulse_s``, ``overloaded``: how far over the limit, see
      :func:`severity` (the ceiling from ``info["overload_ratio"]``; none where absent);
    - ``score_bound``: the episode's floor of the machining time (``info["score_bound"]``);
    - ``machining_time_s``: when the workpiece was finished (the episode's length if not);
    - ``finished``, ``breakage``, ``diverged`` (1.0 / 0.0); ``n_steps``.

    Its declared keys (:func:`reads_info`) are those of the default ``signal`` and
    ``limit``; a caller with others declares its own.
    """
    t = np.asarray(traj["t_s"], dtype=np.float64)
    y = np.asarray(traj[signal], dtype=np.float64)
    r = np.asarray(traj[limit], dtype=np.float64)
    cost = np.asarray(traj["cost"], dtype=np.float64)
    e = (y - r) / r
    dt = sample_period(t)
    # Sample 0 is the reset (t = 0, nothing cut yet); errors are scored from the first step,
    # and only while the tool is in the workpiece (the last sample of a finished cut is air).
    cutting = np.asarray(traj.get("depth_mm", np.ones(t.size)), dtype=np.float64)[1:] > 0
    te, ee = t[1:][cutting], e[1:][cutting]
    cost = cost[1:][cutting]
    ae = np.abs(ee)
    out: dict[str, float] = {
        "iae": float(np.sum(ae) * dt),
        "itae": float(np.sum(te * ae) * dt),
    }
    inside = np.flatnonzero(ae <= SETTLE_BAND)
    out["max_overshoot"] = float(max(0.0, ee[inside[0] :].max())) if inside.size else 0.0

    window = max(1, int(round(OSC_WINDOW_S / dt))) if dt > 0 else 1
    seg = np.asarray(traj.get("segment", np.zeros(t.size)))[1:][cutting]
    settle, sse, osc = [], [], []
    unsettled = 0
    for a, b in segment_bounds(seg):
        es = ee[a:b]
        bad = np.flatnonzero(np.abs(es) > SETTLE_BAND)
        if bad.size and bad[-1] == es.size - 1:
            unsettled += 1
            settle.append(es.size * dt)
        else:
            settle.append((bad[-1] + 1) * dt if bad.size else 0.0)
        tail = es[int(0.7 * es.size) :]
        sse.append(abs(float(tail.mean())) if tail.size else 0.0)
        osc.append(oscillation_amplitude(es, window))
    out["settling_time_s"] = float(np.mean(settle)) if settle else 0.0
    out["n_unsettled"] = float(unsettled)
    out["steady_state_error"] = float(np.mean(sse)) if sse else 0.0
    out["oscillation"] = float(max(osc)) if osc else 0.0
    out["time_over_limit"] = float(np.mean(cost > 0.0)) if cost.size else 0.0
    out.update(trajectory_severity(traj, t, y[1:][cutting], r[1:][cutting], cost))
    out["score_bound"] = score_bound(traj)
    finished, out["machining_time_s"] = finished_at(traj, "machining_time_s", t)
    out.update(episode_end(traj, finished, t))
    return out
