"""The benchmark: every agent of every env on the same held-out episodes, one report.

``machining-bench benchmark [--quick] [--out results]`` runs, for each env, the physical
bound, the MPC oracle (where built), the paper's classical agents, the tuned classical
agents (``agents/bench/tuned.json``) and the learned policies (every training seed) on
the fixed episodes of the ``test`` split, paired by seed, and on the ``ood`` split apart.
It prints one table per env and writes ``benchmark.csv`` (every episode), ``report.md``
and PNG plots: score intervals, performance profiles, representative trajectories and,
for the regulation envs, a robustness heatmap. The paper reproductions follow.

``test`` is touched here only: tuning and training use ``train`` and ``validation``.
"""

from __future__ import annotations

import math
import time
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np

from agents.bench import tune
from agents.bench.declarations import BENCHMARKS, PROCESSES
from agents.bench.spec import BenchmarkSpec
from agents.bench.tune import load_tuned, tuned_factory
from agents.eval import Evaluation, agent_name, evaluate, rollout
from agents.eval.stats import agent_stats, iqm, paired_difference, rliable_seed
from machining_envs.core.checks import is_seed
from machining_envs.core.splits import split_seeds

__all__ = ["run_benchmark", "check_env_ids", "SIZES"]

#: Episodes per agent for the quick and the full run: (test, ood, at most this many test
#: episodes for an oracle, which also stops at its spec's ``oracle_episodes``).
SIZES = {"quick": (8, 0, 1), "full": (100, 25, 100)}
#: What the extra held-out splits are, for the report.
_SPLIT_NOTES = {
    "wear": "the training ranges with a tool that dulls within the cut",
    "shopfloor": (
        "the training ranges on a real CNC: feed override in 1 % steps, rate- and "
        "acceleration-limited, delayed 2 periods; in Turning-v0 also a 2.2 kW spindle that "
        "slows when overloaded"
    ),
}
_KIND_COLOUR = {"bound": "0.3", "oracle": "k", "paper": "C0", "tuned": "C2", "learned": "C1"}


def _installed(module: str) -> bool:
    try:
        __import__(module)
    except ImportError:
        return False
    return True


class _EnvRun:
    """The rows of one env: per agent, its kind and its episode rows per split."""

    def __init__(self, spec: BenchmarkSpec):
        self.spec = spec
        self.kind: dict[str, str] = {}
        self.rows: dict[str, dict[str, list]] = {}
        self.factory: dict[str, object] = {}
        env = gym.make(spec.env_id, **spec.env_kwargs)
        try:
            self.score = spec.task.score
            self.failed = self.score.failed_value(env)
        finally:
            env.close()

    def add(self, name, kind, split, rows, policy_seed=None):
        for r in rows:
            r["env_id"] = self.spec.env_id
            r["split"] = split
            r["kind"] = kind
            if policy_seed is not None:
                r["policy_seed"] = policy_seed
        self.kind.setdefault(name, kind)
        self.rows.setdefault(name, {}).setdefault(split, []).extend(rows)

    def all_rows(self) -> list[dict]:
        return [r for by in self.rows.values() for rs in by.values() for r in rs]


def _factories(spec: BenchmarkSpec, tuned: dict, verbose: bool, one_seed: bool = False):
    """``(kind, factory, policy_seed)`` of every row the env's benchmark runs (with
    ``one_seed``, each learned row's first training seed only)."""
    out = [("paper", f, None) for f in spec.paper_agents]
    for cls in spec.tuned:
        f = tuned_factory(cls, spec.env_id, tuned)
        if f is None:
            if verbose:
                print(f"  {cls.__name__}: no tuned settings (run `machining-bench tune`)")
            continue
        out.append(("tuned", f, None))
    if spec.learned:
        if not _installed("stable_baselines3"):
            if verbose:
                print(
                    "  learned rows skipped: they need the rl extra (pip install 'machining-envs[rl]')"
                )
        else:
            from agents.rl.policy import load_policy, pretrained_seeds

            for name in spec.learned:
                for seed, path in pretrained_seeds(name)[: 1 if one_seed else None]:

                    def make(env, path=path, name=name):
                        return load_policy(path, name=f"{name}")

                    out.append(("learned", make, seed))
    return out


