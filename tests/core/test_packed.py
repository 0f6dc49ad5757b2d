"""A kernel's arguments packed into one table (``machining_envs.core.compiled.packed``), and each
process's trampoline giving its kernel's numbers to the last bit."""

import copy
import pickle

import gymnasium as gym
import numba
import numpy as np
import pytest

import machining_envs  # noqa: F401  (registers the ids)
from machining_envs.contouring import feed_lanes as feed_env
from machining_envs.contouring import lanes as contouring_env
from machining_envs.core.compiled.packed import (
    SLOT,
    PackedArgs,
    as_float,
    as_int,
    b1_1,
    b1_2,
    f4_2,
    f8_1,
    f8_2,
    f8_2_rows,
    f8_3,
    i8_1,
    i8_2,
    pack,
)
from machining_envs.core.compiled.schema import unflatten
from machining_envs.drilling import lanes as drilling_env
from machining_envs.milling import lanes as milling_env
from machining_envs.turning import lanes as turning_env


@numba.njit
def _read_back(t):
    """Every reader on a table of the ten kinds, writing through the arrays it makes."""
    a, b, c, d = f8_1(t, 0), f8_2(t, 1), f8_3(t, 2), f4_2(t, 3)
    e, f, g, h = i8_1(t, 4), i8_2(t, 5), b1_1(t, 6), b1_2(t, 7)
    x, n, m = as_float(t, 8), as_int(t, 9), as_float(t, 10)
    a[-1] = x
    b[1, 2] = x + n
    c[1, 2, 3] = m
    d[0, 1] = 2.5
    e[0] = n
    f[1, 0] = 7
    g[1] = True
    h[0, 1] = True
    return a.sum() + b.sum() + c.sum() + d.sum() + e.sum() + f.sum() + g.sum() + h.sum()


def _kinds():
    return (
        np.arange(3.0),
        np.arange(6.0).reshape(2, 3),
        np.zeros((2, 3, 4)),
        np.zeros((2, 2), dtype=np.float32),
        np.arange(4),
        np.zeros((3, 2), dtype=np.int64),
        np.zeros(2, dtype=bool),
        np.zeros((2, 2), dtype=bool),
        0.1,
        -3,
        5,  # an int read as a float, as a direct call would take it
    )


def test_the_readers_give_the_arrays_and_numbers_packed():
    args = _kinds()
    plain = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
    total = _read_back(pack(args))
    # the arrays read back are the packed arrays themselves (writes reach them) ...
    plain[0][-1] = 0.1
    plain[1][1, 2] = 0.1 - 3
    plain[2][1, 2, 3] = 5.0
    plain[3][0, 1] = 2.5
    plain[4][0] = -3
    plain[5][1, 0] = 7
    plain[6][1] = True
    plain[7][0, 1] = True
    for got, want in zip(args[:8], plain[:8], strict=True):
        assert got.dtype == want.dtype and np.array_equal(got, want)
    # ... and the float's bits survive the table
    assert total == sum(float(p.sum()) for p in plain[:8])
    assert pack((0.1,))[1] == np.float64(0.1).view(np.int64)
    assert len(pack(args)) == SLOT * len(args)


@numba.njit
def _rows_of(t):
    a = f8_2_rows(t, 0)
    a[1, 0] = -1.0  # writes reach the array packed
    return a.sum(), a.shape[0], a.shape[1]


def test_a_view_of_some_columns_packs_with_its_row_stride():
    """A 2-d float64 view of some columns of a wider array (a block of lanes on axis 1)
    packs with its row stride and reads back as that view; a C-contiguous array reads
    back the same way; other strides are refused, and the plain reader refuses the view."""
    wide = np.arange(40.0).reshape(4, 10)
    view = wide[:, 3:7]
    total, rows, cols = _rows_of(pack((view,)))
    assert (rows, cols) == (4, 4) and wide[1, 3] == -1.0
    assert total == view.sum() and wide[1, 2] == 12.0 and wide[1, 7] == 17.0
    whole = np.arange(6.0).reshape(2, 3)
    assert _rows_of(pack((whole,)))[1:] == (2, 3) and whole[1, 0] == -1.0
    with pytest.raises(TypeError, match="another kind"):
        _read_f8_2(pack((view,)))
    with pytest.raises(TypeError, match="another kind"):
        _rows_of(pack((np.zeros(3),)))
    with pytest.raises(TypeError, match="not C-contiguous"):
        pack((wide[:, ::2],))  # not contiguous within a row
    with pytest.raises(TypeError, match="not C-contiguous"):
        pack((np.zeros((4, 10), dtype=np.float32)[:, 3:7],))  # float64 only


