"""Stepping a vector env's lanes on several threads: one compiled kernel, run on blocks of
lanes at once.

A process's kernel steps lanes ``0 .. N-1`` of arrays whose rows (or columns) are the lanes,
and each lane's arithmetic reads and writes its own rows only. So the kernel run on views of
lanes ``lo .. hi-1`` steps those lanes exactly as the run over all of them does, and blocks
of lanes can run at the same time on threads: the kernels are compiled with
``nogil=True``, so they run in parallel while Python waits. The numbers of every lane are
the same, to the last bit, whatever the number of threads.

:class:`LaneBlocks` splits the lanes into contiguous blocks (one per thread, none smaller
than ``MIN_BLOCK`` lanes) and runs a kernel over them: the calling thread takes the first
block, a pool of worker threads the others. Each argument of the kernel is declared as one
of:

- ``0`` or ``1``: an array whose axis 0 (or 1) is the lanes: each block gets its view;
- ``None``: shared by all lanes (constants, tables, integers), passed as it is;
- ``SCRATCH``: scratch space the kernel reuses lane after lane: each block gets its own
  array of the same shape (the first block the array itself).

Resets run on the calling thread, and some of them (the exact discretisations of the
turning and contouring plants, through scipy) call OpenBLAS, whose threads spin for about
0.1 ms after every call, even a 4x4 product. A single env resets now and then, but a vector
env of many lanes resets some at almost every step, and its BLAS threads then kept the
other cores busy: a two-thread ContouringFeed-v0 ran no faster than one. So the vector env
of such a process runs its resets in :func:`one_blas_thread`, with BLAS on one thread: the
numbers are the same, the cores stay free.

This module imports numpy, threadpoolctl and the standard library only.
"""

from __future__ import annotations

import os
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

__all__ = [
    "MAX_THREADS",
    "MIN_BLOCK",
    "SCRATCH",
    "LaneBlocks",
    "check_num_threads",
    "one_blas_thread",
]

#: Fewest lanes a thread steps: below this, handing a block to a thread (tens of µs)
#: costs more than the block's own step saves.
MIN_BLOCK = 128
#: Block edges fall on multiples of this (kernels that step a few lanes at a time keep
#: their groups).
ALIGN = 64
#: Largest ``num_threads`` accepted.
MAX_THREADS = 256
#: Axis code of an argument that is per-block scratch space.
SCRATCH = "scratch"


def check_num_threads(num_threads) -> int:
    """``num_threads`` as an int in ``[1, MAX_THREADS]`` (``TypeError`` / ``ValueError``
    naming it otherwise)."""
    if isinstance(num_threads, bool) or not isinstance(num_threads, (int, np.integer)):
        raise TypeError(
            f"num_threads must be an integer in [1, {MAX_THREADS}], got {num_threads!r}"
        )
    if not 1 <= num_threads <= MAX_THREADS:
        raise ValueError(f"num_threads must be an integer in [1, {MAX_THREADS}], got {num_threads}")
    return int(num_threads)


