"""The benchmark's plots of one env, drawn from its run (``agents.bench.run.EnvRun``).

- score intervals: each agent's IQM with its 95 % interval on ``test``;
- performance profiles (rliable);
- the allowance plot: each agent's score (IQM) against the allowance of steps over the
  limit, the trade-off behind the verdict column;
- trajectories of the typical test episode, from the trajectories the run recorded (no
  episode simulated again): small multiples, one panel per agent, the limit drawn in each;
- the robustness heatmap of the regulation envs (its own grid of cuts).

Every agent is labelled once, by its name (a tuned agent's name says "(tuned)"); the kind
is the colour, in a legend beside the axes.
"""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np

from agents.bench.figures import save_figure
from agents.bench.run import EnvRun
from agents.eval import rollout
from agents.eval.stats import BOOTSTRAP_REPS, iqm, rliable_seed, score_matrix
from machining_envs.core.score import ALLOWANCES

__all__ = [
    "plot_scores",
    "plot_profiles",
    "plot_allowances",
    "plot_trajectories",
    "plot_robustness",
    "KIND_COLOUR",
]

KIND_COLOUR = {"bound": "0.3", "oracle": "k", "paper": "C0", "tuned": "C2", "learned": "C1"}
#: Allowances (share of steps over the limit) of the allowance plot's curves.
CURVE_ALLOWANCES = (0.0025, 0.005, 0.0075, 0.01, 0.015, 0.02, 0.03, 0.05)


def _kind_legend(fig, kinds) -> None:
    """A legend of the kinds present (colours), outside the axes, at the figure's foot."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=KIND_COLOUR[k], lw=3) for k in kinds]
    fig.legend(handles, list(kinds), loc="lower center", ncol=len(kinds), fontsize=8, frameon=False)


def plot_scores(run: EnvRun, stats: dict, path: Path) -> Path:
    from matplotlib.figure import Figure

    k = run.score.scale
    names = list(stats)
    fig = Figure(figsize=(7.5, 0.45 * len(names) + 1.9))
    ax = fig.subplots()
    for i, name in enumerate(names):
        s = stats[name]
        c = KIND_COLOUR[run.kind[name]]
        ax.plot([s.iqm_low * k, s.iqm_high * k], [i, i], color=c, lw=6, alpha=0.5)
        ax.plot([s.iqm * k], [i], "|", color=c, ms=14, mew=2)
    rows = next(iter(run.rows.values()))["test"]
    bounds = np.array([r.get("score_bound", math.nan) for r in rows]) * k
    if np.all(np.isfinite(bounds)):
        ax.axvline(float(iqm(bounds)), color="0.3", ls="--", lw=1)
        ax.text(
            float(iqm(bounds)),
            len(names) - 0.4,
            " physical bound (IQM)",
            fontsize=7,
            color="0.3",
            va="bottom",
        )
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_ylim(-0.6, len(names))
    ax.set_xlabel(f"{run.score.label}: IQM, 95 % CI (lower is better)")
    ax.set_title(f"{run.spec.env_id}: test split", fontsize=10)
    _kind_legend(fig, dict.fromkeys(run.kind[n] for n in names))
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    save_figure(fig, path)
    return path


def plot_profiles(run: EnvRun, path: Path) -> Path:
    """Performance profiles: the share of test episodes whose efficiency exceeds tau (or,
    without a bound, whose score is below tau), with rliable's bootstrap bands."""
    from matplotlib.figure import Figure
    from rliable import library

    score, failed = run.score, run.failed
    names = run.names("test")
    eff = {n: [score.efficiency(r, failed) for r in run.rows[n]["test"]] for n in names}
    has_bound = all(math.isfinite(e) for es in eff.values() for e in es)
    mats = {}
    for n in names:
        rows = run.rows[n]["test"]
        if has_bound:
            by_p: dict = {}
            for r, e in zip(rows, eff[n], strict=True):
                by_p.setdefault(r.get("policy_seed", 0), {})[r["seed"]] = e
            seeds = sorted(next(iter(by_p.values())))
            mats[n] = np.array([[by_p[p][s] for p in sorted(by_p)] for s in seeds])
        else:
            mats[n] = -score_matrix(rows, score, failed)[1] * score.scale
    if has_bound:
        taus = np.linspace(0.0, 1.0, 41)
        xlabel = "efficiency tau (bound / charged value)"
    else:
        lo = min(m.min() for m in mats.values())
        taus = np.linspace(lo, 0.0, 41)
        xlabel = f"-({score.label}) tau"
    with rliable_seed(0):
        prof, ci = library.create_performance_profile(mats, taus, reps=min(BOOTSTRAP_REPS, 500))
    fig = Figure(figsize=(9, 4))
    ax = fig.subplots()
    for i, n in enumerate(names):
        c = KIND_COLOUR[run.kind[n]] if run.kind[n] == "oracle" else f"C{i % 10}"
        ax.plot(taus, prof[n], color=c, lw=1.5, label=n)
        ax.fill_between(taus, ci[n][0], ci[n][1], color=c, alpha=0.15)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("share of episodes above tau")
    ax.set_title(f"{run.spec.env_id}: performance profiles (test)", fontsize=10)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    fig.tight_layout()
    save_figure(fig, path)
    return path


