"""``core.compiled.normals``: the standard normals compiled code draws from a numpy ``Generator``
are ``standard_normal()``'s, in order, and leave the generator where numpy's would."""

from __future__ import annotations

import copy
import ctypes
import pickle

import numba
import numpy as np
import pytest

from machining_envs.core.compiled.normals import (
    ROW,
    LaneGenerators,
    generator_row,
    lane_noise,
    standard_normal,
)


@numba.njit(cache=True)
def _fill(table, k, out):
    for i in range(out.shape[0]):
        out[i] = standard_normal(table, k)


BIT_GENERATORS = [
    np.random.PCG64,
    np.random.PCG64DXSM,
    np.random.MT19937,
    np.random.Philox,
    np.random.SFC64,
]


@pytest.mark.parametrize("bit_generator", BIT_GENERATORS, ids=lambda b: b.__name__)
def test_the_normals_and_the_state_are_numpys(bit_generator):
    """200 000 normals from each of 10 seeds: numpy's to the last bit (1.5 % of the draws
    fall outside the ziggurat's rectangles, about 3 000 a seed, some 50 of them in the
    tail: the paths that call exp and log1p), and the generator then draws what numpy's
    does."""
    lanes = LaneGenerators(2)
    for seed in range(10):
        mine = np.random.Generator(bit_generator(seed))
        want = np.random.Generator(bit_generator(seed))
        lanes.bind(1, mine)
        got = np.empty(200_000)
        _fill(lanes.table, 1, got)
        np.testing.assert_array_equal(got, want.standard_normal(got.size), strict=True)
        assert mine.random(3).tolist() == want.random(3).tolist()
        assert mine.integers(0, 1000, 5).tolist() == want.integers(0, 1000, 5).tolist()


def test_a_lane_without_noise_draws_nothing():
    lanes = LaneGenerators(1)
    rng = np.random.default_rng(4)
    lanes.bind(0, rng)
    state = rng.bit_generator.state

    @numba.njit
    def noise(table, scale):
        return lane_noise(table, 0, scale)

    assert noise(lanes.table, 0.0) == 0.0
    assert rng.bit_generator.state == state
    assert noise(lanes.table, 2.0) == 2.0 * np.random.default_rng(4).standard_normal()


def test_binding_writes_the_row_and_keeps_the_generator():
    lanes = LaneGenerators(3)
    assert lanes.table.shape == (3, ROW) and not lanes.table.any()
    rng = np.random.default_rng(0)
    lanes.bind(2, rng)
    assert lanes.generators[2] is rng
    assert tuple(lanes.table[2]) == generator_row(rng) and not lanes.table[:2].any()
    # the addresses numpy's ctypes interface gives for the same bit generator
    c = rng.bit_generator.ctypes
    fn = [ctypes.cast(f, ctypes.c_void_p).value for f in (c.next_uint64, c.next_double)]
    assert generator_row(rng) == (c.state_address, *fn)
    with pytest.raises(TypeError, match="numpy Generator"):
        lanes.bind(0, np.random.RandomState(0))
    with pytest.raises(ValueError, match="lane 0's generator is already lane 2's"):
        lanes.bind(0, rng)
    lanes.bind(2, rng)  # the same lane again: nothing to do
    lanes.bind(2, np.random.default_rng(1))
    lanes.bind(0, rng)  # free again


@pytest.mark.parametrize("clone", [copy.deepcopy, lambda x: pickle.loads(pickle.dumps(x))])
def test_a_copy_draws_from_its_own_generators(clone):
    """A copy's rows point at its own generators (copies of the original's, in the same
    state), so the two draw the same numbers without moving each other."""
    lanes = LaneGenerators(2)
    lanes.bind(0, np.random.default_rng(7))
    twin = clone(lanes)
    assert twin.generators[1] is None and not twin.table[1].any()
    assert twin.generators[0] is not lanes.generators[0]
    assert tuple(twin.table[0]) == generator_row(twin.generators[0])
    a, b = np.empty(50), np.empty(50)
    _fill(lanes.table, 0, a)
    _fill(twin.table, 0, b)
    np.testing.assert_array_equal(a, b)
