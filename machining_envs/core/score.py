"""The primary score of a task: one number per agent over its episodes, lower is better.

Every env is judged the same way: the mean of one per-episode metric (machining time,
drilling time, cycle time or contour error) where an episode *counts* only if it kept the
process's constraint, and an episode that does not count is charged a fixed cost (the
env's time limit, or its divergence limit), so that no agent can win by breaking the
constraint. The score's second column is a tracking measure reported beside it.

An episode counts if it finished, nothing broke or diverged, and (where the env has one)
the constrained signal spent under 2 % of the time over its limit: the share of steps with
a constraint cost (``info["cost"] > 0``: force or torque above the scenario's process limit,
contour error above its tolerance) stays under ``OVER_LIMIT_SHARE``, and the signal never
passed the scenario's overload ceiling (``overload_ratio`` times the limit: the episode's
``overloaded`` metric), however short the excursion, as a CNC's overload monitor stops the
program there. The limit is the scenario's, the same for every agent; where to regulate
below it is each agent's choice.

The 2 % is where a line is drawn, so the benchmark also scores every agent at the
``ALLOWANCES`` (0.5, 1 and 2 % of steps, the ceiling always on): ``counts``, ``charged``
and ``__call__`` take the allowance as ``allowance=``.

Each env also reports ``info["score_bound"]``: a floor of the episode's value computed from
its hidden truth (for Turning-v0, the time to cut the workpiece with the force exactly at
the limit everywhere, within the servo's top speed). ``efficiency = bound / charged value``
is 1 for an agent that reaches the floor and falls towards 0 as it wastes time.

>>> from machining_envs.core.score import REGULATION_SCORE
>>> row = {"machining_time_s": 30.0, "breakage": 0.0, "time_over_limit": 0.0,
...        "finished": 1.0, "itae": 5.0}
>>> REGULATION_SCORE([row, {**row, "breakage": 1.0}], failed_value=200.0)["score"]
115.0
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["PrimaryScore", "Task", "REGULATION_SCORE", "OVER_LIMIT_SHARE", "ALLOWANCES"]

#: An episode counts only if its constrained signal spent less than this share of the
#: time over its limit.
OVER_LIMIT_SHARE = 0.02
#: The allowances (shares of steps over the limit) a verdict must hold at.
ALLOWANCES = (0.005, 0.01, 0.02)


@dataclass(frozen=True)
class PrimaryScore:
    """How one env's episodes are scored (see the module docstring).

    ``failed_attr`` names the env attribute holding what an episode that does not count
    costs (in the units of ``value_key``); a row's own ``time_limit_s`` (envs whose limit
    depends on the path) takes its place when present.
    """

    value_key: str
    """Per-episode metric averaged into the score (lower is better)."""
    label: str
    """Name and unit of the score, for tables."""
    over_key: str | None = "time_over_limit"
    """Share of the time over the limit; the episode counts only if it is under 2 %."""
    secondary_key: str | None = "itae"
    """Tracking measure reported beside the score (mean over episodes)."""
    secondary_label: str = "ITAE"
    failed_attr: str = "max_episode_time_s"
    """Env attribute with the cost of an episode that does not count."""
    scale: float = 1.0
    """Factor applied to the score for display (1000 shows mm as µm)."""
    bound_key: str | None = "score_bound"
    """Per-episode floor of ``value_key`` from the episode's truth (NaN or absent: none)."""

    def counts(self, row: dict, allowance: float = OVER_LIMIT_SHARE) -> bool:
        """Whether an episode counts: finished, nothing broke or diverged and, where the
        score has a share over the limit (``over_key``), the load never passed the overload
        ceiling (``overloaded``) and the constraint held on all but less than
        ``allowance`` of the steps."""
        ok = row.get("finished", 0.0) == 1.0
        ok = ok and row.get("breakage", 0.0) == 0.0 and row.get("diverged", 0.0) == 0.0
        if self.over_key is not None:  # (a score of the error itself needs neither)
            over = row.get(self.over_key, math.nan)
            ok = ok and math.isfinite(over) and over < allowance
            ok = ok and row.get("overloaded", 0.0) == 0.0
        return bool(ok)

    def charged(self, row: dict, failed_value: float, allowance: float = OVER_LIMIT_SHARE) -> float:
        """What one episode adds to the score: its value, or the failure cost."""
        value = float(row[self.value_key])
        if self.counts(row, allowance):
            return value
        cost = float(row.get("time_limit_s", failed_value))
        return max(cost, value) if math.isfinite(value) else cost

    def efficiency(self, row: dict, failed_value: float) -> float:
        """``bound / charged value`` of one episode (NaN where the env gives no bound)."""
        if self.bound_key is None:
            return math.nan
        bound = float(row.get(self.bound_key, math.nan))
        charged = self.charged(row, failed_value)
        if not (math.isfinite(bound) and bound > 0 and charged > 0):
            return math.nan
        return bound / charged

    def __call__(self, rows: list[dict], failed_value: float) -> dict:
        """``score`` (mean charged value), ``valid`` (share that counts), ``efficiency``
        (mean of bound / charged value, NaN without a bound), ``secondary`` (mean of
        ``secondary_key``, NaN if absent) and ``itae`` (its alias, kept for the regulation
        envs' tables)."""
        if not rows:
            raise ValueError("rows must hold at least one episode")
        charged = [self.charged(r, failed_value) for r in rows]
        eff = [self.efficiency(r, failed_value) for r in rows]
        sec = (
            float(np.mean([r.get(self.secondary_key, math.nan) for r in rows]))
            if self.secondary_key
            else math.nan
        )
        return {
            "score": float(np.mean(charged)),
            "valid": float(np.mean([self.counts(r) for r in rows])),
            "efficiency": float(np.mean(eff)) if all(math.isfinite(e) for e in eff) else math.nan,
            "secondary": sec,
            "itae": sec,
        }

    def failed_value(self, env) -> float:
        """The failure cost read from an env (``failed_attr`` of its unwrapped env)."""
        v = getattr(getattr(env, "unwrapped", env), self.failed_attr, None)
        return float(v) if v is not None else math.nan


#: Turning-v0 and EndMilling-v0: machining time of the workpiece.
REGULATION_SCORE = PrimaryScore("machining_time_s", "machining time (s)")


@dataclass(frozen=True)
class Task:
    """What an env's episodes are judged by: its episode metrics and its primary score.

    Every env class carries its task as the class attribute ``task``, so that any tool
    (the harness, training evaluation, the benchmark) scores an env, including one a user
    registers under an id of their own, without knowing which process it simulates.
    """

    metrics: Callable[[dict], dict]
    """Per-episode metrics from a recorded ``info`` trajectory (dict of arrays)."""
    score: PrimaryScore
    """The primary score over those metrics."""
    limit_keys: tuple[str, str] | None = None
    """``(signal, limit)``: the ``info`` keys of the constrained signal and its limit, from
    which the env reports each step's ``excess`` (``machining_envs.core.metrics.
    note_severity``); None for a task with no constrained signal."""