def allowance_curves(run: EnvRun, allowances=CURVE_ALLOWANCES) -> dict[str, np.ndarray]:
    """Each agent's score IQM on ``test`` at each allowance (score units, unscaled)."""
    out = {}
    for n in run.names("test"):
        rows = run.rows[n]["test"]
        out[n] = np.array(
            [float(iqm(score_matrix(rows, run.score, run.failed, a)[1])) for a in allowances]
        )
    return out


def plot_allowances(run: EnvRun, path: Path) -> Path | None:
    """Each agent's score (IQM on ``test``) against the allowance of steps over the limit,
    the ceiling always on; the verdict's allowances marked. None for a score that has no
    allowance (Contouring-v0)."""
    if run.score.over_key is None:
        return None
    from matplotlib.figure import Figure

    k = run.score.scale
    curves = allowance_curves(run)
    x = 100.0 * np.array(CURVE_ALLOWANCES)
    fig = Figure(figsize=(9, 4.2))
    ax = fig.subplots()
    for i, (n, y) in enumerate(curves.items()):
        c = KIND_COLOUR[run.kind[n]] if run.kind[n] == "oracle" else f"C{i % 10}"
        ls = {"paper": ":", "tuned": "-", "learned": "--", "oracle": "-"}[run.kind[n]]
        ax.plot(x, y * k, color=c, ls=ls, marker="o", ms=3, lw=1.3, label=n)
    for a in ALLOWANCES:
        ax.axvline(100.0 * a, color="0.8", lw=0.8, zorder=0)
    ax.set_xlabel("allowance: share of steps over the limit that still counts (%)")
    ax.set_ylabel(f"{run.score.label}, IQM (lower is better)")
    ax.set_title(
        f"{run.spec.env_id}: score against the allowance (test; grey: the verdict's)", fontsize=10
    )
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    fig.tight_layout()
    save_figure(fig, path)
    return path


