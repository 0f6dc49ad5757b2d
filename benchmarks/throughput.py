"""Single-env step throughput of the machining envs against Gymnasium's Pendulum-v1.

Both envs are made with ``gym.make`` (same default wrappers) and stepped in the same process,
interleaved over several rounds, with uniformly random actions drawn beforehand from a
seeded generator so that action sampling is not timed. Two rates per env:

- ``step``: env.step calls only (the target: Turning-v0 >= 0.5x Pendulum-v1);
- ``with resets``: the whole loop, resets included. Random feed commands break the tool
  within about 50 steps, so Turning-v0 resets every ~50 steps (each reset draws a workpiece
  and discretises the plant at a new spindle speed, ~0.5 ms), Pendulum-v1 every 200.

    python benchmarks/throughput.py [--steps 20000] [--rounds 5]
"""

from __future__ import annotations

import argparse
import platform
import time

import gymnasium as gym
import numpy as np

import machining_envs

PEER = "Pendulum-v1"


def steps_per_second(env_id: str, n_steps: int, seed: int) -> tuple[float, float, int]:
    """(steps/s counting step calls only, steps/s of the whole loop, number of resets)."""
    env = gym.make(env_id)
    rng = np.random.default_rng(seed)
    low, high = env.action_space.low, env.action_space.high
    actions = rng.uniform(low, high, size=(n_steps, *env.action_space.shape)).astype(np.float32)
    env.reset(seed=seed)
    clock = time.perf_counter
    in_step = 0.0
    resets = 0
    t0 = clock()
    for a in actions:
        t1 = clock()
        _, _, terminated, truncated, _ = env.step(a)
        in_step += clock() - t1
        if terminated or truncated:
            env.reset()
            resets += 1
    total = clock() - t0
    env.close()
    return n_steps / in_step, n_steps / total, resets


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args(argv)
    ids = [PEER, *machining_envs.ENV_IDS]
    rates = {i: [] for i in ids}
    for r in range(args.rounds):
        for env_id in ids:
            rates[env_id].append(steps_per_second(env_id, args.steps, seed=r))
    print(
        f"python {platform.python_version()}, numpy {np.__version__}, gymnasium {gym.__version__}; "
        f"{args.rounds} rounds x {args.steps} random-action steps, median of rounds"
    )
    med = {i: np.median(np.array(rates[i]), axis=0) for i in ids}
    print(
        f"{'env':34s} {'step/s':>9s} {'ratio':>6s} {'with resets/s':>14s} {'ratio':>6s} {'resets':>7s}"
    )
    for env_id in ids:
        s, w, n = med[env_id]
        print(
            f"{env_id:34s} {s:9.0f} {s / med[PEER][0]:6.2f} {w:14.0f} {w / med[PEER][1]:6.2f} {n:7.0f}"
        )


if __name__ == "__main__":
    main()
