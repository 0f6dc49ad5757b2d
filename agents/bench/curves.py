"""Learning curves of the shipped policies against the best tuned classical agent.

Each shipped training seed keeps ``eval.csv``: the env's primary score on the same
``validation`` episodes (seeds 5000, 5001, ...) at every evaluation made while training, with
the env steps and the wall time of the run. Per evaluation, the curve is the IQM over the
seeds with its 95 % stratified-bootstrap interval (rliable). The reference is the best tuned
classical agent scored on the very same validation episodes, run here. Reported: the first
evaluation at which the seeds' IQM is at least as good as the reference (env steps, and the
training wall time the runs recorded there), or the best IQM reached if none is.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agents.bench.figures import save_figure
from agents.eval.harness import evaluate_validation
from agents.eval.stats import iqm_interval

__all__ = ["LearningCurve", "learning_curve", "plot_learning_curves"]


@dataclass(frozen=True)
class LearningCurve:
    """The validation curve of one learned row over its training seeds (score units)."""

    name: str
    steps: np.ndarray  # (n_evals,) median env steps at each evaluation
    wall_s: np.ndarray  # (n_evals,) mean training wall time at each evaluation
    scores: np.ndarray  # (n_seeds, n_evals)
    iqm: np.ndarray
    low: np.ndarray
    high: np.ndarray
    n_episodes: int
    reference: str | None
    reference_score: float
    #: Index of the first evaluation whose IQM is <= the reference's score; None if none is.
    first_match: int | None

    def summary(self, scale: float, unit: str) -> str:
        n = self.scores.shape[0]
        head = (
            f"{self.name} ({n} seed{'s' if n > 1 else ''}, {self.n_episodes} validation "
            f"episodes per evaluation)"
        )
        if self.reference is None or not math.isfinite(self.reference_score):
            return f"{head}: no tuned reference to compare with."
        ref = f"{self.reference} scores {_g(self.reference_score * scale)} {unit} on them"
        if self.first_match is not None:
            k = self.first_match
            return (
                f"{head}: {ref}; the seeds' IQM first matches it at {self.steps[k]:.0f} env steps "
                f"({self.wall_s[k]:.0f} s of training as recorded), IQM "
                f"{_g(self.iqm[k] * scale)} [{_g(self.low[k] * scale)}, {_g(self.high[k] * scale)}]."
            )
        k = int(np.argmin(self.iqm))
        return (
            f"{head}: {ref}; the seeds' IQM never matches it within {self.steps[-1]:.0f} env "
            f"steps (best {_g(self.iqm[k] * scale)} [{_g(self.low[k] * scale)}, "
            f"{_g(self.high[k] * scale)}] at {self.steps[k]:.0f} steps)."
        )


def _g(v: float) -> str:
    return f"{v:.3g}" if abs(v) < 1000 else f"{v:.0f}"


def _read_eval(folder: Path) -> list[dict]:
    path = folder / "eval.csv"
    if not path.is_file():
        return []
    with open(path) as fh:
        return list(csv.DictReader(fh))


def learning_curve(
    name: str,
    seeds: list[tuple[int, Path]],
    env_id: str,
    env_kwargs: dict,
    score,
    failed,
    reference: tuple[str, object] | None,
    seed: int = 0,
) -> LearningCurve | None:
    """The curve of the policies ``seeds`` (``(seed, model path)``, their ``eval.csv`` beside
    each model) and the reference ``(name, agent factory)`` scored on the same validation
    episodes; None when no seed has an ``eval.csv``."""
    runs = [_read_eval(path.parent) for _, path in seeds]
    runs = [r for r in runs if r]
    if not runs:
        return None
    n_evals = min(len(r) for r in runs)
    scores = np.array([[float(e["score"]) for e in r[:n_evals]] for r in runs])
    steps = np.median([[int(e["timesteps"]) for e in r[:n_evals]] for r in runs], axis=0)
    wall = np.mean([[float(e["wall_s"]) for e in r[:n_evals]] for r in runs], axis=0)
    meta = seeds[0][1].parent / "config.json"
    n_episodes, first, allowances = 10, 0, None
    if meta.is_file():
        config = json.loads(meta.read_text())["config"]
        n_episodes = int(config.get("eval_episodes", 10))
        first = int(config.get("eval_first_episode", 0))
        allowances = config.get("eval_allowances")
    iqm, low, high = (np.empty(n_evals) for _ in range(3))
    for k in range(n_evals):
        iqm[k], low[k], high[k] = iqm_interval(scores[:, k : k + 1], seed)
    ref_name, ref_score, reached = None, math.nan, None
    if reference is not None:
        ref_name, factory = reference
        ev = evaluate_validation(factory, env_id, n_episodes, first, env_kwargs=env_kwargs)
        # scored as the runs chose their models: at every allowance where they did
        if allowances:
            from agents.rl.callbacks import selection_score  # (loads SB3: only here)

            ref_score = selection_score(ev.rows, score, failed, allowances)
        else:
            ref_score = float(score(ev.rows, failed)["score"])
        hits = np.flatnonzero(iqm <= ref_score)
        reached = int(hits[0]) if hits.size else None
    return LearningCurve(
        name, steps, wall, scores, iqm, low, high, n_episodes, ref_name, ref_score, reached
    )


def plot_learning_curves(
    curves: list[LearningCurve], env_id: str, scale: float, label: str, path: Path
) -> Path | None:
    """One panel: every learned row's IQM with its interval and its seeds, the reference."""
    from matplotlib.figure import Figure

    if not curves:
        return None
    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    for i, c in enumerate(curves):
        colour = f"C{i + 1}"
        for s in c.scores:
            ax.plot(c.steps, s * scale, color=colour, lw=0.6, alpha=0.35)
        ax.fill_between(c.steps, c.low * scale, c.high * scale, color=colour, alpha=0.25)
        ax.plot(c.steps, c.iqm * scale, color=colour, lw=2, label=f"{c.name}: IQM over seeds")
        if c.first_match is not None:
            ax.plot(c.steps[c.first_match], c.iqm[c.first_match] * scale, "o", color=colour)
    ref = next((c for c in curves if c.reference is not None), None)
    if ref is not None and math.isfinite(ref.reference_score):
        ax.axhline(
            ref.reference_score * scale,
            color="C2",
            ls="--",
            lw=1.2,
            label=f"{ref.reference}, same episodes",
        )
    top = max(np.nanpercentile(c.scores * scale, 95) for c in curves)
    if ref is not None and math.isfinite(ref.reference_score):
        top = max(top, ref.reference_score * scale * 1.5)
    ax.set_ylim(bottom=0, top=top * 1.05)
    ax.set_xlabel("env steps")
    ax.set_ylabel(f"{label} on validation (lower is better)")
    ax.set_title(f"{env_id}: learning curves (thin: single seeds)", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    return path
