"""The step-breakdown script runs and splits every vector env's step (numbers not judged)."""

import re

import gymnasium as gym
import numpy as np

import machining_envs
from tests.benchmark_scripts import BENCHMARKS, run_benchmark


def test_step_breakdown_script_splits_every_env():
    """The four parts add up to the step, and the multiples of the single env are its step
    over the vector env's and over the compiled step alone; ``--frozen``'s calls of the
    compiled step alone come after the timed steps and stay out of them."""
    out = run_benchmark("step_breakdown.py --lanes 16 --episode-steps 200 --frozen")
    for env_id in machining_envs.ENV_IDS:
        line = next(row for row in out.splitlines() if row.startswith(env_id))
        values = [float(x) for x in re.findall(r"(?<![\w(])-?\d+\.\d+(?!%)", line)]
        total, *parts = values[:5]
        single, x_single, alone, ceiling = values[-4:]
        assert single > 0 and alone > 0, line  # the single env's step, the compiled step alone
        # Each multiple is the single env's step over the vector env's (printed rounded).
        for ratio, per_lane in ((x_single, total), (ceiling, alone)):
            slack = 0.05 + ratio * (0.005 / per_lane + 0.005 / single)
            assert abs(ratio - single / per_lane) <= slack, line
        shares = [int(s) for s in re.findall(r"\(\s*(-?\d+)%\)", line)]
        assert total > 0 and parts[0] > 0, line  # the compiled step takes some time
        assert len(shares) == 4 and all(0 <= s <= 100 for s in shares), line
        assert abs(sum(parts) - total) <= 0.03, line  # printed to two decimals


def test_frozen_steps_leave_the_lane_blocks_threads_alone(monkeypatch):
    """``--frozen`` puts the core's arrays back before each call of the compiled step, and
    not the worker threads' flags among them: a worker asleep whose flags were put back as
    awake was never woken, and ``--threads 2 --frozen`` hung."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import step_breakdown

    venv = gym.make_vec("machining_envs/EndMilling-v0", num_envs=256, num_threads=2)
    try:
        venv.reset(seed=0)
        venv.step(np.zeros((256, 1), dtype=np.float32))  # starts the worker thread
        blocks = venv.unwrapped._core.blocks
        flags = [w.ctl for w in blocks._workers]
        assert flags, "no worker thread to check"
        restored = step_breakdown._core_arrays(venv.unwrapped._core)
        assert restored, "no array of the core found"
        assert not any(np.shares_memory(a, f) for a in restored for f in flags)
        assert step_breakdown.frozen_step(venv, calls=3) > 0
    finally:
        venv.close()
