"""Records of a kernel's arguments (``machining_envs.core.compiled.schema``): declared once,
read back from a packed table as the same arrays, cut into blocks by their axes."""

import enum
import pickle
import subprocess
import sys

import numba
import numpy as np
import pytest

from machining_envs.core.compiled import schema
from machining_envs.core.compiled.packed import pack

Plant = schema.record(
    "Plant",
    __name__,
    """
    z buf: lanes f8_2
    seg: lanes i8_1
    info: lanes_t f8_2_rows
    gain: shared f8
    m: shared i8
    """,
)
Env = schema.record(
    "Env",
    __name__,
    """
    obs: lanes f4_2
    done: lanes b1_1
    """,
)
_read_plant = Plant.reader
_read_env = Env.reader
_AT_PLANT, _AT_ENV, _END = schema.offsets(Plant, Env)

Col = enum.IntEnum("Col", "a b c", start=0)


@numba.njit(cache=True)
def _kernel(p, e):
    """Writes every field it is given, columns by name."""
    for k in range(p.z.shape[0]):
        p.z[k, Col.c] = p.z[k, Col.a] * p.gain + p.m
        p.buf[k, 0] += 1.0
        p.seg[k] += 2
        p.info[1, k] = p.z[k, Col.c]
        e.obs[k, 0] = np.float32(p.z[k, Col.c])
        e.done[k] = True


@numba.njit(cache=True)
def _trampoline(t):
    _kernel(_read_plant(t, _AT_PLANT), _read_env(t, _AT_ENV))


def _arrays(n=3):
    info = np.zeros((2, n + 8))[:, :n]  # rows further apart than a row
    plant = Plant(
        np.arange(3.0 * n).reshape(n, 3),
        np.zeros((n, 2)),
        np.zeros(n, dtype=np.int64),
        info,
        1.5,
        4,
    )
    env = Env(np.zeros((n, 2), dtype=np.float32), np.zeros(n, dtype=np.bool_))
    return plant, env


def test_a_record_declares_its_fields_kinds_and_axes_once():
    assert Plant._fields == ("z", "buf", "seg", "info", "gain", "m")
    assert Plant.fields[0] == schema.Field("f8_2", 0) and Plant.fields[3] == schema.Field(
        "f8_2_rows", 1
    )
    assert Plant.axes == (0, 0, 0, 1, None, None)
    assert schema.axes(Plant, Env) == Plant.axes + (0, 0)
    assert (_AT_PLANT, _AT_ENV, _END) == (0, 6, 8)
    # a record pickles by reference to its class (bound to its name in its module)
    p, _ = _arrays()
    assert pickle.loads(pickle.dumps(p)).gain == 1.5


def test_the_trampoline_hands_its_kernel_the_same_records():
    direct, packed = _arrays(), _arrays()
    _kernel(*direct)
    _trampoline(pack(schema.flatten(*packed)))
    for a, b in zip(schema.flatten(*direct), schema.flatten(*packed), strict=True):
        if isinstance(a, np.ndarray):
            assert a.tobytes() == b.tobytes()
    assert direct[1].done.all() and direct[0].seg.tolist() == [2, 2, 2]
    assert direct[0].z[:, Col.c].tolist() == [4.0, 8.5, 13.0]


def test_flatten_unflatten_gather_and_via_table():
    plant, env = _arrays()
    flat = schema.flatten(plant, env)
    assert len(flat) == _END
    back = schema.unflatten((*flat, 3), (Plant, Env))  # what follows the records is left out
    assert back == (plant, env)

    class Holder:
        obs = env.obs

    assert schema.gather(Env, Holder, done=env.done) == env
    calls = []

    def trampoline(table, tail):
        calls.append((table.size, tail))
        _trampoline(table)

    schema.via_table(trampoline, _END)(*flat, 7)
    assert calls == [(_END * 5, 7)] and env.done.all()


def test_named_columns_are_views():
    class Core:
        pass

    table = np.zeros((4, 3))
    core = Core()
    schema.bind_columns(core, table, Col)
    core.b[:] = 2.0
    assert table[:, 1].tolist() == [2.0] * 4 and core.c.base is table


@pytest.mark.parametrize(
    "spec, message",
    [
        ("z: lanes f9_2", "kind"),
        ("z: sideways f8_2", "place"),
        ("z: lanes", "place kind"),
        ("z: lanes f8_2\nz: shared f8", "twice"),
        ("z buf", "no 'place kind'"),
    ],
)
def test_a_bad_spec_is_refused_naming_the_line(spec, message):
    with pytest.raises(ValueError, match=message):
        schema.record("Bad", __name__, spec)


_CACHED = """
import gymnasium as gym, numpy as np, machining_envs
from machining_envs.turning import lanes
env = gym.make("machining_envs/Turning-v0")
env.reset(seed=0)
env.step(np.zeros(1, dtype=np.float32))
for f in (lanes._step_packed, lanes._start_packed):
    print(f.__name__, sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values()))
"""


def test_kernels_of_records_load_from_numba_cache():
    """A trampoline that rebuilds records (generated readers inlined) is cached on disk: a
    second process loads it, compiling nothing."""
    run = [sys.executable, "-c", _CACHED]
    subprocess.run(run, check=True, capture_output=True, timeout=900)  # compiles, if need be
    out = subprocess.run(run, check=True, capture_output=True, text=True, timeout=900).stdout
    for line in out.splitlines():
        name, hits, misses = line.split()
        assert (int(hits), int(misses)) == (1, 0), line
