"""Every process's declaration (``PROCESS`` of ``agents/bench/<process>.py``), in one place.

A new process adds its module's ``PROCESS`` here; nothing else in the tooling changes.
"""

from __future__ import annotations

from agents.bench import contouring, drilling, milling, turning
from agents.bench.spec import BenchmarkSpec, Process

__all__ = ["PROCESSES", "BENCHMARKS", "process", "benchmark_spec"]

#: The declarations of every process, in the order the benchmark runs them.
PROCESSES: tuple[Process, ...] = (
    turning.PROCESS,
    milling.PROCESS,
    drilling.PROCESS,
    contouring.PROCESS,
)
#: The benchmark of every env, process by process.
BENCHMARKS: tuple[BenchmarkSpec, ...] = tuple(b for p in PROCESSES for b in p.benchmarks)


def process(name: str) -> Process:
    """The declaration of the process called ``name`` (``ValueError`` naming the choices)."""
    for p in PROCESSES:
        if p.name == name:
            return p
    raise ValueError(f"process must be one of {[p.name for p in PROCESSES]}, got {name!r}")


def benchmark_spec(env_id: str) -> BenchmarkSpec | None:
    """The benchmark of an env id; None for an id the benchmark does not run."""
    return next((b for b in BENCHMARKS if b.env_id == env_id), None)
