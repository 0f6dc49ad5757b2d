"""Step throughput of the machining envs: single envs against Gymnasium's Pendulum-v1, native
vector envs against the single env, SyncVectorEnv and Gymnasium's CartPoleVectorEnv.

Both envs are made with ``gym.make`` (same default wrappers) and stepped in the same process,
interleaved over several rounds, with uniformly random actions drawn beforehand from a
seeded generator so that action sampling is not timed. Two rates per env:

- ``step``: env.step calls only (the target: every env >= 1.0x Pendulum-v1);
- ``with resets``: the whole loop, resets included. Random feed commands break the tool
  within about 50 steps, so Turning-v0 resets every ~50 steps (each reset draws a workpiece
  and discretises the plant at a new spindle speed, ~0.5 ms), Pendulum-v1 every 200.

The second table steps each id's native vector env (``gym.make_vec(id, num_envs=N)``) at
N = 1, 64, 1024 and 8192 with random actions (finished lanes reset in the same step), each
over about 200 000 env-steps from the first reset: with long episodes few lanes finish in
that window, so these rates leave most resets out. The column ``steady`` runs the N = 1024
env on past that: one mean episode of the single env under random actions untimed (the
lanes' episodes then end at spread-out times), then as many steps timed, once per round
(at least 200 steps; each window capped at 2.5 million env-steps), so that it pays its
resets as the single env's rate (with resets) does. After each window the single env runs
as in the first table (``--steps`` steps, resets included), so that each round gives a
ratio of two rates taken seconds apart: this machine's speed drifts by up to a fifth within
minutes, which moved the ratios by as much when the single env's rate came from the first
table, minutes earlier. ``x single`` is the median of the rounds' ratios, ``range`` the
lowest and highest; ``x sync`` is the N = 1024 rate over Gymnasium's ``SyncVectorEnv`` of
N copies of the single env over the same window from the first reset. The memory per lane
is what ``tracemalloc`` counts for making and resetting the N = 1024 env, over 1024.
Gymnasium's ``CartPoleVectorEnv`` at N = 1024 is the reference row.

Every rate above is of envs on one thread. The steady columns come again for
``num_threads=T`` (``--threads``, by default the CPUs this process may use): the kernel
then steps blocks of lanes on T threads, the rest of the step staying on one; each round
takes the one-thread and the T-thread windows in turn, each paired with its own run of the
single env (which always runs on one thread).

    python benchmarks/throughput.py [--steps 20000] [--rounds 5] [--lanes 1 64 1024 8192]
                                    [--threads T] [--env machining_envs/Turning-v0 ...]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import tracemalloc

import gymnasium as gym
import numpy as np

import machining_envs

PEER = "Pendulum-v1"


def usable_cpus() -> int:
    """The CPUs this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def steps_per_second(env_id: str, n_steps: int, seed: int) -> tuple[float, float, int]:
    """(steps/s counting step calls only, steps/s of the whole loop, number of resets)."""
    env = gym.make(env_id)
    rng = np.random.default_rng(seed)
    low, high = env.action_space.low, env.action_space.high
    actions = rng.uniform(low, high, size=(n_steps, *env.action_space.shape)).astype(np.float32)
    env.reset(seed=seed)
    env.step(actions[0])  # first call: compiled kernels are loaded (once per process)
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


