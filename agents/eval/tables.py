"""Score tables: the primary score of every agent on a scenario, with the paired margin of
learned agents over the best of the others."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from agents.eval.harness import Evaluation
from machining_envs.core.score import REGULATION_SCORE, PrimaryScore

__all__ = ["primary_score_table"]


def primary_score_table(
    ev: Evaluation,
    scenario: str,
    failed_value: float,
    score: PrimaryScore = REGULATION_SCORE,
    learned: Iterable[str] = (),
) -> str:
    """Markdown table of the primary score per agent on ``scenario`` (``machining_envs.core.score``).

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
