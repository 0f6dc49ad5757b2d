"""The batched-use script runs and prints a rate for every id and the sweep's times
(numbers not judged)."""

import re

import machining_envs
from tests.benchmark_scripts import run_benchmark


def test_batched_use_script_prints_every_env_and_the_sweep():
    out = run_benchmark("batched_use.py --lanes 4 --steps 20 --rounds 1 --sweep 3")
    for env_id in machining_envs.ENV_IDS:
        line = next(row for row in out.splitlines() if row.startswith(env_id))
        rates = [float(x) for x in line.split()[2:]]
        assert len(rates) == 5 and all(r > 0 for r in rates), line
    assert re.search(r"batched \d+\.\d+ s, episode by episode \d+\.\d+ s", out), out
