"""Stepping a vector env's lanes on several threads: one compiled kernel, run on blocks of
lanes at once.

A process's kernel steps lanes ``0 .. N-1`` of arrays whose rows (or columns) are the lanes,
and each lane's arithmetic reads and writes its own rows only. So the kernel run on views of
lanes ``lo .. hi-1`` steps those lanes exactly as the run over all of them does, and blocks
of lanes can run at the same time on threads: the kernels are compiled with
``nogil=True``, so they run in parallel while Python waits. The numbers of every lane are
the same, to the last bit, whatever the number of threads.

:class:`LaneBlocks` splits the lanes into contiguous blocks (one per thread, none smaller
than ``min_block`` lanes, ``MIN_BLOCK`` by default) and runs a kernel over them: the calling
thread takes the first block, a pool of worker threads the others. Each argument of the
kernel is declared as one of:

- ``0`` or ``1``: an array whose axis 0 (or 1) is the lanes: each block gets its view;
- ``None``: shared by all lanes (constants, tables, integers), passed as it is;
- ``SCRATCH``: scratch space the kernel reuses lane after lane: each block gets its own
  array of the same shape (the first block the array itself).

Resets run on the calling thread, and none of them calls BLAS: OpenBLAS's threads spin for
about 0.1 ms after a call they take part in (scipy's ``expm`` of a 4x4 block was one, through
LAPACK's threaded solve), and a vector env resets some lanes at almost every step, so they
would keep the kernel's cores busy (a two-thread ContouringFeed-v0 once ran no faster than
one). The discretisations the resets make are compiled instead.

A compiled kernel (numba) with no other trailing argument than one integer runs on
**workers that wait in compiled code**: each worker thread polls a flag of its own, without
the GIL, and calls the kernel on its block itself when the flag moves, so handing it a
block costs about a microsecond (the calling thread sets every worker's flag in one
compiled call, and waits for them all in another). A pool's thread sleeps between blocks,
and waking it took 90-100 µs on a virtual machine (``benchmarks/thread_handoff.py``), as
long as a whole kernel of a thousand lanes. A worker polls for a few milliseconds after
each block (long enough for the next step of an env stepped in a loop to find it awake),
then sleeps until the next block; while an env is stepped without pause, its workers keep
their cores busy.
Anything else (a Python kernel, other trailing arguments) runs on the pool.

This module imports numpy, numba, ``core.compiled.packed`` and the standard library only.
"""

from __future__ import annotations

import os
import threading
import time
import weakref
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from numba import types
from numba.core import cgutils
from numba.core.registry import CPUDispatcher
from numba.extending import intrinsic

from machining_envs.core.checks import is_integer
from machining_envs.core.compiled.packed import pack

__all__ = [
    "MAX_THREADS",
    "MIN_BLOCK",
    "SCRATCH",
    "LaneBlocks",
    "check_num_threads",
    "serve_one_table",
    "serve_one_table_with_tail",
]

#: Fewest lanes a thread steps, by default: a block must carry more work than handing it
#: to a thread costs. A process whose kernel costs more a lane may allow smaller blocks
#: (``LaneBlocks``'s ``min_block``; the vector envs' ``min_block``).
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
    if not is_integer(num_threads):
        raise TypeError(
            f"num_threads must be an integer in [1, {MAX_THREADS}], got {num_threads!r}"
        )
    if not 1 <= num_threads <= MAX_THREADS:
        raise ValueError(f"num_threads must be an integer in [1, {MAX_THREADS}], got {num_threads}")
    return int(num_threads)


