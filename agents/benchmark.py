"""The benchmark: every applicable agent on every env, same held-out scenarios, one report.

``machining-bench benchmark [--quick] [--out results]`` prints a markdown table and writes
``benchmark.csv``, ``report.md`` and PNG plots (representative trajectories, metric bars)
to the output folder, plus the paper reproduction figure.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np

from agents.adaptive import VariableGainPI
from agents.drilling import PD, NoControl
from agents.feed import ConstantOverride
from agents.harness import Evaluation, agent_name, evaluate, rollout
from agents.hinf import HInf2DOF
from agents.integral import FixedGainIntegral, IntegralACC, MillingConstantFeed
from agents.pid import ConstantFeed, FixedGainPI
from agents.position import PIPosition
from agents.rl import pretrained
from agents.scores import (
    CONTOURING_SCORE,
    DRILLING_SCORE,
    FEED_SCORE,
    REGULATION_SCORE,
    PrimaryScore,
)
from agents.sliding_mode import SlidingMode
from machining_envs.contouring_metrics import contouring_metrics
from machining_envs.drilling_metrics import drilling_metrics
from machining_envs.metrics import regulation_metrics
from machining_envs.milling_metrics import milling_metrics

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
    """One env's part of the benchmark (append one per env to ``BENCHMARKS``)."""

    env_id: str
    agents: tuple[Callable, ...]  # factories env -> agent
    paper_scenarios: tuple[str, ...]
    heldout_scenario: str
    showcase_scenario: str
    metrics_fn: Callable[[dict], dict] = regulation_metrics
    #: The env's primary score (``agents.scores``), tabled per agent on the held-out set.
    score: PrimaryScore = REGULATION_SCORE
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


