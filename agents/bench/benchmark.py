"""The benchmark: every agent of every env on the same held-out episodes, one report.

``machining-bench benchmark [--quick] [--out results]`` runs, for each env, the physical
bound, the MPC oracle (where built), the paper's classical agents, the tuned classical
agents (``agents/bench/tuned.json``) and the learned policies (every training seed) on
the fixed episodes of the ``test`` split, paired by seed, and on the ``ood`` split apart;
on the ``shopfloor`` split also the classical agents tuned for the shop-floor machine
(``agents/bench/tuned_shopfloor.json``, rows "(tuned, shop floor)", compared with the
constant feed tuned for that machine).
It prints one table per env and writes ``benchmark.csv`` (every episode), ``report.md``,
``results.md`` (the test tables, one number a cell) and PNG plots. The paper reproductions
follow.

Each table scores every agent at the allowances of 0.5, 1 and 2 % of steps over the limit
(the overload ceiling always on) against the best tuned classical agent, and its verdict
column says *better* or *worse* only where the comparison holds at all three
(``agents.eval.stats.verdict``); the report's claims come from that column.

The modules: ``run`` runs the rows (and records the plotted episode), ``results`` computes
the statistics, ``plots`` draws, ``report`` writes an env's section; this one runs the envs
(one process each with ``jobs``) and writes the files.

``test`` is touched here only: tuning and training use ``train`` and ``validation``.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

from agents.bench import tune
from agents.bench.declarations import BENCHMARKS, PROCESSES
from agents.bench.report import env_section
from agents.bench.run import installed as _installed  # noqa: F401  (tests and users import it here)
from agents.bench.run import one_thread, run_env
from agents.bench.tune import load_tuned
from agents.eval import Evaluation
from machining_envs.core.checks import is_seed
from machining_envs.core.splits import split_seeds

__all__ = ["run_benchmark", "check_env_ids", "SIZES", "EXTRA_SIZES"]

#: Episodes per agent for the quick and the full run: (test, ood, at most this many test
#: episodes for an oracle, which also stops at its spec's ``oracle_episodes``).
SIZES = {"quick": (8, 0, 1), "full": (100, 25, 100)}
#: Episodes of an extra held-out split where they are not ``ood``'s, per run: the full run
#: judges the shop-floor rows (``docs/shopfloor.md``) on 100 episodes, as it does ``test``.
EXTRA_SIZES = {"quick": {}, "full": {"shopfloor": 100}}


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


def _env_section(env_id, n_test, n_ood, n_oracle, quick, seed, out, verbose, t0, apart=False):
    """One env's part of the benchmark: its section (``agents.bench.report.env_section``)
    with the episode rows and seconds added. Takes and returns plain data, so that it can
    run in another process. ``apart``: the oracle runs in a process of its own."""
    spec = next(s for s in BENCHMARKS if s.env_id == env_id)
    tuned = _tuned_settings()
    t_env = time.perf_counter()
    machine_tuned = load_tuned(tune.SHOPFLOOR_TUNED_FILE)
    run = run_env(
        spec,
        n_test,
        n_ood,
        n_oracle,
        tuned,
        verbose,
        t0,
        one_seed=quick,
        oracle_apart=apart,
        machine_tuned=machine_tuned,
        n_extra=EXTRA_SIZES["quick" if quick else "full"],
    )
    section = env_section(run, tuned, n_test, n_ood, quick, seed, Path(out))
    section["rows"] = run.all_rows()
    section["seconds"] = time.perf_counter() - t_env
    return section


def _show(section, verbose: bool) -> None:
    if verbose:
        print(f"{section['text']}\n({section['seconds']:.0f} s)", flush=True)


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
    out_dir="results",
    quick: bool = False,
    seed: int = 0,
    verbose: bool = True,
    envs: list[str] | None = None,
    reproductions: bool = True,
    jobs: int | None = None,
) -> Evaluation:
    """Run every env's benchmark (or those in ``envs``); return all episode rows.

    ``quick``: 8 test episodes per agent instead of 100, no ood (25 in the full run) nor extra
    split (25 each in the full run, the ``shopfloor`` split 100: ``EXTRA_SIZES``), one
    episode for the oracles that are fast enough (``oracle_in_quick``), each learned row's
    first training seed only, no robustness grid, learning curves or loop margins. ``seed``
    seeds the bootstrap only: the episodes are the splits' fixed ones. ``jobs``: envs run at
    once, each in its own process, with each env's MPC oracle in a process of its own beside
    the env's other rows (default 1: everything in this process, one env after another);
    the numbers do not depend on it.
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
        "that does not count is charged the env's failure cost). An episode counts if it "
        "finished, nothing broke, its load never passed the overload ceiling and it spent "
        "less than the allowance of its steps over the limit (2 % in IQM, counts and "
        "efficiency). IQM: interquartile mean with its 95 % stratified-bootstrap interval "
        "(rliable); counts: share of episodes that count; efficiency: mean of bound / "
        "charged value (the oracle's: its IQM with its interval, beside the bound on the "
        "oracle's own episodes). Δ at a %: the paired difference (reference minus agent, "
        "positive = better) against the best tuned classical agent (chosen by its "
        "validation score) with the allowance at a % of steps, with its 95 % bootstrap "
        "interval over episodes. Verdict: *better* only if the interval is above zero at "
        "every allowance, *worse* only if below at every one; *depends on the allowance* "
        "if some are resolved and others not; *unresolved* if none is. Worst seed: the "
        "training seed of a learned row that keeps the fewest workpieces, and its share.",
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
    else:  # one env per process; the longest start first
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = multiprocessing.get_context("spawn")  # no fork of torch's or numba's threads
        with ProcessPoolExecutor(jobs, mp_context=ctx, initializer=one_thread) as pool:
            longest = sorted(BENCHMARKS, key=lambda s: -s.expected_seconds)
            order = [s.env_id for s in longest if s.env_id in chosen]
            futures = {pool.submit(_env_section, e, *args, True): e for e in order}
            for f in as_completed(futures):
                sections[futures[f]] = f.result()
                _show(sections[futures[f]], verbose)
    compact = [
        "# machining_envs benchmark: results",
        "",
        f"`{'machining-bench benchmark --quick' if quick else 'machining-bench benchmark'}`: "
        f"every agent on the same {n_test} `test` episodes. One number a cell: IQM of the "
        "score (2 % allowance), share that counts, efficiency, the paired difference "
        "against the reference at each allowance (positive = better), the verdict over "
        "them and a learned row's worst training seed's counting share (report.md has the "
        "intervals). An episode counts if it finished, nothing broke, its load never passed "
        "the scenario's overload ceiling and under the allowance of its steps were over the "
        "limit. Verdict against the best tuned classical agent: *better* only where the "
        "paired 95 % interval is above zero at 0.5, 1 and 2 %; claims of a win rest on it.",
        "",
    ]
    flags = []
    for env_id in chosen:  # the report in the usual order
        section = sections[env_id]
        report += section["lines"]
        compact += section["compact"]
        flags += [f"{section['name']}: {f}" for f in section["flags"]]
        times[section["name"]] = section["seconds"]
        all_rows += section["rows"]
    allev = Evaluation(rows=all_rows)
    allev.to_csv(out / "benchmark.csv")
    if flags:
        compact += [
            "Training seeds under 80 % of counting workpieces:",
            "",
            *[f"- {f}" for f in flags],
            "",
        ]
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
    import datetime
    import os
    import platform

    compact += [
        f"Wall time: {total:.0f} s with jobs={jobs} on {os.cpu_count()} CPUs "
        f"({platform.processor() or platform.machine()}), {datetime.date.today()}; per env: "
        + ", ".join(f"{k} {v:.0f} s" for k, v in times.items())
        + ".",
        "",
    ]
    (out / "results.md").write_text("\n".join(compact))
    if verbose:
        per_env = ", ".join(f"{k} {v:.0f} s" for k, v in times.items())
        print(
            f"\nwrote {out / 'benchmark.csv'}, {out / 'report.md'}, {out / 'results.md'} and plots"
        )
        print(f"time: {per_env}; total {total:.0f} s")
    return allev
