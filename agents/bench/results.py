"""The statistics of one env's benchmark, from its :class:`~agents.bench.run.EnvRun`.

Per agent and split (:func:`split_results`): the IQM of the charged values with its 95 %
interval, the share of episodes that count, the efficiency (bound / charged value), the
paired difference against the reference at every allowance of steps over the limit
(``machining_envs.core.score.ALLOWANCES``, the overload ceiling always on) and the verdict
over them (``agents.eval.stats.verdict``); for a learned row, each training seed's share of
counting episodes and the worst seed. The oracle's efficiency comes with its own interval
and with the physical bound on the oracle's own episodes.

The reference is the best tuned classical agent: among the rows of the spec's ``tuned``
classes, the lowest ``validation_score`` in ``tuned.json`` (chosen without looking at
``test``); the physical bound row is the floor on the reference's episodes (its env's
options). The rows tuned for the shop-floor machine (the ``shopfloor`` split's rows of the
spec's ``machine_tuned``, :func:`machine_reference`) are compared with the constant feed
tuned for that machine (the spec's ``machine_reference``), by the same rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from agents.bench.run import EnvRun
from agents.bench.tune import best_tuned
from agents.eval.stats import (
    AgentStats,
    agent_stats,
    allowance_sweep,
    iqm,
    iqm_interval,
    seed_count_shares,
)
from machining_envs.core.score import ALLOWANCES

__all__ = [
    "AgentResult",
    "SplitResults",
    "reference",
    "machine_reference",
    "split_results",
    "SEED_FLOOR",
    "fmt",
]

#: A training seed that keeps fewer than this share of its workpieces is flagged.
SEED_FLOOR = 0.8


def fmt(v: float | None, digits: int = 3) -> str:
    """``v`` to ``digits`` significant digits, no float noise (``1.05e-15`` prints ``0``)."""
    if v is None or not math.isfinite(v):
        return "–"
    if abs(v) < 1e-9:
        return "0"
    return f"{v:.{digits}g}" if abs(v) < 10**digits else f"{v:.0f}"


@dataclass
class AgentResult:
    """One agent on one split."""

    name: str
    kind: str
    stats: AgentStats
    #: Paired difference against the reference at each allowance (empty for the reference).
    diffs: list[dict] = field(default_factory=list)
    verdict: str = "–"
    #: Training seed -> share of its episodes that count (at the 2 % allowance).
    seed_shares: dict = field(default_factory=dict)
    #: Efficiency IQM with its interval (the oracle's row).
    efficiency_iqm: tuple[float, float, float] | None = None
    #: The physical bound's IQM on this agent's episodes (the oracle's row).
    bound_iqm: float | None = None

    @property
    def worst_seed(self) -> tuple[int, float] | None:
        if not self.seed_shares:
            return None
        seed = min(self.seed_shares, key=self.seed_shares.get)
        return seed, self.seed_shares[seed]


@dataclass
class SplitResults:
    split: str
    reference: str | None
    agents: dict[str, AgentResult]
    #: IQM of the physical bound over the split's episodes (None: the env gives none).
    bound_iqm: float | None
    n_episodes: int


def reference(run: EnvRun, tuned: dict) -> str | None:
    """The best tuned classical agent (see the module docstring)."""
    rows = {cls.__name__: name for name, cls in run.tuned_cls.items()}
    return rows.get(best_tuned(run.spec.env_id, tuned, among=rows))


def machine_reference(run: EnvRun) -> str | None:
    """The row of the constant feed tuned for the shop-floor machine (None: not run)."""
    cls = run.spec.machine_reference
    return next((n for n, c in run.machine_cls.items() if c is cls), None)


_ORDER = {"oracle": 0, "paper": 1, "tuned": 2, "learned": 3}


def _bounds(rows: list[dict], key: str | None) -> np.ndarray | None:
    b = np.array([r.get(key or "", math.nan) for r in rows], dtype=float)
    return b if b.size and np.all(np.isfinite(b)) else None


def split_results(run: EnvRun, split: str, ref: str | None, seed: int = 0) -> SplitResults:
    """Every agent's results on ``split`` (see the module docstring)."""
    score, failed = run.score, run.failed
    names = sorted(run.names(split), key=lambda n: (_ORDER[run.kind[n]], n in run.machine_cls))
    out: dict[str, AgentResult] = {}
    shop_ref = machine_reference(run)
    for name in names:
        rows = run.rows[name][split]
        res = AgentResult(name, run.kind[name], agent_stats(rows, score, failed, seed))
        own = shop_ref if name in run.machine_cls else ref
        if run.kind[name] == "oracle":
            res.verdict = "– (reads the truth)"
        elif own is not None and name != own and split in run.rows.get(own, {}):
            res.diffs, res.verdict = allowance_sweep(
                run.rows[own][split], rows, score, failed, seed
            )
            if own != ref:
                res.verdict = f"{res.verdict} (vs the shop-floor reference)"
        elif name == own:
            res.verdict = "reference" if own == ref else "reference (shop floor)"
        if run.kind[name] == "learned":
            res.seed_shares = seed_count_shares(rows, score)
        b = _bounds(rows, score.bound_key)
        if run.kind[name] == "oracle" and b is not None:
            eff = np.array([[score.efficiency(r, failed)] for r in rows])
            res.efficiency_iqm = iqm_interval(eff, seed)
            res.bound_iqm = float(iqm(b))
        out[name] = res
    others = [n for n in names if run.kind[n] != "oracle"] or names
    first = run.rows[others[0]][split] if others else []
    # The bound row: the floor on the reference's own rows where it has the split. Rows may
    # run on other env options with floors of their own (MicroDrilling-v0's control modes:
    # the voltage rows' floor is the travel at the programmed feed, which the peck cycles on
    # control="voltage_feed" beat); the best tuned agent's is the floor of the best way.
    src = run.rows.get(ref, {}).get(split) if ref is not None else None
    b = _bounds(src or first, score.bound_key)
    return SplitResults(
        split, ref, out, None if b is None else float(iqm(b)), len({r["seed"] for r in first})
    )


