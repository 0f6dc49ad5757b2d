"""The batched-use script runs and prints a rate for every id and the sweep's times
(numbers not judged)."""

import re
import subprocess
import sys
from pathlib import Path

import machining_envs

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "batched_use.py"


def test_batched_use_script_prints_every_env_and_the_sweep():
    out = subprocess.run(
        [
            sys.executable,
            str(SCRIPT),
            "--lanes",
            "4",
            "--steps",
            "20",
            "--rounds",
            "1",
            "--sweep",
            "3",
        ],  # fmt: skip
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    for env_id in machining_envs.ENV_IDS:
        line = next(row for row in out.splitlines() if row.startswith(env_id))
        rates = [float(x) for x in line.split()[2:]]
        assert len(rates) == 5 and all(r > 0 for r in rates), line
    assert re.search(r"batched \d+\.\d+ s, episode by episode \d+\.\d+ s", out), out
