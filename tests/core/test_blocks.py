"""Blocks of lanes stepped on threads (``machining_envs.core.compiled.blocks``)."""

import gc
import pickle
import threading

import numba
import numpy as np
import pytest

from machining_envs.core.compiled.blocks import (
    ALIGN,
    MAX_THREADS,
    MIN_BLOCK,
    SCRATCH,
    LaneBlocks,
    block_edges,
    check_num_threads,
    serve_one_table,
)
from machining_envs.core.compiled.packed import b1_1, f8_1, f8_2, i8_1


@pytest.mark.parametrize(
    "n", [1, 5, 63, 64, 127, 128, 191, 255, 256, 300, 1000, 1024, 8192, 10_001]
)
@pytest.mark.parametrize("threads", [1, 2, 3, 4, 16, 256])
@pytest.mark.parametrize("min_block", [MIN_BLOCK, ALIGN])
def test_blocks_cover_the_lanes_in_order(n, threads, min_block):
    edges = block_edges(n, threads, min_block)
    assert edges[0][0] == 0 and edges[-1][1] == n
    for (_, hi), (lo, _) in zip(edges[:-1], edges[1:], strict=True):
        assert hi == lo and lo % ALIGN == 0
    assert 1 <= len(edges) <= threads
    # as many blocks as the lanes allow (a small batch stays on one thread), none much
    # smaller than min_block (an edge moves by at most ALIGN / 2 to fall on a multiple)
    assert len(edges) == max(1, min(threads, n // min_block))
    if len(edges) > 1:
        assert all(hi - lo >= min_block - ALIGN for lo, hi in edges)
        assert all(hi - lo >= ALIGN // 2 for lo, hi in edges)


@pytest.mark.parametrize("bad", [0, 32, 100, -64, 64.0, None])
def test_a_minimum_block_off_the_alignment_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match="min_block must be a positive multiple of 64"):
        block_edges(1024, 4, bad)


def test_the_heavier_kernels_step_smaller_blocks():
    """Turning-v0 and ContouringFeed-v0 (a lane's step 0.5 and 1.3 µs compiled) hand out
    blocks of 64 lanes; the lighter kernels keep 128."""
    import gymnasium as gym

    import machining_envs  # noqa: F401  (registers the ids)

    for env_id, lanes in (
        ("Turning-v0", 64),
        ("ContouringFeed-v0", 64),
        ("EndMilling-v0", 128),
        ("MicroDrilling-v0", 128),
        ("Contouring-v0", 128),
    ):
        venv = gym.make_vec(f"machining_envs/{env_id}", num_envs=128, num_threads=4)
        try:
            assert venv.unwrapped.min_block == lanes
            assert len(venv.unwrapped.lane_blocks.edges) == 128 // lanes, env_id
        finally:
            venv.close()


def test_bad_thread_counts_are_refused_naming_the_parameter():
    for bad in (0, -1, MAX_THREADS + 1):
        with pytest.raises(
            ValueError, match=rf"num_threads must be an integer in \[1, {MAX_THREADS}\]"
        ):
            check_num_threads(bad)
    for bad in (2.0, "2", None, True):
        with pytest.raises(TypeError, match="num_threads"):
            check_num_threads(bad)
    assert check_num_threads(np.int64(3)) == 3


def _fill(ids, cols, rows, scratch, shared, value):
    """A kernel over lanes: lane k writes its own row and column, using ``scratch``."""
    for k in range(ids.shape[0]):
        scratch[:] = ids[k] * shared[0]
        rows[k] = scratch.sum() + value
        cols[:, k] = ids[k]


def test_a_kernel_on_blocks_gives_what_it_gives_on_all_lanes():
    n = 700
    ids = np.arange(n, dtype=float)
    shared = np.array([2.0])
    out = []
    for threads in (1, 2, 3):
        rows, cols, scratch = np.zeros(n), np.zeros((2, n)), np.zeros(4)
        blocks = LaneBlocks(n, threads)
        args = (ids, cols, rows, scratch, shared)
        blocks.run(_fill, args, (0, 1, 0, SCRATCH, None), 0.5)
        blocks.close()
        out.append((rows, cols))
    for rows, cols in out[1:]:
        np.testing.assert_array_equal(rows, out[0][0])
        np.testing.assert_array_equal(cols, out[0][1])
    np.testing.assert_array_equal(out[0][0], 8.0 * ids + 0.5)


def test_the_blocks_run_at_once_on_several_threads():
    n = 1024
    blocks = LaneBlocks(n, 4)
    assert len(blocks.edges) == 4
    seen = []
    barrier = threading.Barrier(4, timeout=10)  # breaks unless the four blocks run together

    def kernel(lanes):
        barrier.wait()
        seen.append((threading.get_ident(), lanes[0], lanes[-1]))

    blocks.run(kernel, (np.arange(n),), (0,))
    blocks.close()
    assert len({t for t, _, _ in seen}) == 4
    assert sorted((lo, hi) for _, lo, hi in seen) == [(lo, hi - 1) for lo, hi in blocks.edges]


def test_an_error_in_a_block_is_raised_after_every_block_has_finished():
    n = 512
    done = np.zeros(n, dtype=bool)

    def kernel(lanes, flags):
        flags[:] = True
        if lanes[0] == 0:
            raise RuntimeError("block 0 failed")

    blocks = LaneBlocks(n, 4)
    with pytest.raises(RuntimeError, match="block 0 failed"):
        blocks.run(kernel, (np.arange(n), done), (0, 0))
    assert done.all()

    def late(lanes, flags):
        if lanes[0] != 0:
            raise ValueError(f"block at {lanes[0]} failed")

    with pytest.raises(ValueError, match="failed"):
        blocks.run(late, (np.arange(n), done), (0, 0))
    blocks.close()


def test_axis_codes_are_checked_against_the_arguments():
    blocks = LaneBlocks(512, 2)
    with pytest.raises(ValueError, match="2 kernel arguments but 1 axis codes"):
        blocks.run(_fill, (np.zeros(512), np.zeros(512)), (0,))
    with pytest.raises(ValueError, match="axis code"):
        blocks.run(lambda a: None, (np.zeros(512),), (2,))
    with pytest.raises(ValueError, match="argument 0 .* lanes on axis 0"):
        blocks.run(lambda a: None, (np.zeros(100),), (0,))
    with pytest.raises(ValueError, match="argument 1 .* lanes on axis 1"):
        blocks.run(lambda a, b: None, (np.zeros(512), np.zeros((512, 3))), (0, 1))
    blocks.close()


def test_blocks_pickle_without_their_threads():
    blocks = LaneBlocks(1024, 2)
    blocks.run(lambda a: None, (np.zeros(1024),), (0,))
    copy = pickle.loads(pickle.dumps(blocks))
    assert copy.edges == blocks.edges and copy.num_threads == 2
    hits = np.zeros(1024)

    def kernel(a):
        a += 1.0

    copy.run(kernel, (hits,), (0,))
    np.testing.assert_array_equal(hits, 1.0)
    copy.close()
    blocks.close()


@numba.njit(nogil=True)
def _mark(lanes, flags, code):
    for i in range(lanes.shape[0]):
        flags[i] = True
    if lanes[0] != 0 and code == 7:
        raise ValueError("a worker's block failed")


def test_a_compiled_kernel_runs_on_workers_that_raise_its_errors():
    """A compiled kernel with an integer after its arrays runs on workers that wait in
    compiled code; an error in a worker's block is raised once every block has finished,
    and the workers serve the next run."""
    n = 512
    lanes, done = np.arange(n), np.zeros(n, dtype=np.bool_)
    blocks = LaneBlocks(n, 4)
    blocks.run(_mark, (lanes, done), (0, 0), 1)
    assert done.all() and len(blocks._workers) == 3
    done[:] = False
    with pytest.raises(ValueError, match="worker's block failed"):
        blocks.run(_mark, (lanes, done), (0, 0), 7)
    assert done.all()
    done[:] = False
    blocks.run(_mark, (lanes, done), (0, 0), 1)
    assert done.all()
    threads = [w.thread for w in blocks._workers]
    blocks.close()
    assert blocks._workers == [] and not any(t.is_alive() for t in threads)
    blocks.run(_mark, (lanes, done), (0, 0), 1)  # made again when needed
    assert len(blocks._workers) == 3
    blocks.close()


def test_workers_asleep_are_woken_for_the_next_block():
    """Workers idle past their polls sleep; the next run wakes each of them (the flags
    all set in one call say which sleep), and every block is stepped. Their flags lie a
    cache line apart."""
    import time

    from machining_envs.core.compiled.blocks import _AWAKE

    n = 512
    lanes, done = np.arange(n), np.zeros(n, dtype=np.bool_)
    blocks = LaneBlocks(n, 4)
    blocks.run(_mark, (lanes, done), (0, 0), 1)
    ctls = blocks._ctls
    assert ctls.shape == (3, 8) and ctls.strides == (64, 8) and ctls.ctypes.data % 64 == 0
    deadline = time.monotonic() + 30.0
    while ctls[:, _AWAKE].any() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not ctls[:, _AWAKE].any()  # all asleep
    done[:] = False
    runner = threading.Thread(target=blocks.run, args=(_mark, (lanes, done), (0, 0), 1))
    runner.start()
    runner.join(timeout=30.0)
    assert not runner.is_alive() and done.all()
    assert blocks._asleep.all()  # each was found asleep, and woken
    blocks.close()


def test_workers_stop_with_their_blocks():
    """Workers hold the lanes' arrays: blocks never closed stop theirs when collected."""
    blocks = LaneBlocks(512, 2)
    blocks.run(_mark, (np.arange(512), np.zeros(512, dtype=np.bool_)), (0, 0), 1)
    threads = [w.thread for w in blocks._workers]
    del blocks
    gc.collect()
    for t in threads:
        t.join(timeout=10)
    assert threads and not any(t.is_alive() for t in threads)


@numba.njit(nogil=True)
def _scale(rows, cols, out, factor):
    """rows: lanes on axis 0; cols: lanes on axis 1; out: lanes on axis 0."""
    for i in range(rows.shape[0]):
        out[i] = rows[i, 0] * factor + cols[0, i]


@numba.njit(nogil=True)
def _scale_packed(t, factor):
    _scale(f8_2(t, 0), f8_2(t, 1), f8_1(t, 2), factor)


def test_a_trampoline_runs_on_each_blocks_table_where_the_blocks_pack():
    """With ``packed``, every block runs the trampoline on its own table (its views'
    addresses); where a block's view does not pack (here an integer array with the lanes on
    axis 1: only a float64 one packs, by its row stride), the kernel runs on the views as
    without it. The numbers are the same either way."""
    n = 512
    rows = np.arange(2.0 * n).reshape(n, 2)
    cols = np.arange(3 * n).reshape(3, n)
    want = rows[:, 0] * 3 + cols[0]
    # packable: lanes on axis 0 only (a constant row shared by the blocks)
    shared = np.full((1, n), 5.0)
    out = np.zeros(n)
    blocks = LaneBlocks(n, 2)
    blocks.run(_scale, (rows, shared, out), (0, None, 0), 3, packed=_scale_packed)
    np.testing.assert_array_equal(out, rows[:, 0] * 3 + 5.0)
    tables = blocks._tables
    assert tables is not None and len(tables) == 2
    assert blocks._served[0] is _scale_packed  # the workers run the trampoline
    lo, hi = blocks.edges[1]
    assert tables[1][0][1] == rows[lo:hi].ctypes.data  # the second block's own rows
    blocks.run(_scale, (rows, shared, out), (0, None, 0), 3, packed=_scale_packed)
    assert blocks._tables is tables  # packed once for the same arguments
    blocks.close()
    # not packable: an integer view across axis 1 -> the kernel on the views
    out[:] = 0.0
    blocks = LaneBlocks(n, 2)
    blocks.run(_scale, (rows, cols, out), (0, 1, 0), 3, packed=_scale_packed)
    np.testing.assert_array_equal(out, want)
    assert blocks._tables is None and blocks._served[0] is _scale
    state = pickle.loads(pickle.dumps(blocks))
    assert state._tables is None and state._tables_of is None
    blocks.close()


@numba.njit(nogil=True)
def _mark_packed(t):
    lanes, flags = i8_1(t, 0), b1_1(t, 1)
    _mark(lanes, flags, 7 if lanes[0] == 448 else 1)


@numba.njit(nogil=True)
def _serve_mark(ctl, table, polls):
    return serve_one_table(_mark_packed, ctl, table, polls)


def test_workers_run_a_trampolines_own_loop_and_raise_its_errors():
    """Given ``serve`` (a module's loop for its trampoline, :func:`serve_one_table`), the
    workers run it on their blocks' tables; a kernel's error in a worker is still raised
    once every block has finished. With a trailing argument, the generic loop serves."""
    n = 512
    lanes, done = np.arange(n), np.zeros(n, dtype=np.bool_)
    blocks = LaneBlocks(n, 2)
    blocks.run(_mark, (lanes, done), (0, 0), packed=_mark_packed, serve=_serve_mark)
    assert done.all() and blocks._served[0] is _mark_packed and blocks._served[3] is _serve_mark
    done[:] = False
    shifted = lanes + 192  # the second block now starts at lane 448: its kernel raises
    with pytest.raises(ValueError, match="worker's block failed"):
        blocks.run(_mark, (shifted, done), (0, 0), packed=_mark_packed, serve=_serve_mark)
    assert done.all()
    blocks.close()