BENCHMARKS = (
    BenchmarkSpec(
        "machining_envs/Turning-v0",
        (
            ConstantFeed.from_env,
            FixedGainPI.from_env,
            VariableGainPI.from_env,
            pretrained("turning_ppo"),
        ),
        ("paper_245", "paper_405", "paper_700", "taper_405"),
        "test",
        "paper_405",
    ),
    BenchmarkSpec(
        "machining_envs/EndMilling-v0",
        (
            MillingConstantFeed.from_env,
            FixedGainIntegral.from_env,
            IntegralACC.from_env,
            pretrained("end_milling_ppo"),
        ),
        ("paper_step", "paper_taper"),
        "test",
        "paper_step",
        metrics_fn=milling_metrics,
        table_metrics=(
            "machining_time_min",
            "mrr_mm3_per_min",
            "iae",
            "max_overshoot",
            "settling_time_s",
            "oscillation",
            "time_over_limit",
            "breakage",
            "finished",
        ),
        plot_main=("torque_Nmm", "torque_ref_Nmm", "torque (N·mm)"),
        plot_lower=("feed_mm_per_rev", "feed (mm/rev)"),
        plot_context=("depth_mm", "radial depth (mm)"),
        bar_metrics=(
            ("machining_time_min", "machining time, eq. 20 (min)"),
            ("iae", "IAE (s)"),
            ("oscillation", "torque oscillation (share of Tr)"),
            ("time_over_limit", "share of time over 1.1x reference"),
        ),
    ),
    BenchmarkSpec(
        "machining_envs/MicroDrilling-v0",
        (NoControl.from_env, PD.from_env, SlidingMode.from_env, pretrained("micro_drilling_ppo")),
        ("paper_0.5", "paper_0.6", "paper_0.7", "paper_0.8"),
        "test",
        "paper_0.8",
        metrics_fn=drilling_metrics,
        score=DRILLING_SCORE,
        table_metrics=(
            "drilling_time_s",
            "torque_mean_rel",
            "torque_std_rel",
            "thrust_mean_N",
            "thrust_std_N",
            "spindle_range_hz",
            "time_over_limit",
            "peak_torque_rel",
            "breakage",
            "finished",
        ),
        plot_main=("torque_Nmm", "torque_ref_Nmm", "torque (N·mm)"),
        plot_lower=("spindle_hz", "spindle (Hz)"),
        plot_context=("depth_mm", "hole depth (mm)"),
        bar_metrics=(
            ("torque_mean_rel", "mean torque / reference"),
            ("torque_std_rel", "torque std / reference"),
            ("peak_torque_rel", "peak torque / breakage torque"),
            ("breakage", "breakage rate"),
        ),
    ),
    BenchmarkSpec(
        "machining_envs/Contouring-v0",
        (PIPosition.from_env, HInf2DOF.from_env, pretrained("contouring_ppo")),
        ("paper_circle", "paper_involute"),
        "test",
        "paper_circle",
        metrics_fn=contouring_metrics,
        score=CONTOURING_SCORE,
        table_metrics=(
            "max_contour_error_mm",
            "rms_contour_error_mm",
            "max_tracking_error_mm",
            "radius_reduction_mm",
            "ellipse_mm",
            "cycle_time_s",
            "effort_rms_Nm",
            "finished",
            "diverged",
        ),
        plot_main=("contour_error_mm", None, "contour error (mm)"),
        plot_lower=("tracking_error_mm", "tracking error (mm)"),
        plot_context=("path_s_mm", "set point along the path (mm)"),
        bar_metrics=(
            ("max_contour_error_mm", "largest contour error (mm)"),
            ("rms_contour_error_mm", "RMS contour error (mm)"),
            ("cycle_time_s", "cycle time (s)"),
            ("effort_rms_Nm", "RMS motor torque (N m)"),
        ),
    ),
    BenchmarkSpec(
        "machining_envs/ContouringFeed-v0",
        (
            ConstantOverride.from_env,
            functools.partial(ConstantOverride.from_env, override=1.0),
            pretrained("contouring_feed_ppo"),
        ),
        ("paper_circle", "paper_involute"),
        "test",
        "paper_involute",
        metrics_fn=contouring_metrics,
        score=FEED_SCORE,
        table_metrics=(
            "cycle_time_s",
            "max_contour_error_mm",
            "rms_contour_error_mm",
            "time_over_tolerance",
            "effort_rms_Nm",
            "finished",
            "diverged",
        ),
        plot_main=("peak_contour_error_mm", "tolerance_mm", "contour error (mm)"),
        plot_lower=("feed_override", "feed override"),
        plot_context=("path_s_mm", "set point along the path (mm)"),
        bar_metrics=(
            ("cycle_time_s", "cycle time (s)"),
            ("max_contour_error_mm", "largest contour error (mm)"),
            ("time_over_tolerance", "share of steps over tolerance"),
        ),
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
        learned = set()
        for k, factory in enumerate(spec.agents):
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
        failed = spec.score.failed_value(gym.make(spec.env_id))
        primary = primary_score_table(
            ev, spec.heldout_scenario, failed, spec.score, learned=learned
        )
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

    from agents.cli import REPRODUCTIONS, reproduction

    for process in REPRODUCTIONS:
        if verbose:
            print(f"### Paper reproduction: {process}\n")
        repro = reproduction(process)(out, verbose=verbose)
        n_ok = sum(r["match"] for r in repro)
        report += [
            f"## Paper reproduction: {process}",
            "",
            f"{n_ok}/{len(repro)} experiments show the paper's behaviour.",
            "",
            f"![reproduction](reproduce_{process}.png)",
            "",
        ]
    (out / "report.md").write_text("\n".join(report))
    if verbose:
        print(
            f"\nwrote {out / 'benchmark.csv'}, {out / 'report.md'} and plots "
            f"({time.perf_counter() - t0:.0f} s)"
        )
    return allev


def primary_score_table(
    ev: Evaluation,
    scenario: str,
    failed_value: float,
    score: PrimaryScore = REGULATION_SCORE,
    learned: Iterable[str] = (),
) -> str:
    """Markdown table of the primary score per agent on ``scenario`` (``agents.scores``).

    Score: the mean of the env's score metric with episodes that do not count charged
    ``failed_value`` (or their own ``time_limit_s``); the spread is the standard error of
    that mean over episodes. For the agents named in ``learned`` a last column gives the
    margin over the best of the others (its score minus theirs, positive when the learned
    agent is better) with the standard error of the episode-by-episode differences (the
    agents meet the same seeds). Empty when the rows lack the needed metrics.
    """
    need = {score.value_key, "finished"} | ({score.over_key} if score.over_key else set())
    rows = [r for r in ev.rows if r["scenario"] == scenario]
    if not rows or not all(need <= set(r) for r in rows):
        return ""
    k = score.scale
    cost = "their own time limit" if "time_limit_s" in rows[0] else f"{failed_value * k:g}"
    by_agent: dict[str, list[dict]] = {}
    for r in rows:
        by_agent.setdefault(r["agent"], []).append(r)
    charged = {
        name: {r["seed"]: score.charged(r, failed_value) * k for r in rs}
        for name, rs in by_agent.items()
    }
    learned = set(learned) & set(by_agent)
    others = [n for n in by_agent if n not in learned]
    best = min(others, key=lambda n: np.mean(list(charged[n].values())), default=None)
    margin = bool(learned) and best is not None
    head = f"| agent | score ± s.e. | episodes that count | {score.secondary_label} |"
    rule = "|---|---|---|---|"
    if margin:
        head += f" margin over {best} ± s.e. |"
        rule += "---|"
    lines = [
        f"Primary score on `{scenario}`: {score.label}, lower is better; episodes that do "
        f"not count cost {cost}:",
        "",
        head,
        rule,
    ]
    for name, rs in by_agent.items():
        s = score(rs, failed_value)
        se = _standard_error(list(charged[name].values()))
        line = (
            f"| {name} | {s['score'] * k:.4g} ± {se:.2g} | {s['valid']:.0%} | "
            f"{s['secondary']:.3g} |"
        )
        if margin:
            line += (
                f" {_paired_margin(charged[best], charged[name])} |" if name in learned else " |"
            )
        lines.append(line)
    return "\n".join(lines)


def _paired_margin(reference: dict, agent: dict) -> str:
    """Mean of ``reference - agent`` over the seeds both ran, ± its standard error."""
    seeds = sorted(set(reference) & set(agent))
    if not seeds:
        return "n/a"
    d = [reference[s] - agent[s] for s in seeds]
    return f"{np.mean(d):+.4g} ± {_standard_error(d):.2g}"


def _standard_error(values) -> float:
    """Standard error of the mean of ``values`` (0 for a single value)."""
    return float(np.std(values, ddof=1) / np.sqrt(len(values))) if len(values) > 1 else 0.0


def _plot_trajectories(spec: BenchmarkSpec, path: Path, seed: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    key, ref_key, label = spec.plot_main
    low_key, low_label = spec.plot_lower
    fig, axes = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
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
    plt.close(fig)


def _plot_bars(ev: Evaluation, spec: BenchmarkSpec, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenario = spec.heldout_scenario
    keys = [m for m, _ in spec.bar_metrics]
    summ = [r for r in ev.summary(keys) if r["scenario"] == scenario]
    names = [r["agent"] for r in summ]
    fig, axes = plt.subplots(1, len(keys), figsize=(3.3 * len(keys), 3.2), squeeze=False)
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
    plt.close(fig)
