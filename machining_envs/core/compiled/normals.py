"""Standard normals of a numpy ``Generator``, drawn by compiled code from its own bit
generator: the sensor noise of the plants, one number where a step needs it.

The kernels of the turning, milling and drilling envs take their noise from each lane's
generator (the episode's ``np_random``). Drawing it from Python, a block of normals at a
time, cost a library call for each lane whose block ran out and kept a block per lane in
memory. Here compiled code draws each normal when the step needs it, with
``Generator.standard_normal``'s algorithm (numpy's 256-level ziggurat, as numba compiles
it for its own ``Generator`` support), on the generator's own state: through the bit
generator's public C interface (its ``bitgen_t``: the address of its state and of its
``next_uint64`` and ``next_double`` functions), so that the numbers are the ones
``rng.standard_normal()`` gives, in the same order, and the generator stands where it would
after them (``tests/core/test_normals.py`` checks both, for PCG64 and other bit
generators).

A table row holds addresses, not the generator: whoever fills it keeps the generator alive
(:class:`LaneGenerators`). numpy's own calls take the generator's lock; these do not, so a
generator bound here must not be drawn from by another thread while a step runs (the envs'
generators are their own).

This module imports numpy and numba only; it knows nothing of gymnasium.
"""

from __future__ import annotations

import ctypes

import numba
import numpy as np
from numba.core import cgutils, types
from numba.extending import intrinsic

# numba's own Generator.standard_normal (numpy's ziggurat, on a bit generator's C
# functions), which its support for numpy Generators compiles.
from numba.np.random.distributions import random_standard_normal
from numba.np.random.generator_core import next_uint64

__all__ = ["ROW", "LaneGenerators", "generator_row", "lane_noise", "next_word", "standard_normal"]

#: Entries of a generator's row: its state's address, then those of its ``next_uint64``
#: and ``next_double`` functions.
ROW = 3


#: numpy's ``bitgen_t`` (``numpy/random/bitgen.h``, its C API for random numbers): the
#: state's address, then ``next_uint64``, ``next_uint32``, ``next_double``, ``next_raw``.
_BITGEN_WORDS = 5
#: ``PyCapsule_GetPointer`` with its own prototype (not set on ``ctypes.pythonapi``'s,
#: which others share).
_capsule_pointer = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.c_char_p)(
    ("PyCapsule_GetPointer", ctypes.pythonapi)
)


def generator_row(rng: np.random.Generator) -> tuple[int, int, int]:
    """The row of ``rng`` (see :data:`ROW`), read from its bit generator's ``bitgen_t``
    (the ``capsule`` numpy gives C code; ``BitGenerator.ctypes`` would give the same
    addresses, at some 60 µs and 1.6 kB a generator); ``TypeError`` for anything but a
    numpy ``Generator``."""
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"a lane's generator must be a numpy Generator, got {type(rng).__name__}")
    address = _capsule_pointer(rng.bit_generator.capsule, b"BitGenerator")
    words = (ctypes.c_uint64 * _BITGEN_WORDS).from_address(address)
    return words[0], words[1], words[3]


class LaneGenerators:
    """The generators lanes draw their noise from, and their rows (``table``, int64 of
    shape ``(n, ROW)``) for the kernels; keeps each generator alive while its row is in the
    table. A pickle or a copy holds the generators and the table, whose rows it writes anew
    (the addresses are this process's; the array stays the one the kernels' argument
    tuples hold)."""

    __slots__ = ("generators", "table")

    def __init__(self, n: int) -> None:
        self.generators: list[np.random.Generator | None] = [None] * n
        self.table = np.zeros((n, ROW), dtype=np.int64)

    def bind(self, lane: int, rng: np.random.Generator) -> None:
        """Lane ``lane`` draws from ``rng`` from now on (nothing is done if it already
        does). ``ValueError`` if another lane draws from it: lanes on several threads would
        draw from one state at once."""
        if self.generators[lane] is rng:
            return
        row = generator_row(rng)
        shared = np.flatnonzero(self.table[:, 0] == row[0])
        if shared.size:
            raise ValueError(
                f"lane {lane}'s generator is already lane {int(shared[0])}'s: every lane "
                "needs a generator of its own"
            )
        self.table[lane] = row
        self.generators[lane] = rng

    def bind_many(self, lanes: list[int], rngs) -> None:
        """:meth:`bind` of each lane ``k`` of ``lanes`` to ``rngs[k]``."""
        generators = self.generators
        for k in lanes:
            if generators[k] is not rngs[k]:
                self.bind(k, rngs[k])

    def __getstate__(self) -> dict:
        return {"generators": self.generators, "table": self.table}

    def __setstate__(self, state: dict) -> None:
        self.generators = state["generators"]
        self.table = state["table"]
        for k, rng in enumerate(self.generators):
            self.table[k] = 0 if rng is None else generator_row(rng)


#: numba's type of a numpy bit generator in compiled code: its state and C functions.
_BIT_GENERATOR = types.NumPyRandomBitGeneratorType("bit_generator")


@intrinsic
def _bit_generator(typingctx, state, next_uint64, next_double):
    """numba's bit generator value for the addresses of a row (see :data:`ROW`): what
    its ``Generator`` support makes of a numpy generator passed in from Python, without
    the Python object (none of its members that hold it are read)."""
    if not (state == next_uint64 == next_double == types.int64):
        return None

    def codegen(context, builder, signature, args):
        bits = cgutils.create_struct_proxy(_BIT_GENERATOR)(context, builder)
        bits.state, bits.fnptr_next_uint64, bits.fnptr_next_double = args
        return bits._getvalue()

    return _BIT_GENERATOR(types.int64, types.int64, types.int64), codegen


@numba.njit(cache=True)
def standard_normal(table, k):
    """The next standard normal of lane ``k``'s generator (row ``table[k]``): the number
    its ``standard_normal()`` would give, by numpy's ziggurat."""
    return random_standard_normal(_bit_generator(table[k, 0], table[k, 1], table[k, 2]))


@numba.njit(cache=True)
def next_word(table, k):
    """The next 64-bit word of lane ``k``'s generator: the ``next_uint64`` of its bit
    generator, which ``Generator.integers`` reads for 64-bit ranges."""
    return next_uint64(_bit_generator(table[k, 0], table[k, 1], table[k, 2]))


@numba.njit(cache=True, inline="always")
def lane_noise(table, k, scale):
    """Lane ``k``'s sensor noise for one step: ``scale`` times the next standard normal of
    its generator; 0, and nothing drawn, where ``scale`` is 0 (a lane without noise)."""
    if scale != 0.0:
        return scale * standard_normal(table, k)
    return 0.0