def plot_trajectories(run: EnvRun, path: Path) -> Path | None:
    """The typical test episode (``run.plot_seed``) of every agent, from the recorded
    trajectories: one panel per agent (shared axes), the constrained signal with its limit
    and, on the right axis in grey, the command (the spec's lower signal). The signal axis
    stops at 1.5 times the limit (or three times the typical peak) so that an agent that
    diverges does not hide the others."""
    from matplotlib.figure import Figure

    spec = run.spec
    trajs = run.trajectories
    if not trajs:
        return None
    key, lim_key, label = spec.plot_main
    low_key, low_label = spec.plot_lower
    names = sorted(trajs, key=lambda n: ["oracle", "paper", "tuned", "learned"].index(run.kind[n]))
    ncol = min(3, len(names))
    nrow = math.ceil(len(names) / ncol)
    fig = Figure(figsize=(3.6 * ncol + 0.6, 2.3 * nrow + 0.9))
    axes = np.atleast_1d(fig.subplots(nrow, ncol, sharex=True, sharey=True, squeeze=False)).ravel()
    peaks = [float(np.nanmax(np.abs(trajs[n][key]))) for n in names]
    lim = None
    low_max = max(float(np.nanmax(trajs[n][low_key])) for n in names)
    for ax, name in zip(axes, names, strict=False):
        tr = trajs[name]
        c = KIND_COLOUR[run.kind[name]]
        ax.plot(tr["t_s"], tr[key], color=c, lw=1)
        if lim_key is not None and lim_key in tr:
            lim = float(tr[lim_key][0])
            ax.axhline(lim, color="k", ls="--", lw=0.7)
        ax2 = ax.twinx()
        ax2.plot(tr["t_s"], tr[low_key], color="0.6", lw=0.7)
        ax2.set_ylim(0.0, 1.1 * low_max if low_max > 0 else 1.0)
        ax2.tick_params(labelsize=6, colors="0.5")
        ax.set_title(name, fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    top = 1.5 * lim if lim is not None else 3.0 * float(np.median(peaks))
    if max(peaks) > top:
        axes[0].set_ylim(top=top)
    for ax in axes[::ncol]:
        ax.set_ylabel(label, fontsize=8)
    for ax in axes[(nrow - 1) * ncol :]:
        ax.set_xlabel("time (s)", fontsize=8)
    fig.suptitle(
        f"{spec.env_id}: typical test episode (seed {run.plot_seed}); dashed: the limit; "
        f"grey, right axis: {low_label}",
        fontsize=9,
    )
    fig.tight_layout()
    save_figure(fig, path)
    return path


def plot_robustness(run: EnvRun, ref: str | None, path: Path) -> Path | None:
    """Efficiency of the best tuned classical agent and of the learned agent (first seed)
    over the spec's grid (one episode per cell, seed 0)."""
    from matplotlib.figure import Figure

    grid = run.spec.robustness
    learned = [n for n, k in run.kind.items() if k == "learned"]
    who = [n for n in (ref, learned[0] if learned else None) if n is not None]
    if not who:
        return None
    fig = Figure(figsize=(4.8 * len(who) + 1.0, 4), layout="constrained")
    axes = fig.subplots(1, len(who), squeeze=False)[0]
    score, failed = run.score, run.failed
    for ax, name in zip(axes, who, strict=True):
        env = gym.make(run.spec.env_id, **run.env_kwargs_of(name))  # the env the row ran on
        try:
            agent = run.factory[name](env)
            eff = np.full((len(grid.y_values), len(grid.x_values)), np.nan)
            for iy, y in enumerate(grid.y_values):
                for ix, x in enumerate(grid.x_values):
                    tr = rollout(agent, env, grid.scenario(x, y), 0)
                    eff[iy, ix] = score.efficiency(run.spec.task.metrics(tr), failed)
        finally:
            env.close()
        im = ax.imshow(eff, origin="lower", vmin=0.0, vmax=1.0, cmap="viridis", aspect="auto")
        for iy in range(eff.shape[0]):
            for ix in range(eff.shape[1]):
                ax.text(
                    ix,
                    iy,
                    f"{eff[iy, ix]:.2f}",
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="w" if eff[iy, ix] < 0.6 else "k",
                )
        ax.set_xticks(range(len(grid.x_values)), [f"{v:g}" for v in grid.x_values])
        ax.set_yticks(range(len(grid.y_values)), [f"{v:g}" for v in grid.y_values])
        ax.set_xlabel(grid.x_label)
        ax.set_ylabel(grid.y_label)
        ax.set_title(name, fontsize=9)
    fig.colorbar(im, ax=list(axes), label="efficiency (bound / charged time)")
    fig.suptitle(f"{run.spec.env_id}: robustness", fontsize=10)
    save_figure(fig, path)
    return path
