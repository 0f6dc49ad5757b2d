"""What a process declares to the tooling: the benchmark of each of its envs
(:class:`BenchmarkSpec`) and its paper reproduction, in one :class:`Process`.

Each process's declaration is the ``PROCESS`` at the end of ``agents/bench/<process>.py``;
``agents.bench.declarations`` lists them. The benchmark, the score tables, the CLI and the
docs read these declarations and hold no knowledge of any process of their own. The env's
episode metrics and primary score are not declared here: they belong to the env's task
(``machining_envs.core.score.Task``, the env class's ``task``), which training uses too.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import gymnasium as gym
from gymnasium.envs.registration import load_env_creator

import machining_envs  # noqa: F401  (registers the env ids)
from agents.eval import task_of
from machining_envs.core.score import Task

__all__ = ["BenchmarkSpec", "Process", "TABLE_METRICS"]

#: Metrics shown in the printed table by default (all are in the CSV).
TABLE_METRICS = (
    "machining_time_s",
    "iae",
    "itae",
    "max_overshoot",
    "settling_time_s",
    "steady_state_error",
    "oscillation",
    "time_over_limit",
    "breakage",
    "finished",
)


@dataclass(frozen=True)
class BenchmarkSpec:
    """One env's part of the benchmark: which agents run on which scenarios, and how the
    table and plots show them."""

    env_id: str
    agents: tuple[Callable, ...]
    """Agent factories ``env -> agent``; a factory with ``learned = True`` is a learned
    policy (its row gets the paired margin over the best of the others)."""
    paper_scenarios: tuple[str, ...]
    heldout_scenario: str
    showcase_scenario: str
    """Scenario of the trajectory plot."""
    table_metrics: tuple[str, ...] = TABLE_METRICS
    #: (info key, reference key or None, axis label) of the trajectory plot's upper panel,
    #: (info key, label) of its lower panel and of the context drawn on the lower panel's
    #: right axis (None for none).
    plot_main: tuple[str, str | None, str] = ("force_N", "force_ref_N", "force (N)")
    plot_lower: tuple[str, str] = ("feed_mm_per_rev", "feed (mm/rev)")
    plot_context: tuple[str, str] | None = ("depth_mm", "depth (mm)")
    bar_metrics: tuple[tuple[str, str], ...] = (
        ("machining_time_s", "machining time (s)"),
        ("iae", "IAE (s)"),
        ("time_over_limit", "share of time over 1.1x reference"),
        ("breakage", "breakage rate"),
    )

    @property
    def task(self) -> Task:
        """The env's task (episode metrics and primary score), from its class."""
        entry = gym.spec(self.env_id).entry_point
        cls = load_env_creator(entry) if isinstance(entry, str) else entry
        return task_of(cls)

    @property
    def metrics_fn(self) -> Callable[[dict], dict]:
        return self.task.metrics


@dataclass(frozen=True)
class Process:
    """Everything the tooling needs to know about one machining process."""

    name: str
    """Short name, used on the command line (``machining-bench reproduce <name>``)."""
    benchmarks: tuple[BenchmarkSpec, ...]
    """The benchmark of each of the process's envs."""
    reproduce: Callable[..., list[dict]]
    """The paper reproduction: takes the output folder (or None), ``seed=`` and
    ``verbose=``, prints paper vs ours, saves its figures and returns one dict per
    experiment with a boolean ``"match"``."""
