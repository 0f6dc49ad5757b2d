"""What a process declares to the tooling: the benchmark of each of its envs
(:class:`BenchmarkSpec`) and its paper reproduction, in one :class:`Process`.

Each process's declaration is the ``PROCESS`` at the end of ``agents/bench/<process>.py``;
``agents.bench.declarations`` lists them. The benchmark, the score tables, the CLI and the
docs read these declarations and hold no knowledge of any process of their own. The env's
episode metrics and primary score are not declared here: they belong to the env's task
(``machining_envs.core.score.Task``, the env class's ``task``), which training uses too.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field

import gymnasium as gym
from gymnasium.envs.registration import load_env_creator

import machining_envs  # noqa: F401  (registers the env ids)
from agents.eval import task_of
from machining_envs.core.score import Task
from machining_envs.core.workpieces import DepthProfile

__all__ = [
    "BenchmarkSpec",
    "ConstantDepthCut",
    "DeferredAgent",
    "Process",
    "Robustness",
    "TABLE_METRICS",
]

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
class Robustness:
    """The grid of the robustness heatmap: one constant-depth (or constant-parameter) cut
    per cell, ``scenario(x, y)`` building it from the two axes' values."""

    x_label: str
    x_values: tuple[float, ...]
    y_label: str
    y_values: tuple[float, ...]
    scenario: Callable[[float, float], object]


@dataclass(frozen=True)
class ConstantDepthCut:
    """A :class:`Robustness` grid's cell for turning or milling: at ``(speed, depth_mm)``, one
    constant depth over ``length_mm`` with the nominal process constants, ``speed`` being the
    scenario class's third argument (``spindle_rpm``, ``spindle_scale``)."""

    scenario_cls: type
    length_mm: float

    def __call__(self, speed: float, depth_mm: float):
        prof = DepthProfile.steps((depth_mm,), self.length_mm, name=f"{depth_mm:g} mm")
        return self.scenario_cls(f"grid_{speed:g}_{depth_mm:g}", prof, float(speed))


@dataclass(frozen=True)
class DeferredAgent:
    """An agent factory ``env -> Class.from_env(env)`` that imports ``Class`` (``path``:
    ``"module.Class"``) only when called: for agents whose imports are heavy or optional
    (the MPC oracles need CasADi)."""

    path: str

    def __call__(self, env):
        module, _, name = self.path.rpartition(".")
        return getattr(importlib.import_module(module), name).from_env(env)


@dataclass(frozen=True)
class BenchmarkSpec:
    """One env's part of the benchmark: which agents run, and how the report shows them.

    Rows, in the order the table prints them: the physical bound (from every episode's
    ``score_bound``), the MPC ``oracle`` (on the first ``oracle_episodes`` test episodes),
    the ``paper_agents`` at the papers' settings, the ``tuned`` classes at the settings of
    ``agents/bench/tuned.json`` (``agents.bench.tune``), and the ``learned`` policies
    (``agents/rl/pretrained/<name>``, each training seed a policy).
    """

    env_id: str
    paper_agents: tuple[Callable, ...]
    """Agent factories ``env -> agent`` at the papers' settings."""
    paper_scenarios: tuple[str, ...]
    showcase_scenario: str
    """Scenario of the paper-agent trajectory plot."""
    tuned: tuple[type, ...] = ()
    """Classical agent classes (with ``TUNABLE``) tuned by ``machining-bench tune``."""
    machine_tuned: tuple[type, ...] = ()
    """Classical agent classes ``machining-bench tune --machine`` tunes for a described
    machine (default: ``tuned``); the benchmark's ``shopfloor`` split runs them at the
    settings of ``agents/bench/tuned_shopfloor.json``, labelled "(tuned, shop floor)"."""
    machine_reference: type | None = None
    """The constant feed among ``machine_tuned``: the reference of the shop-floor rows."""
    learned: tuple[str, ...] = ()
    """Folders of ``agents/rl/pretrained`` whose policies the benchmark scores."""
    oracle: Callable | None = None
    """Factory of the MPC oracle (single env; reads the episode's truth)."""
    oracle_episodes: int = 10
    oracle_in_quick: bool = True
    """Whether ``--quick`` runs the oracle (on one episode)."""
    oracle_seconds: float = 10.0
    """About how long the oracle takes an episode on 2 cores, s (for the skip message)."""
    rows_seconds: float = 60.0
    """About how long the env's rows but the oracle take in the full run on one core, s
    (measured; docs/results.md has the last run). With ``--jobs``, the envs whose rows or oracle
    take longest start first."""
    env_kwargs: dict = field(default_factory=dict)
    """Keyword arguments of ``gym.make`` for every row (tuning uses them too)."""
    robustness: Robustness | None = None
    extra_splits: tuple[str, ...] = ()
    """Held-out splits beyond ``test`` and ``ood`` reported beside them (``wear``), with as
    many episodes as ``ood`` where ``agents.bench.benchmark.EXTRA_SIZES`` gives none (the
    full run: ``shopfloor`` 100)."""
    margin_points: tuple = ()
    """Operating points (``agents.eval.margins.OperatingPoint``) of the loop-margin table:
    every feedback agent linearised there (turning only)."""
    table_metrics: tuple[str, ...] = TABLE_METRICS
    """Metrics ``machining-bench evaluate`` prints."""
    #: (info key, limit key or None, axis label) of the trajectory plot's upper panel,
    #: (info key, label) of its lower panel and of the context drawn on the lower panel's
    #: right axis (None for none).
    plot_main: tuple[str, str | None, str] = ("force_N", "force_limit_N", "force (N)")
    plot_lower: tuple[str, str] = ("feed_mm_per_rev", "feed (mm/rev)")
    plot_context: tuple[str, str] | None = ("depth_mm", "depth (mm)")

    @property
    def machine_classes(self) -> tuple[type, ...]:
        """The classes tuned for a described machine and run on ``shopfloor``:
        ``machine_tuned``, or ``tuned`` where it names none."""
        return self.machine_tuned or self.tuned

    @property
    def expected_seconds(self) -> float:
        """About how long the env takes in the full run with its oracle apart, s: the
        longer of its rows and its oracle's episodes."""
        oracle = self.oracle_seconds * self.oracle_episodes if self.oracle is not None else 0.0
        return max(self.rows_seconds, oracle)

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