@numba.njit
def _read_f8_2(t):
    return f8_2(t, 0).sum()


@numba.njit
def _read_int(t):
    return as_int(t, 0)


def test_a_reader_refuses_an_argument_of_another_kind():
    for wrong in (np.zeros(3), np.zeros((2, 2), dtype=np.float32), np.zeros((2, 2), bool), 1.0):
        with pytest.raises(TypeError, match="another kind"):
            _read_f8_2(pack((wrong,)))
    with pytest.raises(TypeError, match="another kind"):
        _read_int(pack((1.5,)))
    assert _read_f8_2(pack((np.ones((2, 2)),))) == 4.0


def test_pack_refuses_what_a_reader_cannot_read_naming_the_argument():
    bad = [
        (np.zeros((4, 4))[:, ::2], "argument 1 is a 2-d float64 array \\(not C-contiguous\\)"),
        (np.zeros(3, dtype=np.int32), "argument 1 is a 1-d int32 array"),
        (np.zeros((1, 1, 1, 1)), "argument 1 is a 4-d float64"),
        (np.zeros(()), "argument 1 is a 0-d"),
        ("x", "argument 1 is a str"),
        (True, "argument 1 is a bool"),
        (None, "argument 1 is a NoneType"),
    ]
    for arg, message in bad:
        with pytest.raises(TypeError, match=message):
            pack((np.zeros(2), arg))


def test_packed_args_pack_again_for_another_tuple_only():
    packed = PackedArgs()
    a = (np.zeros(3), 1.0)
    t1 = packed(a)
    assert packed(a) is t1
    b = (np.zeros(3), 1.0)
    t2 = packed(b)
    assert t2 is not t1 and t2[1] == b[0].ctypes.data
    # a pickle or a copy holds no addresses: it packs the tuple it is given
    for other in (pickle.loads(pickle.dumps(packed)), copy.copy(packed), copy.deepcopy(packed)):
        c = (np.zeros(3), 1.0)
        assert other(c)[1] == c[0].ctypes.data


#: id -> (kernel, trampoline, trailing arguments) of each process.
KERNELS = {
    # (Turning-v0's table also holds the start's arrays and the pending starts, after
    # _step's records; its trampoline's op 0 is the step)
    "Turning-v0": (
        lambda *args: turning_env._step(*unflatten(args, turning_env._TABLE[:2])),
        turning_env._step_packed,
        (0,),
    ),
    "EndMilling-v0": (
        lambda *args: milling_env._step(*unflatten(args, milling_env._TABLE), args[-1]),
        milling_env._step_packed,
        (3,),
    ),
    "MicroDrilling-v0": (drilling_env._step, drilling_env._step_packed, ()),
    "Contouring-v0": (contouring_env._contour_step, contouring_env._contour_step_packed, ()),
    # (ContouringFeed-v0's also holds what a batch's start reads and writes, after
    # _feed_step's)
    "ContouringFeed-v0": (
        lambda *args: feed_env._feed_step(*args[: feed_env._F_START]),
        feed_env._feed_step_packed,
        (),
    ),
}


def _arguments(core) -> tuple:
    """The kernel's arguments: from ``_kernel_args`` where the core builds them there, else
    the tuple it keeps in ``_args``."""
    from machining_envs.core.lanes import CachedKernelArgs

    return core._kernel_args() if isinstance(core, CachedKernelArgs) else core._args


