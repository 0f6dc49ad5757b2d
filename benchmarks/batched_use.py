"""What the native vector envs cost through the two ways users reach them most: SB3's
``VecEnv`` interface (``agents.rl.vec.SB3VecEnv``) and the evaluation harness.

- **SB3 adapter**: steps of the adapter over ``gym.make_vec(id, num_envs=N)`` against the
  bare vector env in the same run, with the per-env info dicts holding every info key (the
  default, as SB3's ``DummyVecEnv`` gives them) and with ``info_keys=()`` (the terminal
  observation and ``TimeLimit.truncated`` only). Random actions drawn beforehand; each rate
  is the best of ``--rounds`` windows of ``--steps`` steps, taken in turn.
- **Harness sweep**: ``agents.eval.evaluate`` of Turning-v0's fixed-gain PI over
  ``--sweep`` spindle speeds (the paper's stepped bar, one episode each), batched (every
  speed a lane of one vector env) against episode by episode; the rows are the same
  (``tests/agents/test_harness.py``).

    python benchmarks/batched_use.py [--lanes 16 1024] [--steps 200] [--sweep 32]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import machining_envs
from agents import FixedGainPI
from agents.eval import evaluate
from agents.rl.vec import SB3VecEnv
from machining_envs.core.workpieces import DepthProfile
from machining_envs.turning.scenarios import TurningScenario


def _rate(step, actions) -> float:
    t0 = time.perf_counter()
    for a in actions:
        step(a)
    return len(actions) / (time.perf_counter() - t0)


def adapter_rates(env_id: str, n: int, steps: int, rounds: int) -> tuple[float, float, float]:
    """Steps/s of the bare vector env, the adapter with every info key, and with none."""
    same = {"autoreset_mode": "SAME_STEP"}  # the adapter's mode, in all three
    raw = gym.make_vec(env_id, num_envs=n, **same)
    full = SB3VecEnv(gym.make_vec(env_id, num_envs=n, **same))
    bare = SB3VecEnv(gym.make_vec(env_id, num_envs=n, **same), info_keys=())
    space = raw.single_action_space
    rng = np.random.default_rng(0)
    actions = rng.uniform(space.low, space.high, (steps, n, *space.shape)).astype(space.dtype)
    raw.reset(seed=0)
    for v in (full, bare):
        v.seed(0)
        v.reset()
    for step in (raw.step, full.step, bare.step):  # untimed: the kernels load (or compile,
        step(actions[0])  # on a fresh install) at the first step
    best = [0.0, 0.0, 0.0]
    for _ in range(rounds):
        for k, step in enumerate((raw.step, full.step, bare.step)):
            best[k] = max(best[k], _rate(step, actions))
    return best[0], best[1], best[2]


def sweep_times(n: int) -> tuple[float, float]:
    """Seconds of the harness over ``n`` spindle speeds, batched and episode by episode."""
    bar = DepthProfile.steps((1.0, 2.0, 3.0), 10.0)
    sweep = [TurningScenario(f"{rpm:.0f} rpm", bar, float(rpm)) for rpm in np.linspace(245, 700, n)]
    for batched in (True, False):  # untimed: the compiled kernels load on first use
        evaluate(FixedGainPI.from_env, "machining_envs/Turning-v0", sweep[:2], batched=batched)
    times = []
    for batched in (True, False):
        t0 = time.perf_counter()
        evaluate(FixedGainPI.from_env, "machining_envs/Turning-v0", sweep, batched=batched)
        times.append(time.perf_counter() - t0)
    return times[0], times[1]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lanes", type=int, nargs="+", default=[16, 1024])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--sweep", type=int, default=32, help="spindle speeds of the harness sweep")
    ap.add_argument("--env", nargs="+", default=list(machining_envs.ENV_IDS))
    args = ap.parse_args(argv)
    print("SB3VecEnv over the native vector env: steps/s, and the vector env's rate over it")
    print(
        f"{'env':34s} {'N':>5s} {'vector env':>11s} {'all info':>9s} {'x slower':>8s}"
        f" {'info_keys=()':>12s} {'x slower':>8s}"
    )
    for env_id in args.env:
        for n in args.lanes:
            raw, full, bare = adapter_rates(env_id, n, args.steps, args.rounds)
            print(
                f"{env_id:34s} {n:5d} {raw:11.0f} {full:9.0f} {raw / full:8.2f}"
                f" {bare:12.0f} {raw / bare:8.2f}"
            )
    batched, one = sweep_times(args.sweep)
    print(
        f"\nharness, Turning-v0 FixedGainPI over {args.sweep} spindle speeds (one episode each):"
        f" batched {batched:.2f} s, episode by episode {one:.2f} s, {one / batched:.1f}x"
    )


if __name__ == "__main__":
    main()