def block_edges(n: int, num_threads: int) -> list[tuple[int, int]]:
    """Contiguous blocks ``(lo, hi)`` covering lanes ``0 .. n-1``: at most ``num_threads``,
    each of at least ``MIN_BLOCK`` lanes (one block if ``n`` is too small for two), inner
    edges on multiples of ``ALIGN``, sizes as even as that allows."""
    k = max(1, min(num_threads, n // MIN_BLOCK))
    cuts = [0]
    for i in range(1, k):
        cuts.append(int(round(n * i / k / ALIGN)) * ALIGN)
    cuts.append(n)
    return [(lo, hi) for lo, hi in zip(cuts[:-1], cuts[1:], strict=True) if hi > lo]


class LaneBlocks:
    """The blocks of ``n`` lanes for ``num_threads`` threads, and the threads that step them
    (see the module docstring)."""

    def __init__(self, n: int, num_threads: int = 1) -> None:
        self.n = int(n)
        self.num_threads = check_num_threads(num_threads)
        self.edges = block_edges(self.n, self.num_threads)
        #: One block: the kernel runs over all lanes on the calling thread (a core calls it
        #: itself then, sparing :meth:`run`'s call, 0.7 µs of a single env's step).
        self.one = len(self.edges) == 1
        self._pool: ThreadPoolExecutor | None = None
        self._pool_pid = 0
        # The last argument tuple seen (by identity) and its blocks' arguments.
        self._source: tuple | None = None
        self._blocks: list[tuple] = []

    def __getstate__(self) -> dict:
        # Threads and views do not pickle: made anew when next needed.
        state = dict(self.__dict__)
        state.update(_pool=None, _pool_pid=0, _source=None, _blocks=[])
        return state

    def _block_args(self, args: tuple, axes: tuple) -> list[tuple]:
        if args is not self._source:
            if len(args) != len(axes):
                raise ValueError(f"{len(args)} kernel arguments but {len(axes)} axis codes")
            for i, (x, axis) in enumerate(zip(args, axes, strict=True)):
                if axis in (0, 1) and not (
                    isinstance(x, np.ndarray) and x.ndim > axis and x.shape[axis] == self.n
                ):
                    raise ValueError(
                        f"argument {i} of the kernel should hold the {self.n} lanes on axis "
                        f"{axis}, got {type(x).__name__} of shape {np.shape(x)}"
                    )
                if axis == SCRATCH and not isinstance(x, np.ndarray):
                    raise ValueError(f"argument {i} of the kernel: scratch must be an array")
            blocks = []
            for b, (lo, hi) in enumerate(self.edges):
                row = []
                for x, axis in zip(args, axes, strict=True):
                    if axis is None:
                        row.append(x)
                    elif axis == SCRATCH:
                        row.append(x if b == 0 else np.empty_like(x))
                    elif axis == 0:
                        row.append(x[lo:hi])
                    elif axis == 1:
                        row.append(x[:, lo:hi])
                    else:
                        raise ValueError(f"axis code must be 0, 1, None or SCRATCH, got {axis!r}")
                blocks.append(tuple(row))
            self._source, self._blocks = args, blocks
        return self._blocks

    def run(self, kernel, args: tuple, axes: tuple, *tail) -> None:
        """``kernel(*args, *tail)`` over all lanes: on the blocks' views of ``args`` (one
        axis code per argument in ``axes``), at the same time on the threads, when there is
        more than one block; the kernel returns nothing. A kernel's error is raised once every
        block has finished."""
        if self.one:
            kernel(*args, *tail)
            return
        blocks = self._block_args(args, axes)
        pool = self._pool
        if pool is None or self._pool_pid != os.getpid():  # none yet, or a forked copy's
            pool = self._pool = ThreadPoolExecutor(
                len(blocks) - 1, thread_name_prefix="machining-envs-lanes"
            )
            self._pool_pid = os.getpid()
        futures = [pool.submit(kernel, *b, *tail) for b in blocks[1:]]
        try:
            kernel(*blocks[0], *tail)
        finally:
            for f in futures:
                f.exception()  # wait for every block before anything else touches the lanes
        for f in futures:
            f.result()

    def close(self) -> None:
        """Stop the worker threads (made again if :meth:`run` needs them)."""
        if self._pool is not None and self._pool_pid == os.getpid():
            self._pool.shutdown(wait=True)
        self._pool = None


_BLAS_LOCK = threading.Lock()
_BLAS_SEEN: list = [0, 0, []]  # pid, len(sys.modules), the BLAS libraries' controllers


def _blas_libraries() -> list:
    """threadpoolctl's controllers of the BLAS libraries loaded, looked up (a few ms) at the
    first use, in a forked copy, and after any import since the last look (a module may
    have brought a BLAS of its own)."""
    with _BLAS_LOCK:
        if _BLAS_SEEN[0] != os.getpid() or _BLAS_SEEN[1] != len(sys.modules):
            from threadpoolctl import ThreadpoolController

            libs = ThreadpoolController().select(user_api="blas").lib_controllers
            _BLAS_SEEN[:] = [os.getpid(), len(sys.modules), libs]
        return _BLAS_SEEN[2]


class _OneBlasThread(threading.local):
    """The context of :func:`one_blas_thread`, per Python thread: the outermost entry sets
    the BLAS libraries to one thread, its exit puts back the counts it found and gives up
    the control of OpenBLAS's pool as ``threadpoolctl.threadpool_limits`` does (while
    another thread holds that control, this thread's settings do nothing: threadpoolctl's
    rule for OpenBLAS's process-wide pool)."""

    def __init__(self) -> None:
        self.depth = 0
        self.saved: list = []

    def __enter__(self) -> None:
        if self.depth == 0:
            self.saved = [(lib, lib.num_threads) for lib in _blas_libraries()]
            for lib, _ in self.saved:
                lib.set_num_threads(1)
        self.depth += 1

    def __exit__(self, *exc) -> None:
        self.depth -= 1
        if self.depth == 0:
            for lib, count in self.saved:
                lib.set_num_threads(count)
            for cls in {type(lib) for lib, _ in self.saved}:
                clear = getattr(cls, "clear_controlling_thread", None)
                if clear is not None:
                    clear()
            self.saved = []


_ONE_BLAS_THREAD = _OneBlasThread()


def one_blas_thread() -> _OneBlasThread:
    """A context in which the BLAS libraries numpy and scipy loaded run on one thread (about
    20 µs to enter and leave, more in a busy step); a nested use keeps it until the
    outermost one leaves. The resets of a vector env whose resets call BLAS run in it (see
    the module docstring)."""
    return _ONE_BLAS_THREAD
