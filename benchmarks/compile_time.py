"""What the first steps of each env cost on a fresh install, where numba compiles the kernels,
against the same steps once they are cached on disk.

For each id, in a fresh interpreter whose numba cache is a new empty folder
(``NUMBA_CACHE_DIR``): ``gym.make`` with ``reset`` and one ``step`` (the single env), then
``gym.make_vec`` (16 lanes on two threads) with ``reset`` and one ``step``. Then the same in
a second fresh interpreter on the cache the first one left: what every later process pays.
The ids run in separate interpreters, so each pays for the kernels it shares with others
(``core``'s) as a user who needs only that env does.

    python benchmarks/compile_time.py [--env machining_envs/Turning-v0 ...]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

import machining_envs

CODE = """
import time
t0 = time.perf_counter()
import gymnasium as gym
import machining_envs
env = gym.make({env_id!r})
env.reset(seed=0)
env.step(env.action_space.sample())
t1 = time.perf_counter()
venv = gym.make_vec({env_id!r}, num_envs=16, num_threads=2)
venv.reset(seed=0)
venv.step(venv.action_space.sample())
venv.close()
print(t1 - t0, time.perf_counter() - t1)
"""


def first_steps(env_id: str, cache: str) -> tuple[float, float]:
    """Seconds of the single env's and the vector env's first steps (with the imports) in a
    fresh interpreter whose numba cache is the folder ``cache``."""
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    out = subprocess.run(
        [sys.executable, "-c", CODE.format(env_id=env_id)],
        capture_output=True,
        text=True,
        check=True,
        env=env,
    )
    single, vector = (float(x) for x in out.stdout.split()[-2:])
    return single, vector


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", nargs="+", default=list(machining_envs.ENV_IDS))
    args = ap.parse_args(argv)
    print(f"python {sys.version.split()[0]}; seconds of the first single-env step and the first")
    print("vector-env step (16 lanes, two threads), imports included, in a fresh interpreter:")
    print("cold = an empty numba cache (a fresh install), cached = the cache the cold run left")
    print(
        f"{'env':36s} {'cold single':>11s} {'cold vector':>11s} {'cold':>7s} {'cached':>7s}"
        f" {'x cached':>8s}"
    )
    total = 0.0
    for env_id in args.env:
        with tempfile.TemporaryDirectory() as cache:
            cold = first_steps(env_id, cache)
            warm = first_steps(env_id, cache)
        c, w = sum(cold), sum(warm)
        total += c
        print(f"{env_id:36s} {cold[0]:11.1f} {cold[1]:11.1f} {c:7.1f} {w:7.2f} {c / w:8.1f}")
    print(f"{'sum (each from an empty cache)':36s} {'':11s} {'':11s} {total:7.1f}")


if __name__ == "__main__":
    main()
