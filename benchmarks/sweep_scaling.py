"""Trial throughput of ``machining-bench sweep`` on one and on two local Ray workers.

The same seed sweep (``--trials`` trials of PPO on ``--env``, ``--timesteps`` env steps each,
the shipped config otherwise) runs twice, each time on a fresh local Ray instance: with one
worker (one trial at a time) and with two. Each run's time is the sweep's wall clock from
Ray's start to the written results folder; the printed ratio is two workers' trials per
minute over one worker's. On a 2-core machine the ideal is 2.0.

    python benchmarks/sweep_scaling.py [--env machining_envs/Turning-v0] [--trials 4]
                                       [--timesteps 8192]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

from agents.rl.sweep import SweepSettings, sweep


def _run(env: str, trials: int, steps: int, workers: int) -> float:
    settings = SweepSettings(
        env, "ppo", seeds=list(range(trials)), n_timesteps=steps, workers=workers
    )
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        sweep(settings, os.path.join(tmp, "sweep"), verbose=False)
        return time.perf_counter() - t0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="machining_envs/Turning-v0")
    p.add_argument("--trials", type=int, default=4)
    p.add_argument("--timesteps", type=int, default=8192)
    args = p.parse_args()
    print(
        f"{os.cpu_count()} CPUs; {args.trials} PPO trials of {args.timesteps} steps on {args.env}"
    )
    rates = {}
    for workers in (1, 2):
        wall = _run(args.env, args.trials, args.timesteps, workers)
        rates[workers] = args.trials / wall * 60
        print(f"{workers} worker(s): {wall:6.1f} s, {rates[workers]:.2f} trials/min")
    print(f"two workers / one worker: {rates[2] / rates[1]:.2f}x trial throughput")


if __name__ == "__main__":
    main()
