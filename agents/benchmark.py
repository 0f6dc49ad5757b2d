"""The benchmark: every applicable agent on every env, same held-out scenarios, one report.

``machining-bench benchmark [--quick] [--out results]`` prints a markdown table and writes
``benchmark.csv``, ``report.md`` and PNG plots (representative trajectories, metric bars)
to the output folder, plus the paper reproduction figure.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym

from agents.adaptive import VariableGainPI
from agents.harness import Evaluation, evaluate, rollout
from agents.pid import ConstantFeed, FixedGainPI

__all__ = ["BenchmarkSpec", "BENCHMARKS", "run_benchmark"]

#: Metrics shown in the printed table (all are in the CSV).
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
    env_id: str
    agents: tuple[Callable, ...]  # factories env -> agent
    paper_scenarios: tuple[str, ...]
    heldout_scenario: str
    showcase_scenario: str


BENCHMARKS = (
    BenchmarkSpec(
        "machining_envs/Turning-v0",
        (
            ConstantFeed.from_env,
            FixedGainPI.from_env,
            VariableGainPI.from_env,
        ),
        ("paper_245", "paper_405", "paper_700", "taper_405"),
        "test",
        "paper_405",
    ),
)


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
        for k, factory in enumerate(spec.agents):
            for scenarios, n in (
                (spec.paper_scenarios, n_paper),
                ((spec.heldout_scenario,), n_test),
            ):
                ev = evaluate(factory, spec.env_id, scenarios, n_episodes=n, seed=seed)
                for row in ev.rows:
                    row["env_id"] = spec.env_id
                spec_evals.append(ev)
            if verbose:
                name = spec_evals[-1].rows[0]["agent"]
                print(
                    f"[{env_name}] {k + 1}/{len(spec.agents)} {name}: done ({time.perf_counter() - t0:.0f} s)"
                )
        ev = Evaluation.concat(spec_evals)
        evals.append(ev)
        table = ev.to_markdown(TABLE_METRICS)
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
        _plot_bars(ev, spec.heldout_scenario, bars_png)
        report += [f"![trajectories]({traj_png.name})", "", f"![metrics]({bars_png.name})", ""]
    allev = Evaluation.concat(evals)
    allev.to_csv(out / "benchmark.csv")

    from agents.reproduce import reproduce_turning

    if verbose:
        print("### Paper reproduction: turning (Noh, Kim & Kim 1992)\n")
    repro = reproduce_turning(out, verbose=verbose)
    n_ok = sum(r["match"] for r in repro)
    report += [
        "## Paper reproduction: turning",
        "",
        f"{n_ok}/{len(repro)} runs show the paper's behaviour.",
        "",
        "![reproduction](reproduce_turning.png)",
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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    env = gym.make(spec.env_id)
    try:
        for i, factory in enumerate(spec.agents):
            agent = factory(env)
            tr = rollout(agent, env, spec.showcase_scenario, seed)
            axes[0].plot(tr["t_s"], tr["force_N"], color=f"C{i}", lw=1, label=agent.name)
            axes[1].plot(tr["t_s"], tr["feed_mm_per_rev"], color=f"C{i}", lw=1)
        axes[0].axhline(tr["force_ref_N"][0], color="k", ls="--", lw=0.8, label="reference")
        ax2 = axes[1].twinx()
        ax2.plot(tr["t_s"], tr["depth_mm"], color="0.6", lw=0.8)
        ax2.set_ylabel("depth (mm)", color="0.5")
    finally:
        env.close()
    axes[0].set_ylabel("force (N)")
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"{spec.env_id}, scenario {spec.showcase_scenario}, seed {seed}")
    axes[1].set_ylabel("feed (mm/rev)")
    axes[1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_bars(ev: Evaluation, scenario: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summ = [
        r
        for r in ev.summary(["machining_time_s", "iae", "time_over_limit", "breakage"])
        if r["scenario"] == scenario
    ]
    names = [r["agent"] for r in summ]
    fig, axes = plt.subplots(1, 4, figsize=(13, 3.2))
    for ax, m, label in zip(
        axes,
        ("machining_time_s", "iae", "time_over_limit", "breakage"),
        ("machining time (s)", "IAE (s)", "share of time F > 1.1 Fr", "breakage rate"),
        strict=True,
    ):
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
    plt.close(fig)
