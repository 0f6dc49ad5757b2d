"""Where a native vector env's steady step goes: per lane-step, the compiled physics, the
lanes' resets, the env's own Python around them, and the base's checks and bookkeeping.

Each id's vector env (N = 1024 by default, one thread) is stepped with random actions past
one mean episode of the single env (so that its lanes' episodes end at spread-out times, as
in the steady columns of ``throughput.py``), then timed over as many steps again, with the
env's own methods timed in place:

- **compiled**: the core's ``step`` (the kernel over every lane, and the CNC actuation
  where a scenario has one);
- **resets**: ``_reset_lanes`` (the finished lanes' new scenarios, plants and first
  observations: a split's lanes drawn and started together in compiled calls, with their
  bookkeeping in Python; other scenarios one lane at a time);
- **env Python**: the rest of ``_step_lanes`` (the actions' clipping, the sensor noise's
  draws, the copies of the step's outputs and info arrays) and ``_info_now`` (every lane's
  info read again at a step that resets lanes);
- **base**: the rest of the vector step (the actions' checks, the info's masks, the final
  observations and info of the finished lanes).

The shares tell which part a faster env must cut; the microseconds move with the machine.
``--frozen`` adds the compiled step timed alone: the core's ``step`` called 200 times on the
steady state reached, every array of the core put back before each call, so that each call
steps the same lanes through the same sample (the median call; what an A/B of two versions
of a kernel compares, with less noise than a step among resets and Python).

Each row also gives the single env's step (``gym.make(id)``, its resets counted, from the
run that measures the mean episode) and the vector env's multiple of it (**x single**: the
single env's µs per step over the vector env's per lane-step). With ``--frozen``,
**ceiling** is that multiple if every part of the vector step but the compiled physics
cost nothing: the single env's step over the compiled step alone. No vector env that runs
the same physics per lane on these threads can go past it.

    python benchmarks/step_breakdown.py [--lanes 1024] [--env machining_envs/Turning-v0 ...]
                                        [--threads K] [--frozen]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
from throughput import steady_window, steps_per_second  # this folder's script

import machining_envs
from machining_envs.core.compiled.blocks import LaneBlocks


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


def _core_arrays(obj, depth: int = 2, seen: set | None = None) -> list[np.ndarray]:
    """The writable numpy arrays a core holds: its attributes', and those of the library's
    objects it holds (the plant's lanes, the servo loops), ``depth`` levels down. Not the
    lane blocks' (``core.compiled.blocks``): their workers' flags are the threads' handshake, not
    the lanes' state, and a worker asleep whose flags were put back as awake is never
    woken again."""
    seen = set() if seen is None else seen
    if id(obj) in seen or isinstance(obj, LaneBlocks):
        return []
    seen.add(id(obj))
    names = list(getattr(obj, "__dict__", {})) + list(getattr(type(obj), "__slots__", ()))
    out = []
    for name in names:
        v = getattr(obj, name, None)
        items = v if isinstance(v, (tuple, list)) and len(v) < 64 else (v,)
        for x in items:
            if isinstance(x, np.ndarray):
                if x.flags.writeable and x.dtype != object and id(x) not in seen:
                    seen.add(id(x))
                    out.append(x)
            elif depth and type(x).__module__.startswith("machining_envs"):
                out += _core_arrays(x, depth - 1, seen)
    return out


def frozen_step(venv, calls: int = 200) -> float:
    """Seconds per lane of the core's ``step`` on the state reached, restored before each
    call (median of ``calls``). The lanes' noise generators are not arrays of the core and
    run on: each call draws new sensor noise, which the arithmetic does not depend on; the
    env is left for closing."""
    core = venv.unwrapped._core
    step = type(core).step  # not the timed wrapper breakdown() put on the instance
    arrays = _core_arrays(core)
    saved = [a.copy() for a in arrays]
    times = []
    for _ in range(calls):
        for a, v in zip(arrays, saved, strict=True):
            a[...] = v
        t0 = time.perf_counter()
        step(core)
        times.append(time.perf_counter() - t0)
    for a, v in zip(arrays, saved, strict=True):
        a[...] = v
    return float(np.median(times)) / venv.num_envs


def breakdown(
    env_id: str,
    num_envs: int,
    episode_steps: float,
    seed: int,
    num_threads: int = 1,
    frozen: bool = False,
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
    alone = frozen_step(venv) if frozen else float("nan")
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
        "alone": alone,
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lanes", type=int, default=1024)
    ap.add_argument("--env", nargs="+", default=list(machining_envs.ENV_IDS))
    ap.add_argument(
        "--episode-steps",
        type=int,
        default=20_000,
        help="single-env steps that measure the mean episode",
    )
    ap.add_argument(
        "--threads",
        type=int,
        default=1,
        help="the vector env's num_threads (the compiled part runs on them)",
    )
    ap.add_argument(
        "--frozen", action="store_true", help="also the compiled step timed alone on a frozen state"
    )
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
        + f" {'resets/step':>11s} {'µs/reset':>9s} {'single':>6s} {'x single':>8s}"
        + (f" {'alone':>6s} {'ceiling':>7s}" if args.frozen else "")
    )
    for env_id in args.env:
        _, single_rate, resets = steps_per_second(env_id, args.episode_steps, seed=0)
        single = 1.0 / single_rate  # seconds per step of the single env, its resets counted
        episode = args.episode_steps / max(resets, 1)  # as throughput.py's steady columns
        b = breakdown(
            env_id, args.lanes, episode, seed=0, num_threads=args.threads, frozen=args.frozen
        )
        cells = "".join(f" {b[p] * 1e6:7.2f} ({b[p] / b['total']:4.0%})" for p in parts)
        print(
            f"{env_id:34s} {b['total'] * 1e6:6.2f}{cells} {b['resets/step']:11.1f}"
            f" {b['per reset'] * 1e6:9.0f} {single * 1e6:6.2f} {single / b['total']:8.1f}"
            + (f" {b['alone'] * 1e6:6.2f} {single / b['alone']:7.1f}" if args.frozen else "")
        )


if __name__ == "__main__":
    main()
