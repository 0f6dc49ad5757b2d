"""What running a kernel on blocks of lanes costs on several threads against one: the
handoff of ``machining_envs.core.compiled.blocks.LaneBlocks`` (its workers wait for their blocks in
compiled code, and the calling thread waits for them), measured on this machine.

A compiled kernel (no GIL) does ``work`` multiply-adds per lane over 1024 lanes; one
``LaneBlocks.run`` on one thread and on ``--threads`` threads, each the best of several
windows of 2000 runs. ``handoff`` is what a run on K threads costs beyond a K-th of the
one-thread run: a vector env on K threads gains only where its kernel's share of a step,
divided among the threads, saves more than that.

    python benchmarks/thread_handoff.py [--threads 2] [--runs 2000]
"""

from __future__ import annotations

import argparse
import os
import time

import numba
import numpy as np

from machining_envs.core.compiled.blocks import LaneBlocks


@numba.njit(nogil=True)
def _kernel(x, work):
    for _ in range(work):
        for i in range(x.shape[0]):
            x[i] = x[i] * 0.999 + 1.0


def per_run_us(blocks: LaneBlocks, x: np.ndarray, work: int, runs: int) -> float:
    """Microseconds per ``blocks.run`` of the kernel, best of three windows."""
    blocks.run(_kernel, (x,), (0,), work)
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(runs):
            blocks.run(_kernel, (x,), (0,), work)
        best = min(best, (time.perf_counter() - t0) / runs)
    return best * 1e6


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--threads", type=int, default=max(2, len(os.sched_getaffinity(0))))
    ap.add_argument("--runs", type=int, default=2000)
    args = ap.parse_args(argv)
    x = np.zeros(1024)
    one, many = LaneBlocks(1024, 1), LaneBlocks(1024, args.threads)
    k = len(many.edges)
    print(f"LaneBlocks.run over 1024 lanes: one thread against {k} (µs per run)")
    print(f"{'work':>6s} {'1 thread':>10s} {f'{k} threads':>11s} {'speed-up':>9s} {'handoff':>9s}")
    try:
        for work in (0, 20, 100, 400):
            t1 = per_run_us(one, x, work, args.runs)
            tk = per_run_us(many, x, work, args.runs)
            print(f"{work:6d} {t1:10.1f} {tk:11.1f} {t1 / tk:8.2f}x {tk - t1 / k:9.1f}")
    finally:
        many.close()


if __name__ == "__main__":
    main()
