"""The drilling paper's results: `machining-bench reproduce drilling` runs, prints paper vs ours
and saves the figure; the paper's ranking of the controllers holds over seeds."""

import numpy as np

from agents.bench.cli import main
from agents.bench.declarations import process
from agents.bench.drilling import drilling_comparison, reproduce_drilling


def test_cli_reproduce_drilling(tmp_path, capsys):
    assert process("drilling").reproduce is reproduce_drilling
    code = main(["reproduce", "drilling", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert (tmp_path / "reproduce_drilling.png").stat().st_size > 10_000
    for fig in (
        "Table 1",
        "§3.2",
        "Fig. 12",
        "Fig. 18",
        "Fig. 19",
        "Fig. 20",
        "Fig. 21",
        "Fig. 22",
    ):
        assert fig in out
    lines = out.splitlines()
    verdicts = {}
    for i, line in enumerate(lines):
        if line.strip().startswith("ours:"):
            figure = lines[i - 2].split()[0] + " " + lines[i - 2].split()[1]
            verdicts[figure] = line.rstrip().endswith("yes")
    # Every check the library claims holds; the 0.5 mm one (the paper's sliding mode was the
    # noisiest there) is reported as not reproduced, and the exit code says so.
    assert all(ok for fig, ok in verdicts.items() if fig != "Fig. 18"), verdicts
    assert code == (0 if all(verdicts.values()) else 1)


def test_ranking_of_the_paper_for_06_07_08_mm_over_seeds():
    """Fig. 19-21: per seed, sliding mode < PD < no control in mean torque and in its
    standard deviation; over the seeds, the same for thrust; and no drill breaks."""
    comp = drilling_comparison((0.6, 0.7, 0.8), seeds=(0, 1, 2, 3))
    for d, c in comp.items():
        nc, pd, sm = (c[a]["rows"] for a in ("no control", "PD", "sliding mode"))
        for i in range(4):
            for k in ("torque_mean_Nmm", "torque_std_Nmm"):
                assert sm[i][k] < pd[i][k] < nc[i][k], (d, i, k)
            assert nc[i]["breakage"] == pd[i]["breakage"] == sm[i]["breakage"] == 0.0
        for k in ("thrust_mean_N", "thrust_std_N"):
            m = [np.mean([r[k] for r in rows]) for rows in (sm, pd, nc)]
            assert m[0] < m[1] < m[2], (d, k)