class _Progress:
    """One progress bar per env (tqdm on stderr, where installed: the ``rl`` and ``bench``
    extras bring it), advanced once per agent and split and once per oracle episode; without
    tqdm, one printed line per agent. Silent when ``verbose`` is False."""

    def __init__(self, env_name: str, total: int, verbose: bool, t0: float):
        self.env_name, self.verbose, self.t0 = env_name, verbose, t0
        self.bar = None
        if verbose and _installed("tqdm"):
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=env_name, unit="run", leave=True)

    def note(self, text: str) -> None:
        if not self.verbose:
            return
        if self.bar is not None:
            self.bar.write(text)
        else:
            print(text)

    def working_on(self, text: str) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(text)

    def done(self, text: str, n: int = 1) -> None:
        if self.bar is not None:
            self.bar.update(n)
        elif self.verbose:
            print(f"[{self.env_name}] {text} ({time.perf_counter() - self.t0:.0f} s)")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _run_env(spec: BenchmarkSpec, n_test, n_ood, n_oracle, tuned: dict, verbose: bool, t0,
             one_seed: bool = False):  # fmt: skip
    run = _EnvRun(spec)
    env_name = spec.env_id.split("/")[-1]
    jobs = _factories(spec, tuned, verbose, one_seed)
    named = (("test", n_test), ("ood", n_ood), *((x, n_ood) for x in spec.extra_splits))
    splits = [(split, n) for split, n in named if n > 0]
    oracle_skipped = None
    if spec.oracle is not None and n_oracle < spec.oracle_episodes and not spec.oracle_in_quick:
        oracle_skipped = f"  oracle skipped in --quick ({spec.oracle_seconds:g} s an episode)"
    elif spec.oracle is not None and not _installed("casadi"):
        oracle_skipped = "  oracle skipped: it needs casadi (pip install 'machining-envs[bench]')"
    n_oracle_run = 0
    if spec.oracle is not None and oracle_skipped is None:
        n_oracle_run = min(spec.oracle_episodes, n_oracle)
    progress = _Progress(env_name, len(jobs) * len(splits) + n_oracle_run, verbose, t0)
    try:
        for k, (kind, factory, pseed) in enumerate(jobs):
            tag = f" seed {pseed}" if pseed is not None else ""
            for split, n in splits:
                progress.working_on(f"{kind}{tag} on {split}")
                ev = evaluate(
                    factory,
                    spec.env_id,
                    [split],
                    n_episodes=n,
                    seed=split_seeds(split, n)[0],
                    env_kwargs=spec.env_kwargs,
                )
                name = ev.rows[0]["agent"]
                run.factory.setdefault(name, factory)
                run.add(name, kind, split, ev.rows, pseed)
                progress.done(f"{k + 1}/{len(jobs)} {kind} {name}{tag} on {split}")
        if oracle_skipped is not None:
            progress.note(oracle_skipped)
        elif spec.oracle is not None:
            progress.working_on(f"oracle, {n_oracle_run} test episodes")
            ev = evaluate(
                spec.oracle,
                spec.env_id,
                ["test"],
                n_episodes=n_oracle_run,
                seed=split_seeds("test", n_oracle_run)[0],
                env_kwargs=spec.env_kwargs,
                batched=False,
            )
            name = ev.rows[0]["agent"]
            run.factory.setdefault(name, spec.oracle)
            run.add(name, "oracle", "test", ev.rows)
            progress.done(f"oracle {name}, {n_oracle_run} test episodes", n_oracle_run)
    finally:
        progress.close()
    return run


def _fmt(v: float, digits: int = 3) -> str:
    """``v`` to ``digits`` significant digits, no float noise (``1.05e-15`` prints ``0``)."""
    if v is None or not math.isfinite(v):
        return "–"
    if abs(v) < 1e-9:
        return "0"
    return f"{v:.{digits}g}" if abs(v) < 10**digits else f"{v:.0f}"


