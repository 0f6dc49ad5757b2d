"""``machining-bench``: the quick benchmark writes its report; bad arguments are refused."""

import subprocess
import sys

import pytest

from agents.bench.cli import main


def test_cli_benchmark_quick_writes_report(tmp_path):
    out = subprocess.run(
        [sys.executable, "-m", "agents.bench.cli", "benchmark", "--quick", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "| agent | scenario |" in out.stdout
    assert "margin over" in out.stdout  # the pretrained policies against the best classical
    for name in (
        "benchmark.csv",
        "report.md",
        "Turning-v0_trajectories.png",
        "Turning-v0_metrics.png",
        "reproduce_turning.png",
    ):
        assert (tmp_path / name).stat().st_size > 0, name


def test_cli_rejects_bad_arguments():
    with pytest.raises(SystemExit):
        main(["reproduce", "grinding"])
    with pytest.raises(SystemExit):
        main(["reproduce", "turning", "--sensor-gain", "-3"])