@pytest.mark.parametrize("env_id", sorted(KERNELS))
def test_each_trampoline_steps_as_its_kernel_to_the_last_bit(env_id):
    kernel, trampoline, tail = KERNELS[env_id]
    env = gym.make(f"machining_envs/{env_id}")
    env.reset(seed=3, options={"scenario": "validation"})
    space = env.action_space
    space.seed(3)
    for _ in range(5):
        env.step(space.sample())
    core = env.unwrapped._core
    state = _arguments(core)
    # the lanes' arrays as the env holds them now, twice: one copy stepped by the kernel
    # called directly, the other by the trampoline, for a few steps
    direct = tuple(a.copy() if isinstance(a, np.ndarray) else a for a in state)
    packed = tuple(a.copy() if isinstance(a, np.ndarray) else a for a in state)
    table = pack(packed)
    # both copies draw their noise from the lanes' generators (core.compiled.normals): each starts
    # from the generators' state as it is now
    rngs = core.rngs.generators if hasattr(core, "rngs") else []
    generators = [g for g in rngs if g is not None]
    states = [g.bit_generator.state for g in generators]
    for _ in range(3):
        kernel(*direct, *tail)
    for g, st in zip(generators, states, strict=True):
        g.bit_generator.state = st
    for _ in range(3):
        trampoline(table, *tail)
    moved = 0
    for i, (a, b, s) in enumerate(zip(direct, packed, state, strict=True)):
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and a.shape == b.shape, i
            np.testing.assert_array_equal(a, b, err_msg=f"argument {i}", strict=True)
            # bit for bit, NaN included
            assert a.tobytes() == b.tobytes(), i
            moved += not np.array_equal(a, s, equal_nan=True)
    assert moved >= 2  # the steps changed the state the two compare
    env.close()


@pytest.mark.parametrize("env_id", sorted(KERNELS))
def test_a_copied_env_packs_its_own_arrays(env_id):
    """A deep copy or a pickle of a stepped env steps as the original does, through a table
    of its own arrays (a table copied with its addresses would step the original's)."""
    env = gym.make(f"machining_envs/{env_id}")
    env.reset(seed=2)
    space = env.action_space
    space.seed(1)
    for _ in range(3):
        env.step(space.sample())
    base = env.unwrapped
    copies = [copy.deepcopy(base), pickle.loads(pickle.dumps(base))]
    actions = [space.sample() for _ in range(20)]
    runs = []
    for e in (base, *copies):
        steps = []
        for a in actions:
            obs, reward, terminated, truncated, _ = e.step(a)
            steps.append((obs.tobytes(), reward))
            if terminated or truncated:
                break
        runs.append(steps)
    assert runs[1] == runs[0] and runs[2] == runs[0]

    def addresses(e) -> set:
        t = e._core._packed._table
        return {int(t[SLOT * i + 1]) for i in range(len(t) // SLOT) if t[SLOT * i] > 2}

    # (tables of the linear blocks that every env with the same parameters shares and no
    # kernel writes, such as Turning-v0's for its lanes' starts, are the same arrays)
    lanes = getattr(base._core, "lanes", None)
    shared = {a.ctypes.data for a in getattr(lanes, "speed_free", ()) if isinstance(a, np.ndarray)}
    mine = addresses(base) - shared
    assert mine and all(addresses(c).isdisjoint(mine) for c in copies)
    env.close()


#: id -> the workers' loop its vector env on several threads runs (cached with its module).
SERVES = {
    "Turning-v0": turning_env._serve_step,
    "EndMilling-v0": milling_env._serve_step,
    "MicroDrilling-v0": drilling_env._serve_step,
    "Contouring-v0": contouring_env._serve_contour_step,
    "ContouringFeed-v0": feed_env._serve_feed_step,
}


@pytest.mark.parametrize("env_id", sorted(KERNELS))
def test_a_vector_env_on_threads_runs_its_trampoline_where_it_can(env_id):
    _, trampoline, _ = KERNELS[env_id]
    venv = gym.make_vec(f"machining_envs/{env_id}", num_envs=256, num_threads=2)
    venv.reset(seed=0)
    space = venv.single_action_space
    space.seed(0)
    for _ in range(2):
        venv.step(np.stack([space.sample() for _ in range(256)]))
    served = venv.unwrapped._core.blocks._served
    assert served[0] is trampoline and served[3] is SERVES[env_id]
    venv.close()
