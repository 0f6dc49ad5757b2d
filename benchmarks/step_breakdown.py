"""Where a native vector env's steady step goes: per lane-step, the compiled physics, the
lanes' resets, the env's own Python around them, and the base's checks and bookkeeping.

Each id's vector env (N = 1024 by default, one thread) is stepped with random actions past
one mean episode of the single env (so that its lanes' episodes end at spread-out times, as
in the steady columns of ``throughput.py``), then timed over as many steps again, with the
env's own methods timed in place:

- **compiled**: the core's ``step`` (the kernel over every lane, and the CNC actuation
  where a scenario has one);
- **resets**: ``_reset_lanes`` (each finished lane's new scenario, plant and first
  observation, in Python, one lane at a time);
- **env Python**: the rest of ``_step_lanes`` (the actions' clipping, the sensor noise's
  draws, the copies of the step's outputs and info arrays) and ``_info_now`` (every lane's
  info read again at a step that resets lanes);
- **base**: the rest of the vector step (the actions' checks, the info's masks, the final
  observations and info of the finished lanes).

The shares tell which part a faster env must cut; the microseconds move with the machine.

    python benchmarks/step_breakdown.py [--lanes 1024] [--env machining_envs/Turning-v0 ...]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
from throughput import steady_window, steps_per_second  # this folder's script

import machining_envs


def _timed(obj, name: str, acc: dict, key: str) -> None:
    """Replace the bound method ``obj.name`` by one that adds its run time to ``acc[key]``."""
    inner = getattr(obj, name)

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            acc[key] += time.perf_counter() - t0

    setattr(obj, name, wrapper)


def breakdown(
    env_id: str, num_envs: int, episode_steps: float, seed: int, num_threads: int = 1
) -> dict:
    """Seconds per lane-step of each part of a steady vector step, and resets per step."""
    venv = gym.make_vec(env_id, num_envs=num_envs, num_threads=num_threads)
    space = venv.single_action_space
    rng = np.random.default_rng(seed)
    actions = rng.uniform(space.low, space.high, size=(256, num_envs, *space.shape))
    actions = actions.astype(space.dtype)
    n = steady_window(episode_steps, num_envs)
    venv.reset(seed=seed)
    for i in range(n):
        venv.step(actions[i % 256])
    base = venv.unwrapped
    acc = dict.fromkeys(("step_lanes", "compiled", "resets", "info_now"), 0.0)
    _timed(base, "_step_lanes", acc, "step_lanes")
    _timed(base._core, "step", acc, "compiled")
    _timed(base, "_reset_lanes", acc, "resets")
    _timed(base, "_info_now", acc, "info_now")
    ends = 0
    t0 = time.perf_counter()
    for i in range(n):
        _, _, terminated, truncated, _ = venv.step(actions[i % 256])
        ends += int(np.count_nonzero(terminated | truncated))
    total = time.perf_counter() - t0
    venv.close()
    per = 1.0 / (n * num_envs)
    env_python = acc["step_lanes"] - acc["compiled"] + acc["info_now"]
    return {
        "total": total * per,
        "compiled": acc["compiled"] * per,
        "resets": acc["resets"] * per,
        "env Python": env_python * per,
        "base": (total - acc["step_lanes"] - acc["resets"] - acc["info_now"]) * per,
        "resets/step": ends / n,
        "per reset": acc["resets"] / max(ends, 1),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lanes", type=int, default=1024)
    ap.add_argument("--env", nargs="+", default=list(machining_envs.ENV_IDS))
    ap.add_argument("--episode-steps", type=int, default=20_000,
                    help="single-env steps that measure the mean episode")  # fmt: skip
    ap.add_argument("--threads", type=int, default=1,
                    help="the vector env's num_threads (the compiled part runs on them)")  # fmt: skip
    args = ap.parse_args(argv)
    parts = ("compiled", "resets", "env Python", "base")
    print(
        f"steady vector step, N = {args.lanes}, num_threads = {args.threads}, random actions: "
        "µs per lane-step "
        "(share of the step)"
    )
    print(
        f"{'env':34s} {'step':>6s}"
        + "".join(f" {p:>15s}" for p in parts)
        + f" {'resets/step':>11s} {'µs/reset':>9s}"
    )
    for env_id in args.env:
        resets = steps_per_second(env_id, args.episode_steps, seed=0)[2]
        episode = args.episode_steps / max(resets, 1)  # as throughput.py's steady columns
        b = breakdown(env_id, args.lanes, episode, seed=0, num_threads=args.threads)
        cells = "".join(
            f" {b[p] * 1e6:7.2f} ({b[p] / b['total']:4.0%})" for p in parts
        )  # fmt: skip
        print(
            f"{env_id:34s} {b['total'] * 1e6:6.2f}{cells} {b['resets/step']:11.1f}"
            f" {b['per reset'] * 1e6:9.0f}"
        )


if __name__ == "__main__":
    main()
