"""The thread-handoff script runs and prints its four rows (numbers not judged)."""

import re

from tests.benchmark_scripts import run_benchmark


def test_thread_handoff_script_prints_every_row():
    out = run_benchmark("thread_handoff.py --threads 2 --runs 20")
    rows = [line.split() for line in out.splitlines() if re.match(r"\s*\d+\s+\d", line)]
    assert [int(r[0]) for r in rows] == [0, 20, 100, 400]
    for r in rows:
        one, two, speedup = float(r[1]), float(r[2]), float(r[3].rstrip("x"))
        assert one >= 0 and two > 0 and speedup >= 0, r