def _reference(run: _EnvRun, tuned: dict) -> str | None:
    """The best tuned classical agent: the lowest ``validation_score`` in ``tuned.json``
    among the tuned rows (chosen without looking at ``test``)."""
    entries = tuned.get("envs", {}).get(run.spec.env_id, {})
    best, best_v = None, math.inf
    for name, kind in run.kind.items():
        if kind != "tuned":
            continue
        cls = run.factory[name].__name__.removesuffix("_tuned")
        v = entries.get(cls, {}).get("validation_score", math.inf)
        if v < best_v:
            best, best_v = name, v
    return best


def _table(run: _EnvRun, split: str, ref: str | None, seed: int = 0) -> tuple[str, dict]:
    """The markdown table of one split and the per-agent statistics."""
    score, failed = run.score, run.failed
    k = score.scale
    unit = score.label
    stats = {}
    names = [n for n in run.rows if split in run.rows[n]]
    for name in names:
        stats[name] = agent_stats(run.rows[name][split], score, failed, seed)
    lines = [
        f"| agent | kind | {unit}: IQM [95 % CI] | mean | counts | efficiency | "
        f"better than {ref or 'best tuned'} by [95 % CI] | P(better) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    # The physical bound: the floor of every episode, from its truth.
    any_rows = run.rows[names[0]][split] if names else []
    bounds = [r.get(score.bound_key or "", math.nan) for r in any_rows]
    if bounds and all(math.isfinite(b) for b in bounds):
        b = np.array(bounds) * k
        lines.append(
            f"| physical bound | bound | {_fmt(float(iqm(b)))} | {_fmt(b.mean())} | – | 1 | – | – |"
        )
    order = {"oracle": 0, "paper": 1, "tuned": 2, "learned": 3}
    for name in sorted(names, key=lambda n: order[run.kind[n]]):
        s = stats[name]
        kind = run.kind[name]
        if kind == "learned":
            kind = f"learned, {s.n_seeds} seed{'s' if s.n_seeds > 1 else ''}"
        if run.kind[name] == "oracle":
            kind = f"oracle, {s.n_episodes} ep."
        cmp_, p = "–", "–"
        if ref is not None and name != ref and split in run.rows.get(ref, {}):
            d = paired_difference(run.rows[ref][split], run.rows[name][split], score, failed, seed)
            cmp_ = f"{_fmt(d['diff'] * k)} [{_fmt(d['low'] * k)}, {_fmt(d['high'] * k)}]"
            p = f"{d['p_improve']:.2f}"
        eff = "–" if not math.isfinite(s.efficiency) else f"{s.efficiency:.2f}"
        lines.append(
            f"| {name} | {kind} | {_fmt(s.iqm * k)} [{_fmt(s.iqm_low * k)}, {_fmt(s.iqm_high * k)}] "
            f"| {_fmt(s.mean * k)} | {s.count_rate:.0%} | {eff} | {cmp_} | {p} |"
        )
    return "\n".join(lines), stats


def _tuned_settings() -> dict:
    """The tuned settings (``agents/bench/tuned.json``) the "(tuned)" rows and the
    residual policies run with; a warning where the file is missing, since the table then
    holds the classical agents with their papers' settings only."""
    if not tune.TUNED_FILE.is_file():
        warnings.warn(
            f"{tune.TUNED_FILE} not found: the benchmark runs no tuned classical agent "
            "(`machining-bench tune` writes it)",
            stacklevel=2,
        )
    return load_tuned(tune.TUNED_FILE)


def _env_section(env_id, n_test, n_ood, n_oracle, quick, seed, out, verbose, t0):
    """One env's part of the benchmark: ``(env name, report lines, printed text, episode
    rows, seconds)``. Takes and returns plain data, so that it can run in another process."""
    spec = next(s for s in BENCHMARKS if s.env_id == env_id)
    out = Path(out)
    tuned = _tuned_settings()
    t_env = time.perf_counter()
    env_name = spec.env_id.split("/")[-1]
    run = _run_env(spec, n_test, n_ood, n_oracle, tuned, verbose, t0, one_seed=quick)
    ref = _reference(run, tuned)
    test_table, stats = _table(run, "test", ref, seed)
    ood_table = _table(run, "ood", ref, seed)[0] if n_ood else "skipped in --quick."
    extra = [(split, _table(run, split, ref, seed)[0]) for split in spec.extra_splits if n_ood]
    pngs = [
        _plot_scores(run, stats, out / f"{env_name}_scores.png"),
        _plot_profiles(run, out / f"{env_name}_profiles.png"),
        _plot_trajectories(run, out / f"{env_name}_trajectories.png"),
    ]
    if spec.robustness is not None and not quick:
        pngs.append(_plot_robustness(run, ref, out / f"{env_name}_robustness.png"))
    curve_lines = []
    if not quick:  # the full run's extras: learning curves and loop margins
        curve_lines = _learning_curves(run, ref, out / f"{env_name}_learning.png", pngs, seed)
        curve_lines += _margin_table(run)
    seconds = time.perf_counter() - t_env
    lines = [
        f"## {env_name}",
        "",
        f"`test`, {n_test} episodes:",
        "",
        test_table,
        "",
        f"`ood` (beyond the training ranges), {n_ood} episodes:" if n_ood else "`ood`:",
        "",
        ood_table,
        "",
        *[
            line
            for split, table in extra
            for line in (
                f"`{split}` ({_SPLIT_NOTES.get(split, '')}), {n_ood} episodes:",
                "",
                table,
                "",
            )
        ],  # fmt: skip
        *curve_lines,
        *[f"![{p.stem}]({p.name})" for p in pngs if p is not None],
        "",
    ]
    text = [f"\n### {env_name} ({seconds:.0f} s)\n\n`test`:\n\n{test_table}\n\n"
            f"`ood`:\n\n{ood_table}\n"]  # fmt: skip
    text += [f"`{split}`:\n\n{table}\n" for split, table in extra]
    text += curve_lines[2:-1]
    return env_name, lines, "\n".join(text), run.all_rows(), seconds


def _one_thread() -> None:
    """A worker process computes on one core: BLAS and torch each get one thread, so that
    ``jobs`` processes do not oversubscribe the machine."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    try:
        import torch
    except ImportError:
        return
    torch.set_num_threads(1)


def _show(section, verbose: bool) -> None:
    if verbose:
        print(section[2], flush=True)


def check_env_ids(envs: str | list[str] | None) -> list[str] | None:
    """``envs`` as a list of benchmarked ids (one id may be given as a string), or None
    for all; ``ValueError`` naming any id the benchmark does not know."""
    known = [spec.env_id for spec in BENCHMARKS]
    if isinstance(envs, str):
        envs = [envs]
    unknown = [e for e in envs or () if e not in known]
    if unknown:
        raise ValueError(f"envs (--env) must be ids among {known}, got {unknown}")
    return None if envs is None else list(envs)


def run_benchmark(
    out_dir="results", quick: bool = False, seed: int = 0, verbose: bool = True,
    envs: list[str] | None = None, reproductions: bool = True, jobs: int | None = None,
) -> Evaluation:  # fmt: skip
    """Run every env's benchmark (or those in ``envs``); return all episode rows.

    ``quick``: 8 test episodes per agent instead of 100, no ood (25 in the full run), one
    episode for the oracles that are fast enough (``oracle_in_quick``), each learned row's
    first training seed only, no robustness grid, learning curves or loop margins. ``seed``
    seeds the bootstrap only: the episodes are the splits' fixed ones. ``jobs``: envs run at
    once, each in its own process (default 1; on 2 cores it does not pay, since the
    contouring envs already use both); the numbers do not depend on it.
    """
    envs = check_env_ids(envs)
    if not is_seed(seed):
        raise ValueError(f"seed must be an integer in [0, 2**32), got {seed!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    n_test, n_ood, n_oracle = SIZES["quick" if quick else "full"]
    report = [
        "# machining_envs benchmark",
        "",
        f"Every agent on the same {n_test} `test` episodes (seeds "
        f"{split_seeds('test', n_test)[0]}-{split_seeds('test', n_test)[-1]}) and {n_ood} `ood` "
        "episodes, paired by seed. Score: the env's primary score (lower is better; an episode "
        "that does not count is charged the env's failure cost). IQM: interquartile mean with "
        "its 95 % stratified-bootstrap interval (rliable); counts: share of episodes that count; "
        "efficiency: mean of bound / charged value. The comparison column is the paired "
        "difference (reference minus agent, positive = better) against the best tuned "
        "classical agent (chosen by its validation score), with its 95 % bootstrap interval "
        "over episodes; P(better): probability of improvement on an episode.",
        "",
    ]
    all_rows, times = [], {}
    t0 = time.perf_counter()
    chosen = [spec.env_id for spec in BENCHMARKS if not envs or spec.env_id in envs]
    args = (n_test, n_ood, n_oracle, quick, seed, str(out), verbose, t0)
    sections = {}
    jobs = max(1, min(jobs or 1, len(chosen)))
    if jobs == 1:
        for env_id in chosen:
            sections[env_id] = _env_section(env_id, *args)
            _show(sections[env_id], verbose)
    else:  # one env per process; the longest (listed last) start first
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = multiprocessing.get_context("spawn")  # no fork of torch's or numba's threads
        with ProcessPoolExecutor(jobs, mp_context=ctx, initializer=_one_thread) as pool:
            futures = {pool.submit(_env_section, e, *args): e for e in reversed(chosen)}
            for f in as_completed(futures):
                sections[futures[f]] = f.result()
                _show(sections[futures[f]], verbose)
    for env_id in chosen:  # the report in the usual order
        env_name, lines, _, rows, seconds = sections[env_id]
        report += lines
        times[env_name] = seconds
        all_rows += rows
    allev = Evaluation(rows=all_rows)
    allev.to_csv(out / "benchmark.csv")
    if reproductions:
        for process in PROCESSES:
            if verbose:
                print(f"### Paper reproduction: {process.name}\n")
            repro = process.reproduce(out, verbose=verbose)
            n_ok = sum(r["match"] for r in repro)
            report += [
                f"## Paper reproduction: {process.name}",
                "",
                f"{n_ok}/{len(repro)} experiments match the paper within their stated tolerance.",
                "",
                f"![reproduction](reproduce_{process.name}.png)",
                "",
            ]
    total = time.perf_counter() - t0
    report += [
        "## Time",
        "",
        *[f"- {k}: {v:.0f} s" for k, v in times.items()],
        f"- total: {total:.0f} s",
        "",
    ]
    (out / "report.md").write_text("\n".join(report))
    if verbose:
        per_env = ", ".join(f"{k} {v:.0f} s" for k, v in times.items())
        print(f"\nwrote {out / 'benchmark.csv'}, {out / 'report.md'} and plots")
        print(f"time: {per_env}; total {total:.0f} s")
    return allev


def _learning_curves(run: _EnvRun, ref: str | None, path: Path, pngs: list, seed: int) -> list:
    """The report's lines on the shipped policies' learning curves (and their plot, added
    to ``pngs``); none without learned rows."""
    from agents.bench.curves import learning_curve, plot_learning_curves

    learned = [n for n, kind in run.kind.items() if kind == "learned"]
    if not learned:
        return []
    from agents.rl.policy import pretrained_seeds

    reference = (ref, run.factory[ref]) if ref is not None else None
    curves = []
    for name in learned:
        c = learning_curve(
            name, pretrained_seeds(name), run.spec.env_id, run.spec.env_kwargs, run.score,
            run.failed, reference, seed,
        )  # fmt: skip
        if c is not None:
            curves.append(c)
    if not curves:
        return []
    k, unit = run.score.scale, run.score.label.split(" (")[-1].rstrip(")")
    pngs.append(plot_learning_curves(curves, run.spec.env_id, k, run.score.label, path))
    return [
        "Learning curves (`validation`, as recorded while training):",
        "",
        *[f"- {c.summary(k, unit)}" for c in curves],
        "",
    ]


def _margin_table(run: _EnvRun) -> list:
    """The report's loop-margin table (``spec.margin_points``): gain margin, phase margin and
    sensitivity peak of every paper, tuned and learned agent (a learned row: its first
    training seed) linearised at each operating point."""
    points = run.spec.margin_points
    if not points:
        return []
    from agents.eval.margins import loop_margins

    env = gym.make(run.spec.env_id, **run.spec.env_kwargs)
    lines = [
        "Loop margins at steady cuts (2 mm deep, no noise; the agent linearised around its own "
        "steady state, the plant as eq. 11/14 with the tangent process gain; "
        "`agents.eval.margins`): gain margin / phase margin / sensitivity peak Ms.",
        "",
        "| agent | " + " | ".join(f"{p.spindle_rpm:.0f} rpm" for p in points) + " |",
        "|---|" + "---|" * len(points),
    ]
    for name, kind in run.kind.items():
        if kind not in ("paper", "tuned", "learned"):
            continue
        cells = []
        for point in points:
            try:
                m = loop_margins(run.factory[name](env), point)
            except ValueError as exc:
                cells.append("does not settle" if "settled" in str(exc) else "ends the cut")
                continue
            if math.isinf(m.gain_margin_db) and math.isinf(m.phase_margin_deg):
                cells.append("no feedback")
                continue
            gm = "∞" if math.isinf(m.gain_margin_db) else f"{m.gain_margin_db:.1f} dB"
            pm = "∞" if math.isinf(m.phase_margin_deg) else f"{m.phase_margin_deg:.0f}°"
            cells.append(f"{gm} / {pm} / {m.sensitivity_peak:.2f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    env.close()
    return [*lines, ""]


# ---- plots ---------------------------------------------------------------------------------


def _plot_scores(run: _EnvRun, stats: dict, path: Path) -> Path:
    from matplotlib.figure import Figure

    k = run.score.scale
    names = list(stats)
    fig = Figure(figsize=(7.5, 0.45 * len(names) + 1.4))
    ax = fig.subplots()
    for i, name in enumerate(names):
        s = stats[name]
        c = _KIND_COLOUR[run.kind[name]]
        ax.plot([s.iqm_low * k, s.iqm_high * k], [i, i], color=c, lw=6, alpha=0.5)
        ax.plot([s.iqm * k], [i], "|", color=c, ms=14, mew=2)
    rows = next(iter(run.rows.values()))["test"]
    bounds = np.array([r.get("score_bound", math.nan) for r in rows]) * k
    if np.all(np.isfinite(bounds)):
        ax.axvline(float(iqm(bounds)), color="0.3", ls="--", lw=1, label="physical bound (IQM)")
        ax.legend(fontsize=8, loc="lower right")
    ax.set_yticks(range(len(names)), [f"{n} [{run.kind[n]}]" for n in names], fontsize=8)
    ax.set_xlabel(f"{run.score.label}: IQM, 95 % CI (lower is better)")
    ax.set_title(f"{run.spec.env_id}: test split", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    return path


def _plot_profiles(run: _EnvRun, path: Path) -> Path:
    """Performance profiles: the share of test episodes whose efficiency exceeds tau (or,
    without a bound, whose score is below tau), with rliable's bootstrap bands."""
    from matplotlib.figure import Figure
    from rliable import library

    from agents.eval.stats import BOOTSTRAP_REPS, score_matrix

    score, failed = run.score, run.failed
    names = [n for n in run.rows if "test" in run.rows[n]]
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
    fig = Figure(figsize=(6.5, 4))
    ax = fig.subplots()
    for i, n in enumerate(names):
        c = _KIND_COLOUR[run.kind[n]] if run.kind[n] in ("bound", "oracle") else f"C{i % 10}"
        ax.plot(taus, prof[n], color=c, lw=1.5, label=f"{n} [{run.kind[n]}]")
        ax.fill_between(taus, ci[n][0], ci[n][1], color=c, alpha=0.15)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("share of episodes above tau")
    ax.set_title(f"{run.spec.env_id}: performance profiles (test)", fontsize=10)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    return path


def _representative_seed(run: _EnvRun) -> int:
    """The test episode whose bound (or, without one, whose first agent's score) is the
    median of the split: a typical workpiece, not a chosen one."""
    rows = next(iter(run.rows.values()))["test"]
    key = (
        "score_bound" if all(math.isfinite(r.get("score_bound", math.nan)) for r in rows) else None
    )
    vals = [(r.get(key) if key else run.score.charged(r, run.failed), r["seed"]) for r in rows]
    vals = [v for v in vals if v[1] is not None]
    vals.sort()
    return int(vals[len(vals) // 2][1])


def _plot_trajectories(run: _EnvRun, path: Path) -> Path:
    """One typical test episode, one line per agent (the first seed of a learned agent);
    the upper panel is clipped to three times its limit (or typical peak), so that an agent
    that diverges does not hide the others."""
    from matplotlib.figure import Figure

    spec = run.spec
    key, lim_key, label = spec.plot_main
    low_key, low_label = spec.plot_lower
    seed = _representative_seed(run)
    fig = Figure(figsize=(9, 5.5))
    axes = fig.subplots(2, 1, sharex=True)
    env = gym.make(spec.env_id, **spec.env_kwargs)
    peaks, lim = [], None
    try:
        for i, (name, factory) in enumerate(run.factory.items()):
            kind = run.kind[name]
            agent = factory(env)
            tr = rollout(agent, env, "test", seed)
            c = _KIND_COLOUR[kind] if kind == "oracle" else f"C{i % 10}"  # the oracle in black
            axes[0].plot(tr["t_s"], tr[key], color=c, lw=1, label=f"{agent_name(agent)} [{kind}]")
            axes[1].plot(tr["t_s"], tr[low_key], color=c, lw=1)
            peaks.append(float(np.nanmax(np.abs(tr[key]))))
            if lim_key is not None and lim_key in tr:
                lim = float(tr[lim_key][0])
                if i == len(run.factory) - 1:
                    axes[0].axhline(lim, color="k", ls="--", lw=0.8, label="limit")
        if spec.plot_context is not None:
            ctx_key, ctx_label = spec.plot_context
            ax2 = axes[1].twinx()
            ax2.plot(tr["t_s"], tr[ctx_key], color="0.6", lw=0.8)
            ax2.set_ylabel(ctx_label, color="0.5")
    finally:
        env.close()
    top = 1.5 * lim if lim is not None else 3.0 * float(np.median(peaks))
    if max(peaks) > top:
        axes[0].set_ylim(top=top)
        axes[0].text(0.01, 0.97, "clipped: some agents go beyond the axis", transform=axes[0].transAxes,
                     fontsize=7, va="top")  # fmt: skip
    axes[0].set_ylabel(label)
    axes[0].legend(fontsize=7)
    axes[0].set_title(f"{spec.env_id}: typical test episode (seed {seed})", fontsize=10)
    axes[1].set_ylabel(low_label)
    axes[1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    return path


def _plot_robustness(run: _EnvRun, ref: str | None, path: Path) -> Path | None:
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
    env = gym.make(run.spec.env_id, **run.spec.env_kwargs)
    score, failed = run.score, run.failed
    try:
        for ax, name in zip(axes, who, strict=True):
            agent = run.factory[name](env)
            eff = np.full((len(grid.y_values), len(grid.x_values)), np.nan)
            for iy, y in enumerate(grid.y_values):
                for ix, x in enumerate(grid.x_values):
                    tr = rollout(agent, env, grid.scenario(x, y), 0)
                    eff[iy, ix] = score.efficiency(run.spec.task.metrics(tr), failed)
            im = ax.imshow(eff, origin="lower", vmin=0.0, vmax=1.0, cmap="viridis", aspect="auto")
            for iy in range(eff.shape[0]):
                for ix in range(eff.shape[1]):
                    ax.text(ix, iy, f"{eff[iy, ix]:.2f}", ha="center", va="center", fontsize=7,
                            color="w" if eff[iy, ix] < 0.6 else "k")  # fmt: skip
            ax.set_xticks(range(len(grid.x_values)), [f"{v:g}" for v in grid.x_values])
            ax.set_yticks(range(len(grid.y_values)), [f"{v:g}" for v in grid.y_values])
            ax.set_xlabel(grid.x_label)
            ax.set_ylabel(grid.y_label)
            ax.set_title(f"{name} [{run.kind[name]}]", fontsize=9)
        fig.colorbar(im, ax=list(axes), label="efficiency (bound / charged time)")
    finally:
        env.close()
    fig.suptitle(f"{run.spec.env_id}: robustness", fontsize=10)
    fig.savefig(path, dpi=90)
    return path
