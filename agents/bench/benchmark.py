"""The benchmark: every applicable agent on every env, same held-out scenarios, one report.

``machining-bench benchmark [--quick] [--out results]`` prints a markdown table and writes
``benchmark.csv``, ``report.md`` and PNG plots (representative trajectories, metric bars)
to the output folder, plus the paper reproduction figure.
"""

from __future__ import annotations

import time
from pathlib import Path

import gymnasium as gym

from agents.bench.declarations import BENCHMARKS, PROCESSES
from agents.bench.spec import BenchmarkSpec
from agents.eval import Evaluation, agent_name, evaluate, primary_score_table, rollout

__all__ = ["run_benchmark"]


def _rl_installed() -> bool:
    """Whether Stable-Baselines3 (the ``rl`` extra) is importable."""
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        return False
    return True


def run_benchmark(
    out_dir="results", quick: bool = False, seed: int = 1000, verbose: bool = True
) -> Evaluation:
    """Run every benchmark; return all episode rows. ``quick``: fewer held-out episodes."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    n_test = 5 if quick else 20
    n_paper = 1 if quick else 3
    evals = []
    report = ["# machining_envs benchmark", ""]
    t0 = time.perf_counter()
    for spec in BENCHMARKS:
        env_name = spec.env_id.split("/")[-1]
        spec_evals = []
        learned = set()
        for k, factory in enumerate(spec.agents):
            if getattr(factory, "learned", False) and not _rl_installed():
                if verbose:
                    print(
                        f"[{env_name}] {k + 1}/{len(spec.agents)} {factory.__name__}: skipped "
                        "(learned policies need the rl extra: pip install 'machining-envs[rl]')"
                    )
                continue
            for scenarios, n in (
                (spec.paper_scenarios, n_paper),
                ((spec.heldout_scenario,), n_test),
            ):
                ev = evaluate(
                    factory,
                    spec.env_id,
                    scenarios,
                    n_episodes=n,
                    seed=seed,
                    metrics_fn=spec.metrics_fn,
                )
                for row in ev.rows:
                    row["env_id"] = spec.env_id
                spec_evals.append(ev)
            name = spec_evals[-1].rows[0]["agent"]
            if getattr(factory, "learned", False):
                learned.add(name)
            if verbose:
                print(
                    f"[{env_name}] {k + 1}/{len(spec.agents)} {name}: done ({time.perf_counter() - t0:.0f} s)"
                )
        ev = Evaluation.concat(spec_evals)
        evals.append(ev)
        table = ev.to_markdown(spec.table_metrics)
        score = spec.task.score
        failed = score.failed_value(gym.make(spec.env_id))
        primary = primary_score_table(ev, spec.heldout_scenario, failed, score, learned=learned)
        if primary:
            table += "\n\n" + primary
        report += [
            f"## {env_name}",
            "",
            f"Held-out scenario `{spec.heldout_scenario}`: {n_test} episodes "
            f"per agent (seeds {seed}..{seed + n_test - 1}); paper scenarios: {n_paper} each.",
            "",
            table,
            "",
        ]
        if verbose:
            print(f"\n### {env_name}\n\n{table}\n")
        traj_png = out / f"{env_name}_trajectories.png"
        _plot_trajectories(spec, traj_png, seed)
        bars_png = out / f"{env_name}_metrics.png"
        _plot_bars(ev, spec, bars_png)
        report += [f"![trajectories]({traj_png.name})", "", f"![metrics]({bars_png.name})", ""]
    allev = Evaluation.concat(evals)
    allev.to_csv(out / "benchmark.csv")

    for process in PROCESSES:
        if verbose:
            print(f"### Paper reproduction: {process.name}\n")
        repro = process.reproduce(out, verbose=verbose)
        n_ok = sum(r["match"] for r in repro)
        report += [
            f"## Paper reproduction: {process.name}",
            "",
            f"{n_ok}/{len(repro)} experiments show the paper's behaviour.",
            "",
            f"![reproduction](reproduce_{process.name}.png)",
            "",
        ]
    (out / "report.md").write_text("\n".join(report))
    if verbose:
        print(
            f"\nwrote {out / 'benchmark.csv'}, {out / 'report.md'} and plots "
            f"({time.perf_counter() - t0:.0f} s)"
        )
    return allev


def _plot_trajectories(spec: BenchmarkSpec, path: Path, seed: int) -> None:
    from matplotlib.figure import Figure

    key, ref_key, label = spec.plot_main
    low_key, low_label = spec.plot_lower
    fig = Figure(figsize=(9, 5.5))
    axes = fig.subplots(2, 1, sharex=True)
    env = gym.make(spec.env_id)
    try:
        for i, factory in enumerate(spec.agents):
            agent = factory(env)
            tr = rollout(agent, env, spec.showcase_scenario, seed)
            axes[0].plot(tr["t_s"], tr[key], color=f"C{i}", lw=1, label=agent_name(agent))
            axes[1].plot(tr["t_s"], tr[low_key], color=f"C{i}", lw=1)
        if ref_key is not None:
            axes[0].plot(tr["t_s"], tr[ref_key], color="k", ls="--", lw=0.8, label="reference")
        if spec.plot_context is not None:
            ctx_key, ctx_label = spec.plot_context
            ax2 = axes[1].twinx()
            ax2.plot(tr["t_s"], tr[ctx_key], color="0.6", lw=0.8)
            ax2.set_ylabel(ctx_label, color="0.5")
    finally:
        env.close()
    axes[0].set_ylabel(label)
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"{spec.env_id}, scenario {spec.showcase_scenario}, seed {seed}")
    axes[1].set_ylabel(low_label)
    axes[1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def _plot_bars(ev: Evaluation, spec: BenchmarkSpec, path: Path) -> None:
    from matplotlib.figure import Figure

    scenario = spec.heldout_scenario
    keys = [m for m, _ in spec.bar_metrics]
    summ = [r for r in ev.summary(keys) if r["scenario"] == scenario]
    names = [r["agent"] for r in summ]
    fig = Figure(figsize=(3.3 * len(keys), 3.2))
    axes = fig.subplots(1, len(keys), squeeze=False)
    for ax, (m, label) in zip(axes[0], spec.bar_metrics, strict=True):
        ax.bar(
            range(len(names)),
            [r[m] for r in summ],
            yerr=[r[m + "_std"] for r in summ],
            color=[f"C{i}" for i in range(len(names))],
        )
        ax.set_xticks(range(len(names)), names, rotation=20, ha="right", fontsize=7)
        ax.set_title(label, fontsize=9)
    fig.suptitle(f"held-out scenario '{scenario}': mean ± std over episodes", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
