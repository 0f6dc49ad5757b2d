"""The throughput script runs and prints a ratio for every registered env (numbers not judged)."""

import machining_envs
from tests.benchmark_scripts import run_benchmark


def test_throughput_script_reports_every_env():
    out = run_benchmark(
        "throughput.py --steps 200 --rounds 1 --lanes 1 16 --vector-steps 2000 --sync-steps 200"
    )
    for env_id in ("Pendulum-v1", *machining_envs.ENV_IDS):
        line = next(row for row in out.splitlines() if row.startswith(env_id))
        rate, ratio = (float(x) for x in line.split()[1:3])
        # A rate, and its ratio to Pendulum's printed to two decimals (a slow env on a busy
        # machine may print 0.00: the numbers are not judged).
        assert rate > 0 and ratio >= 0
    vector = out[out.index("native vector envs") :]
    for env_id in machining_envs.ENV_IDS:  # every id has its native vector env
        line = next(row for row in vector.splitlines() if row.startswith(env_id))
        assert "no native vector env" not in line