def flagged_seeds(results: list[SplitResults]) -> list[str]:
    """One line per (agent, seed, split) whose seed keeps fewer than ``SEED_FLOOR`` of its
    workpieces."""
    lines = []
    for sr in results:
        for res in sr.agents.values():
            for s, share in res.seed_shares.items():
                if share < SEED_FLOOR:
                    lines.append(
                        f"{res.name}, training seed {s}: {share:.0%} of the `{sr.split}` "
                        f"workpieces count (under {SEED_FLOOR:.0%})"
                    )
    return lines


def allowance_header() -> list[str]:
    return [f"Δ at {a * 100:g} %" for a in ALLOWANCES]


def _bound_row(label: str, value: float) -> str:
    """A table row of the physical bound, ``value`` in the score's unit."""
    return f"| {label} | bound | {fmt(value)} | – | 1 | " + "– | " * len(ALLOWANCES) + "– | – |"


def _oracle_bound_row(n_episodes: int, value: float) -> str:
    """The bound's row on the oracle's episodes (fewer than the split's)."""
    return _bound_row(f"physical bound, on the oracle's {n_episodes} ep.", value)


def _table_start(run: EnvRun, sr: SplitResults, score_head: str, verdict_head: str) -> list[str]:
    """The lines a split's table starts with: its head (``score_head`` and
    ``verdict_head`` name the score's and the verdict's columns) and the physical bound's
    row, where the split has one."""
    head = [
        "agent",
        "kind",
        score_head,
        "counts",
        "efficiency",
        *allowance_header(),
        verdict_head,
        "worst seed counts",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    if sr.bound_iqm is not None:
        lines.append(_bound_row("physical bound", sr.bound_iqm * run.score.scale))
    return lines


def markdown_table(run: EnvRun, sr: SplitResults) -> str:
    """The split's table: per agent its IQM [95 % CI], counts, efficiency, the paired
    difference at each allowance [95 % CI], the verdict and (learned rows) the worst
    seed's counting share."""
    k = run.score.scale
    lines = _table_start(
        run, sr, f"{run.score.label}: IQM [95 % CI]", f"verdict vs {sr.reference or 'best tuned'}"
    )
    for name, res in sr.agents.items():
        s = res.stats
        kind = res.kind
        if kind == "learned":
            kind = f"learned, {s.n_seeds} seed{'s' if s.n_seeds > 1 else ''}"
        eff = "–" if not math.isfinite(s.efficiency) else f"{s.efficiency:.2f}"
        if res.efficiency_iqm is not None:
            e, lo, hi = res.efficiency_iqm
            kind = f"oracle, {s.n_episodes} ep."
            eff = f"{e:.2f} [{lo:.2f}, {hi:.2f}]"
        if res.bound_iqm is not None and res.stats.n_episodes != sr.n_episodes:
            lines.append(_oracle_bound_row(s.n_episodes, res.bound_iqm * k))
        cells = [
            f"{d['diff'] * k:+.3g} [{fmt(d['low'] * k)}, {fmt(d['high'] * k)}]" for d in res.diffs
        ] or ["–"] * len(ALLOWANCES)
        worst = res.worst_seed
        worst_cell = "–" if worst is None else f"{worst[1]:.0%} (seed {worst[0]})"
        lines.append(
            f"| {name} | {kind} | {fmt(s.iqm * k)} [{fmt(s.iqm_low * k)}, {fmt(s.iqm_high * k)}] "
            f"| {s.count_rate:.0%} | {eff} | " + " | ".join(cells) + f" | {res.verdict} | "
            f"{worst_cell} |"
        )
    return "\n".join(lines)


def compact_table(run: EnvRun, sr: SplitResults) -> str:
    """The split's table with one number a cell (docs/results.md): IQM, counts,
    efficiency, the paired difference at each allowance, the verdict, the worst seed."""
    k = run.score.scale
    lines = _table_start(run, sr, f"{run.score.label} IQM", "verdict")
    for name, res in sr.agents.items():
        s = res.stats
        eff = "–" if not math.isfinite(s.efficiency) else f"{s.efficiency:.2f}"
        kind = res.kind
        if res.efficiency_iqm is not None:
            eff = f"{res.efficiency_iqm[0]:.2f}"
            kind = f"oracle ({s.n_episodes} ep.)"
            if res.bound_iqm is not None and s.n_episodes != sr.n_episodes:
                lines.append(_oracle_bound_row(s.n_episodes, res.bound_iqm * k))
        cells = [f"{d['diff'] * k:+.3g}" for d in res.diffs] or ["–"] * len(ALLOWANCES)
        worst = res.worst_seed
        lines.append(
            f"| {name} | {kind} | {fmt(s.iqm * k)} | {s.count_rate:.0%} | {eff} | "
            + " | ".join(cells)
            + f" | {res.verdict} | {'–' if worst is None else f'{worst[1]:.0%}'} |"
        )
    return "\n".join(lines)