def vector_steps_per_second(
    env_id: str, num_envs: int, env_steps: int, seed: int, mode: str | None = None
) -> float:
    """Env-steps per second of ``gym.make_vec(env_id, num_envs)`` over about ``env_steps``
    env-steps (at least 5 batched steps) with random actions drawn beforehand."""
    kwargs = {} if mode is None else {"vectorization_mode": mode}
    if mode is None and env_id.startswith("machining_envs/"):
        # the mode the table has always measured (SB3's); NEXT_STEP, the default, differs
        # from it by less than the machine's noise (docs/performance.md)
        kwargs["autoreset_mode"] = "SAME_STEP"
    venv = gym.make_vec(env_id, num_envs=num_envs, **kwargs)
    n = max(5, env_steps // num_envs)
    rng = np.random.default_rng(seed)
    space = venv.single_action_space
    if isinstance(space, gym.spaces.Discrete):
        actions = rng.integers(space.n, size=(n, num_envs))
    else:
        actions = rng.uniform(space.low, space.high, size=(n, num_envs, *space.shape))
        actions = actions.astype(space.dtype)
    venv.reset(seed=seed)
    venv.step(actions[0])  # first call: compiled kernels are loaded
    t0 = time.perf_counter()
    for a in actions:
        venv.step(a)
    rate = n * num_envs / (time.perf_counter() - t0)
    venv.close()
    return rate


def steady_window(episode_steps: float, num_envs: int) -> int:
    """Steps of a steady window (and of the untimed run before it): one mean episode of
    the single env, at least 200 steps and at most 2.5 M env-steps."""
    return min(max(200, int(episode_steps)), max(200, 2_500_000 // num_envs))


def vector_steady_rates(
    env_id: str,
    num_envs: int,
    episode_steps: float,
    seed: int,
    rounds: int,
    single_steps: int,
    threads: list[int],
) -> dict[int, tuple[list[float], list[float]]]:
    """Env-steps per second of the native vector env once its lanes' episodes have spread
    out (see the module docstring), in ``rounds`` windows, and after each window the single
    env's steps per second with resets over ``single_steps`` steps (:func:`steps_per_second`),
    so that each round's ratio compares two rates taken seconds apart; random actions cycle
    through 256 batches drawn beforehand. One env per entry of ``threads`` (its
    ``num_threads``), all on the same actions, their windows taken in turn in each round:
    ``{num_threads: (rates, singles)}``."""
    venvs = {t: gym.make_vec(env_id, num_envs=num_envs, num_threads=t) for t in threads}
    n = steady_window(episode_steps, num_envs)
    rng = np.random.default_rng(seed)
    space = venvs[threads[0]].single_action_space
    actions = rng.uniform(space.low, space.high, size=(256, num_envs, *space.shape))
    actions = actions.astype(space.dtype)
    for venv in venvs.values():
        venv.reset(seed=seed)
        for i in range(n):
            venv.step(actions[i % 256])
    out: dict[int, tuple[list[float], list[float]]] = {t: ([], []) for t in threads}
    for r in range(rounds):
        for t, venv in venvs.items():
            t0 = time.perf_counter()
            for i in range(n):
                venv.step(actions[i % 256])
            out[t][0].append(n * num_envs / (time.perf_counter() - t0))
            out[t][1].append(steps_per_second(env_id, single_steps, seed=r)[1])
    for venv in venvs.values():
        venv.close()
    return out


def bytes_per_lane(env_id: str, num_envs: int) -> float:
    """Memory allocated to make and reset the native vector env, per lane (tracemalloc)."""
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    venv = gym.make_vec(env_id, num_envs=num_envs)
    venv.reset(seed=0)
    used = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    venv.close()
    return used / num_envs


def vector_table(
    lanes: list[int],
    env_steps: int,
    sync_steps: int,
    singles: dict,
    rounds: int,
    single_steps: int,
    threads: int,
    env_ids: tuple = machining_envs.ENV_IDS,
) -> None:
    """The vector envs' table; ``singles[id]`` = the single env's mean episode length in
    steps (from the first table); each steady round is paired with ``single_steps`` steps of
    the single env; the steady columns again with ``num_threads=threads`` if above 1."""
    ref_n = 1024 if 1024 in lanes else lanes[-1]
    counts = [1, threads] if threads > 1 else [1]
    print(
        f"\nnative vector envs: env-steps/s with random actions from the first reset, one "
        f"thread; steady: N = {ref_n} with resets spread out, median of {rounds} rounds; "
        f"x single = median over the rounds of steady / the single env with resets measured "
        f"right after it, range over the rounds"
        + (f"; again with num_threads={threads} (T{threads})" if threads > 1 else "")
        + f"; x sync at N = {ref_n} from the first reset; memory per lane from N = {ref_n}"
    )
    head = f"{'env':34s}" + "".join(f" {f'N={n}':>10s}" for n in lanes)
    for t in counts:
        tag = "" if t == 1 else f" T{t}"
        head += f" {'steady' + tag:>10s} {'x single' + tag:>11s} {'range':>11s}"
    print(head + f" {'x sync':>7s} {'kB/lane':>8s}")
    cart = vector_steps_per_second("CartPole-v1", ref_n, env_steps, 0, "vector_entry_point")
    print(
        f"{'CartPoleVectorEnv (reference)':34s}"
        + "".join(f" {cart:10.0f}" if n == ref_n else f" {'':>10s}" for n in lanes)
    )
    for env_id in env_ids:
        if gym.spec(env_id).vector_entry_point is None:
            print(f"{env_id:34s} no native vector env yet")
            continue
        rates = {n: vector_steps_per_second(env_id, n, env_steps, 0) for n in lanes}
        steady = vector_steady_rates(
            env_id, ref_n, singles[env_id], 0, rounds, single_steps, counts
        )
        sync = vector_steps_per_second(env_id, ref_n, sync_steps, 0, "sync")
        kb = bytes_per_lane(env_id, ref_n) / 1024
        row = f"{env_id:34s}" + "".join(f" {rates[n]:10.0f}" for n in lanes)
        for t in counts:
            vec, paired = steady[t]
            ratios = [v / s for v, s in zip(vec, paired, strict=True)]
            span = f"{min(ratios):.1f}-{max(ratios):.1f}"
            row += f" {np.median(vec):10.0f} {np.median(ratios):11.1f} {span:>11s}"
        print(row + f" {rates[ref_n] / sync:7.1f} {kb:8.1f}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--lanes", type=int, nargs="+", default=[1, 64, 1024, 8192])
    ap.add_argument("--vector-steps", type=int, default=200_000, help="env-steps per vector rate")
    ap.add_argument("--sync-steps", type=int, default=20_000, help="env-steps of SyncVectorEnv")
    ap.add_argument("--no-vector", action="store_true", help="single envs only")
    ap.add_argument(
        "--env",
        nargs="+",
        default=list(machining_envs.ENV_IDS),
        choices=machining_envs.ENV_IDS,
        help="the ids to measure (default: every one), each against Pendulum-v1 as ever",
    )
    ap.add_argument(
        "--threads",
        type=int,
        default=usable_cpus(),
        help="num_threads of the second steady columns (default: this process's CPUs; 1: none)",
    )
    args = ap.parse_args(argv)
    ids = [PEER, *args.env]
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
    if not args.no_vector:
        episodes = {i: args.steps / max(med[i][2], 1) for i in ids}
        vector_table(
            sorted(args.lanes),
            args.vector_steps,
            args.sync_steps,
            episodes,
            args.rounds,
            args.steps,
            args.threads,
            tuple(args.env),
        )


if __name__ == "__main__":
    main()
