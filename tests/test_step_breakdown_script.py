"""The step-breakdown script runs and splits every vector env's step (numbers not judged)."""

import re

import machining_envs
from tests.benchmark_scripts import run_benchmark


def test_step_breakdown_script_splits_every_env():
    """The four parts add up to the step; ``--frozen``'s calls of the compiled step alone
    come after the timed steps and stay out of them."""
    out = run_benchmark("step_breakdown.py --lanes 16 --episode-steps 200 --frozen")
    for env_id in machining_envs.ENV_IDS:
        line = next(row for row in out.splitlines() if row.startswith(env_id))
        values = [float(x) for x in re.findall(r"(?<![\w(])-?\d+\.\d+(?!%)", line)]
        total, *parts = values[:5]
        assert values[-1] > 0, line  # the compiled step alone
        shares = [int(s) for s in re.findall(r"\(\s*(-?\d+)%\)", line)]
        assert total > 0 and parts[0] > 0, line  # the compiled step takes some time
        assert len(shares) == 4 and all(0 <= s <= 100 for s in shares), line
        assert abs(sum(parts) - total) <= 0.03, line  # printed to two decimals
