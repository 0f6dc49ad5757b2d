"""The score tables (``agents.eval.tables``): paired margins for learned agents."""

import numpy as np

from agents.eval import Evaluation


def test_primary_score_table_gives_learned_agents_a_paired_margin():
    from agents.eval import primary_score_table

    def row(agent, seed, t, over=0.0):
        return {
            "agent": agent,
            "scenario": "test",
            "seed": seed,
            "machining_time_s": t,
            "finished": 1.0,
            "breakage": 0.0,
            "time_over_limit": over,
            "itae": 1.0,
        }

    ev = Evaluation()
    ev.rows = (
        [row("A", s, t) for s, t in ((1, 10.0), (2, 20.0), (3, 30.0))]
        + [row("B", s, t) for s, t in ((1, 12.0), (2, 22.0), (3, 32.0))]
        + [row("P", 1, 11.0), row("P", 2, 19.0), row("P", 3, 30.0, over=0.05)]
    )
    table = primary_score_table(ev, "test", 100.0, learned=["P"])
    assert "margin over A ± s.e." in table
    # P against A, seed by seed: -1, +1, and its third episode does not count (100 - 30 = -70).
    line = next(x for x in table.splitlines() if x.startswith("| P |"))
    d = np.array([-1.0, 1.0, -70.0])
    assert f"{d.mean():+.4g} ± {np.std(d, ddof=1) / np.sqrt(3):.2g}" in line
    assert table.splitlines()[4].endswith("| |")  # classical agents: no margin
    assert "margin" not in primary_score_table(ev, "test", 100.0)