def block_edges(n: int, num_threads: int, min_block: int = MIN_BLOCK) -> list[tuple[int, int]]:
    """Contiguous blocks ``(lo, hi)`` covering lanes ``0 .. n-1``: at most ``num_threads``,
    as many as hold ``min_block`` lanes each (a multiple of ``ALIGN``; one block if ``n`` is
    too small for two), inner edges on multiples of ``ALIGN``, sizes as even as that
    allows."""
    if not (isinstance(min_block, int) and min_block >= ALIGN and min_block % ALIGN == 0):
        raise ValueError(f"min_block must be a positive multiple of {ALIGN}, got {min_block!r}")
    k = max(1, min(num_threads, n // min_block))
    cuts = [0]
    for i in range(1, k):
        cuts.append(int(round(n * i / k / ALIGN)) * ALIGN)
    cuts.append(n)
    return [(lo, hi) for lo, hi in zip(cuts[:-1], cuts[1:], strict=True) if hi > lo]


# ---- workers that wait in compiled code --------------------------------------------------


def _item_pointer(context, builder, aryty, ary_value, index):
    ary = context.make_array(aryty)(context, builder, ary_value)
    return cgutils.get_item_pointer(context, builder, aryty, ary, [index])


@intrinsic
def _load(typingctx, ctl, i):
    """``ctl[i]`` of an int64 array, read atomically (sequentially consistent)."""
    if not (isinstance(ctl, types.Array) and ctl.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        ptr = _item_pointer(context, builder, signature.args[0], args[0], args[1])
        return builder.load_atomic(ptr, "seq_cst", 8)

    return types.int64(ctl, types.intp), codegen


@intrinsic
def _store(typingctx, ctl, i, value):
    """``ctl[i] = value`` of an int64 array, written atomically (sequentially consistent)."""
    if not (isinstance(ctl, types.Array) and ctl.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        ptr = _item_pointer(context, builder, signature.args[0], args[0], args[1])
        value = context.cast(builder, args[2], signature.args[2], types.int64)
        builder.store_atomic(value, ptr, "seq_cst", 8)
        return context.get_dummy_value()

    return types.void(ctl, types.intp, types.int64), codegen


#: Slots of a worker's row of flags: the number of the block it is asked for (-1: stop),
#: the last it finished, whether it is polling (1) or asleep (0), the kernel's integer.
_GO, _DONE, _AWAKE, _TAIL = 0, 1, 2, 3
#: Polls of an idle worker before it sleeps (a few milliseconds).
_POLLS = 2_000_000


@numba.njit(nogil=True, cache=True)
def _poll(ctl, i, value, polls):
    """Poll ``ctl[i]`` until it equals ``value`` (True) or ``polls`` reads have not (False)."""
    for _ in range(polls):
        if _load(ctl, i) == value:
            return True
    return False


@numba.njit(cache=True)
def _set(ctl, i, value):
    """``ctl[i] = value``, atomically, from Python."""
    _store(ctl, i, value)


@numba.njit(cache=True)
def _get(ctl, i):
    """``ctl[i]``, atomically, from Python."""
    return _load(ctl, i)


@numba.njit(inline="always")
def _call(kernel, args, ctl):
    kernel(*args)


@numba.njit(inline="always")
def _call_with_tail(kernel, args, ctl):
    kernel(*args, _load(ctl, _TAIL))


@numba.njit(nogil=True)
def _serve(call, kernel, ctl, args, polls):
    """:func:`serve_loop`, compiled for each kernel it is given (not cacheable: a function
    passed as an argument), on first use in a process."""
    return serve_loop(call, kernel, ctl, args, polls)


@numba.njit(inline="always")
def serve_one_table(kernel, ctl, table, polls):
    """:func:`serve_loop` of a trampoline (``core.compiled.packed``) on its block's table.

    A process module defines its workers' loop with it, compiled with the module and cached
    on disk, so that the first step on several threads need not compile it::

        @numba.njit(cache=True, nogil=True)
        def _serve_step(ctl, table, polls):
            return serve_one_table(_step_packed, ctl, table, polls)

    and gives it to :meth:`LaneBlocks.run` as ``serve``."""
    return serve_loop(_call, kernel, ctl, (table,), polls)


@numba.njit(inline="always")
def serve_one_table_with_tail(kernel, ctl, table, polls):
    """:func:`serve_one_table` of a trampoline that takes an integer after its table
    (``ctl[_TAIL]``, as :meth:`LaneBlocks.run` passes it)."""
    return serve_loop(_call_with_tail, kernel, ctl, (table,), polls)


@numba.njit(inline="always")
def serve_loop(call, kernel, ctl, args, polls):
    """``call(kernel, args, ctl)`` (:func:`_call`: ``kernel(*args)``; :func:`_call_with_tail`:
    with ``ctl[_TAIL]`` after them) each time ``ctl[_GO]`` moves, then ``ctl[_DONE]`` set to
    it. Returns ``ctl[_GO]`` when it is negative (stop), or the last block done once
    ``polls`` polls found nothing and it has marked itself asleep (the caller then sleeps
    until woken)."""
    seen = _load(ctl, _DONE)
    idle = 0
    while True:
        go = _load(ctl, _GO)
        if go < 0:
            return go
        if go != seen:
            call(kernel, args, ctl)
            seen = go
            _store(ctl, _DONE, go)
            idle = 0
        elif idle < polls:
            idle += 1
        else:
            _store(ctl, _AWAKE, 0)
            if _load(ctl, _GO) == seen:  # read after the mark: a block asked for since is seen
                return seen
            _store(ctl, _AWAKE, 1)


@numba.njit(cache=True)
def _ask_all(ctls, number, tail, asleep):
    """Ask every worker (row ``w`` of ``ctls``) for block ``number`` with the integer
    ``tail``, in one compiled call: whether each is asleep (or about to be), and must be
    woken, into ``asleep[w]``; whether any is."""
    woken = False
    for w in range(ctls.shape[0]):
        row = ctls[w]
        _store(row, _TAIL, tail)
        _store(row, _GO, number)
        asleep[w] = _load(row, _AWAKE) == 0
        woken = woken or asleep[w]
    return woken


@numba.njit(nogil=True, cache=True)
def _poll_all(ctls, number, polls):
    """Poll every worker's ``_DONE`` (row ``w`` of ``ctls``) until it is ``number``: -1
    once all are, else the first worker that ``polls`` reads found not done."""
    for w in range(ctls.shape[0]):
        if not _poll(ctls[w], _DONE, number, polls):
            return w
    return -1


def _control_rows(n: int) -> np.ndarray:
    """Zeros of ``n`` rows of eight int64 values, each row a 64-byte cache line of its own
    (the workers' flags, :class:`_Worker`), so that no two workers' flags share a line."""
    raw = np.zeros(8 * n + 8, dtype=np.int64)
    skip = (-raw.ctypes.data % 64) // 8
    return raw[skip : skip + 8 * n].reshape(n, 8)


class _Worker:
    """A thread that serves one block of lanes from compiled code (module docstring), with
    its flags in ``ctl`` (eight int64 values, a row of :func:`_control_rows`)."""

    def __init__(self, kernel, args: tuple, with_tail: bool, serve, ctl: np.ndarray) -> None:
        self.ctl = ctl
        self.ctl[_AWAKE] = 1
        self.wake = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(
            target=self._loop,
            args=(kernel, args, with_tail, serve),
            daemon=True,
            name="machining-envs-lanes",
        )
        self.thread.start()

    def _loop(self, kernel, args: tuple, with_tail: bool, serve) -> None:
        ctl = self.ctl
        call = _call_with_tail if with_tail else _call
        while True:
            try:
                if serve is not None:  # a process's own loop for its trampoline, cached
                    status = serve(ctl, args[0], _POLLS)
                else:
                    status = _serve(call, kernel, ctl, args, _POLLS)
                if status < 0:
                    return
            except BaseException as exc:  # the kernel's (or its compiler's): the caller's
                self.error = exc
                _set(ctl, _AWAKE, 0)
                _set(ctl, _DONE, _get(ctl, _GO))
            self.wake.wait()
            self.wake.clear()
            if _get(ctl, _GO) < 0:
                return
            _set(ctl, _AWAKE, 1)

    def stop(self) -> None:
        _set(self.ctl, _GO, -1)
        self.wake.set()
        self.thread.join()


def _stop_all(workers: list, pid: int) -> None:
    """Stop ``workers``, threads of process ``pid`` (a forked copy has none of them)."""
    if os.getpid() == pid:
        for worker in workers:
            worker.stop()


class LaneBlocks:
    """The blocks of ``n`` lanes for ``num_threads`` threads, none smaller than ``min_block``
    lanes (:func:`block_edges`), and the threads that step them (see the module docstring)."""

    def __init__(self, n: int, num_threads: int = 1, min_block: int = MIN_BLOCK) -> None:
        self.n = int(n)
        self.num_threads = check_num_threads(num_threads)
        self.edges = block_edges(self.n, self.num_threads, min_block)
        #: One block: the kernel runs over all lanes on the calling thread (a core calls it
        #: itself then, sparing :meth:`run`'s call, 0.7 µs of a single env's step).
        self.one = len(self.edges) == 1
        self._pool: ThreadPoolExecutor | None = None
        self._pool_pid = 0
        # The last argument tuple seen (by identity) and its blocks' arguments.
        self._source: tuple | None = None
        self._blocks: list[tuple] = []
        # The blocks' arguments packed into tables (core.compiled.packed), for the blocks they were
        # packed from (by identity); None where a block's arrays cannot be packed.
        self._tables: list[tuple] | None = None
        self._tables_of: list[tuple] | None = None
        # The compiled workers, what they serve ((kernel, blocks, with tail, loop), by
        # identity), the process they belong to and the number of the last block asked for.
        self._workers: list[_Worker] = []
        self._served: tuple | None = None
        self._workers_pid = 0
        self._number = 0
        self._finalizer: weakref.finalize | None = None
        # The workers' flags (a row each) and whether each was asleep when last asked.
        self._ctls: np.ndarray | None = None
        self._asleep: np.ndarray | None = None

    def __getstate__(self) -> dict:
        # Threads and views do not pickle: made anew when next needed.
        state = dict(self.__dict__)
        state.update(
            _pool=None,
            _pool_pid=0,
            _source=None,
            _blocks=[],
            _tables=None,
            _tables_of=None,
            _workers=[],
            _served=None,
            _workers_pid=0,
            _number=0,
            _finalizer=None,
            _ctls=None,
            _asleep=None,
        )
        return state

    def _block_args(self, args: tuple, axes: tuple) -> list[tuple]:
        source = self._source
        if args is not source and not (
            source is not None
            and len(args) == len(source)
            and all(a is b for a, b in zip(args, source, strict=True))
        ):  # new arguments (the same objects in a new tuple keep their blocks)
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

    def _block_tables(self, blocks: list[tuple]) -> list[tuple] | None:
        """Each block's arguments packed into one table (``core.compiled.packed``), as a one-argument
        tuple; None where some array of a block does not pack (``core.compiled.packed.pack``: a
        view across the lanes' axis 1 packs only if it is 2-d float64)."""
        if self._tables_of is not blocks:
            try:
                self._tables = [(pack(b),) for b in blocks]
            except TypeError:
                self._tables = None
            self._tables_of = blocks  # the blocks keep the tables' arrays alive
        return self._tables

    def run(self, kernel, args: tuple, axes: tuple, *tail, packed=None, serve=None) -> None:
        """``kernel(*args, *tail)`` over all lanes: on the blocks' views of ``args`` (one
        axis code per argument in ``axes``), at the same time on the threads, when there is
        more than one block; the kernel returns nothing. A kernel's error is raised once every
        block has finished.

        ``packed``, the kernel's trampoline (``core.compiled.packed``), runs instead on each block's
        table where there are several blocks and every block's arrays pack: the same
        numbers, and for some kernels faster code (the trampoline's arrays have strides the
        compiler can see). On one block the kernel runs as it is: a caller stepping one
        block calls its trampoline itself, sparing this call.
        ``serve``, the trampoline's worker loop (:func:`serve_one_table`, or
        :func:`serve_one_table_with_tail` for a trampoline taking an integer after its
        table; cached with its module), spares the workers compiling :func:`_serve` for
        it."""
        if self.one:
            kernel(*args, *tail)
            return
        blocks = self._block_args(args, axes)
        loop = None
        if packed is not None:
            tables = self._block_tables(blocks)
            if tables is not None:
                kernel, blocks = packed, tables
                loop = serve
        if isinstance(kernel, CPUDispatcher) and (
            not tail or (len(tail) == 1 and isinstance(tail[0], (int, np.integer)))
        ):
            self._run_compiled(kernel, blocks, tail, loop)
            return
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

    def _run_compiled(self, kernel, blocks: list[tuple], tail: tuple, serve=None) -> None:
        """:meth:`run` of a compiled kernel on the compiled workers (module docstring), with
        the workers' loop ``serve`` where given."""
        with_tail = bool(tail)
        old = self._served
        if (
            old is None
            or self._workers_pid != os.getpid()
            or old[0] is not kernel
            or old[1] is not blocks
            or old[2] != with_tail
            or old[3] is not serve
        ):
            self._stop_workers()
            # Every worker's flags in one array, asked and waited for in one call each.
            self._ctls = _control_rows(len(blocks) - 1)
            self._asleep = np.zeros(len(blocks) - 1, dtype=np.bool_)
            self._workers = [
                _Worker(kernel, b, with_tail, serve, self._ctls[i])
                for i, b in enumerate(blocks[1:])
            ]
            self._served = (kernel, blocks, with_tail, serve)
            self._workers_pid = os.getpid()
            # Stopped with the blocks, if never closed: they hold the lanes' arrays.
            self._finalizer = weakref.finalize(self, _stop_all, self._workers, os.getpid())
        self._number += 1
        number = self._number
        value = int(tail[0]) if tail else 0
        if _ask_all(self._ctls, number, value, self._asleep):
            for i in np.flatnonzero(self._asleep).tolist():
                self._workers[i].wake.set()
        try:
            kernel(*blocks[0], *tail)
        finally:
            self._wait_all(number)  # every block done before anything else touches the lanes
            error = next((w.error for w in self._workers if w.error is not None), None)
            if error is not None:
                for worker in self._workers:  # raised once (the calling thread's first)
                    worker.error = None
        if error is not None:
            raise error

    def _wait_all(self, number: int) -> None:
        """Wait until every worker has done block ``number``; a worker whose thread has
        stopped is an error."""
        while (w := _poll_all(self._ctls, number, _POLLS)) >= 0:
            if not self._workers[w].thread.is_alive():
                raise RuntimeError("a worker thread of the lane blocks has stopped")
            time.sleep(0)

    def _stop_workers(self) -> None:
        finalizer = getattr(self, "_finalizer", None)
        if finalizer is not None:
            finalizer.detach()
            self._finalizer = None
        if self._workers:  # (none, say, when an env left open is collected at exit, after
            _stop_all(self._workers, self._workers_pid)  # the module's names are gone)
        self._workers, self._served = [], None

    def close(self) -> None:
        """Stop the worker threads (made again if :meth:`run` needs them)."""
        if self._pool is not None and self._pool_pid == os.getpid():
            self._pool.shutdown(wait=True)
        self._pool = None
        self._stop_workers()
