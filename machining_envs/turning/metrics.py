"""Turning-v0's task: the regulation metrics of the cut (``machining_envs.core.metrics``)
and its primary score, the machining time of the workpiece counted only where the force
kept its limit (``machining_envs.core.score``)."""

from __future__ import annotations

from machining_envs.core.metrics import regulation_metrics
from machining_envs.core.score import REGULATION_SCORE, Task

__all__ = ["TURNING_TASK"]

#: Turning-v0's episode metrics and primary score.
TURNING_TASK = Task(regulation_metrics, REGULATION_SCORE, ("force_N", "force_limit_N"))
