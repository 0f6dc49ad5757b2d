"""`machining-bench reproduce drilling`: runs, prints paper vs ours, saves the figure."""

from agents.bench.cli import main
from agents.bench.declarations import process
from agents.bench.drilling import reproduce_drilling


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
