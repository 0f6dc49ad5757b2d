"""The report of one env's benchmark: its tables, plots and notes, from its run.

:func:`env_section` turns an :class:`~agents.bench.run.EnvRun` into the env's part of
``report.md`` (every split's table with the allowance columns and the verdict column, the
flagged training seeds, the plots, and in the full run the learning curves and loop
margins), the text printed for it and the compact table of ``results.md`` (one number a
cell).
"""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym

from agents.bench import plots
from agents.bench.results import (
    SEED_FLOOR,
    compact_table,
    flagged_seeds,
    markdown_table,
    reference,
    split_results,
)
from agents.bench.run import EnvRun

__all__ = ["env_section", "SPLIT_NOTES"]

#: What the extra held-out splits are, for the report.
SPLIT_NOTES = {
    "wear": "the `test` ranges with a tool that dulls within the cut",
    "shopfloor": (
        "the `test` ranges on a real CNC: feed override in 1 % steps, rate- and "
        "acceleration-limited, delayed 2 periods; in Turning-v0 also a 2.2 kW spindle that "
        "slows when overloaded"
    ),
}


#: Under the ``shopfloor`` table, where it has rows tuned for the shop-floor machine.
SHOPFLOOR_ROWS_NOTE = (
    'Rows "(tuned, shop floor)": tuned by `machining-bench tune --machine docs/my_cnc.yml '
    "--allowance 0.005` (`agents/bench/tuned_shopfloor.json`) on `train` workpieces run on "
    "the described machine; the `shopfloor` episodes above were not used. Their verdict is "
    "against the shop-floor reference, the constant feed tuned for the same machine."
)


def env_section(
    run: EnvRun, tuned: dict, n_test: int, n_ood: int, quick: bool, seed: int, out: Path
) -> dict:
    """The env's report lines, printed text and compact table (see the module docstring)."""
    spec = run.spec
    env_name = spec.env_id.split("/")[-1]
    ref = reference(run, tuned)
    splits = ["test"] + (["ood", *spec.extra_splits] if n_ood else [])
    results = [split_results(run, s, ref, seed) for s in splits]
    tables = {sr.split: markdown_table(run, sr) for sr in results}
    test = results[0]
    pngs = [
        plots.plot_scores(
            run, {n: r.stats for n, r in test.agents.items()}, out / f"{env_name}_scores.png"
        ),
        plots.plot_profiles(run, out / f"{env_name}_profiles.png"),
        plots.plot_allowances(run, out / f"{env_name}_allowances.png"),
        plots.plot_trajectories(run, out / f"{env_name}_trajectories.png"),
    ]
    if spec.robustness is not None and not quick:
        pngs.append(plots.plot_robustness(run, ref, out / f"{env_name}_robustness.png"))
    curve_lines = []
    if not quick:  # the full run's extras: learning curves and loop margins
        curve_lines = _learning_curves(run, ref, out / f"{env_name}_learning.png", pngs, seed)
        curve_lines += _margin_table(run)
    flags = flagged_seeds(results)
    flag_lines = (
        [
            f"Training seeds that keep fewer than {SEED_FLOOR:.0%} of the workpieces:",
            "",
            *[f"- **{f}**" for f in flags],
            "",
        ]
        if flags
        else []
    )
    split_lines = []
    for sr in results[1:]:
        note = SPLIT_NOTES.get(sr.split)
        head = "`ood` (beyond the training ranges)" if sr.split == "ood" else f"`{sr.split}`"
        if note:
            head += f" ({note})"
        n = run.n_episodes.get(sr.split, n_ood)
        split_lines += [f"{head}, {n} episodes:", "", tables[sr.split], ""]
        if sr.split == "shopfloor" and run.machine_cls:
            split_lines += [SHOPFLOOR_ROWS_NOTE, ""]
    lines = [
        f"## {env_name}",
        "",
        f"`test`, {n_test} episodes:",
        "",
        tables["test"],
        "",
        *split_lines,
        *flag_lines,
        *curve_lines,
        *[f"![{p.stem}]({p.name})" for p in pngs if p is not None],
        "",
    ]
    text = [f"\n### {env_name}\n\n`test`:\n\n{tables['test']}\n"]
    text += [f"`{sr.split}`:\n\n{tables[sr.split]}\n" for sr in results[1:]]
    text += [line for line in flag_lines if line]
    text += curve_lines[2:-1]
    compact = [
        f"### {env_name}",
        "",
        f"`test`, {n_test} episodes:",
        "",
        compact_table(run, test),
        "",
    ]
    return {
        "name": env_name,
        "lines": lines,
        "text": "\n".join(text),
        "compact": compact,
        "flags": flags,
        "verdicts": {n: r.verdict for n, r in test.agents.items()},
    }


def _learning_curves(run: EnvRun, ref: str | None, path: Path, pngs: list, seed: int) -> list:
    """The report's lines on the shipped policies' learning curves (and their plot, added
    to ``pngs``); none without learned rows."""
    from agents.bench.curves import learning_curve, plot_learning_curves

    learned = [n for n, kind in run.kind.items() if kind == "learned"]
    if not learned:
        return []
    from agents.rl.policy import pretrained_seeds

    reference_row = (ref, run.factory[ref]) if ref is not None else None
    curves = []
    for name in learned:
        c = learning_curve(
            name,
            pretrained_seeds(name),
            run.spec.env_id,
            run.env_kwargs_of(ref) if ref is not None else run.spec.env_kwargs,
            run.score,
            run.failed,
            reference_row,
            seed,
        )
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


def _margin_table(run: EnvRun) -> list:
    """The report's loop-margin table (``spec.margin_points``): gain, phase and delay margin and
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
        "`agents.eval.margins`): gain margin / phase margin / delay margin / sensitivity "
        "peak Ms.",
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
            dm = "∞" if math.isinf(m.delay_margin_s) else f"{m.delay_margin_s:.2f} s"
            cells.append(f"{gm} / {pm} / {dm} / {m.sensitivity_peak:.2f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    env.close()
    return [*lines, ""]
