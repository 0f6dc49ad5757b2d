"""A compiled kernel's many arguments in one: the single env's step, called from Python.

A call from Python into a numba kernel checks the type of every argument and unboxes every
array: about 80 ns an array on top of the call. A lane kernel takes 11-39 arrays (the
lanes' state, tables, outputs), so a single env, which calls it once a step for one lane,
paid 1-3 µs of each 7-12 µs step just for that. :func:`pack` writes an argument tuple's
arrays (address, shape) and numbers into one int64 table, once, and each process has a
compiled **trampoline** taking that table alone, which reads the arguments back with the
readers below and calls the kernel: one array to unbox instead of dozens. The kernel gets
C-contiguous arrays of the same types as when called directly (or, read by
:func:`f8_2_rows`, arrays of layout ``A``), and does the same arithmetic in the same order
(no fast-math): the same numbers, to the last bit. The compiler sees more
of them, though (their strides follow from their shapes where it inlines the kernel), and
vectorises some loops better: Turning-v0's kernel runs 1.5x faster through its trampoline.

Each argument takes :data:`SLOT` entries of the table: a code for its kind (dtype and
dimensions, or a float or an int), then its data address (a number's own bits) and its
shape (and, for a 2-d float64 view of some columns of a wider array, read by
:func:`f8_2_rows`, its row stride). Each reader checks the code of the slot it reads and
raises ``TypeError`` where it is another kind, so a trampoline that reads an argument as
what it is not fails instead of reading memory wrongly.

The table holds addresses, not arrays: it is valid only while the tuple it was packed from
keeps its arrays alive. :class:`PackedArgs` keeps the tuple beside its table, packs again
when it is given another tuple, and packs nothing into a pickle or a copy (their arrays are
elsewhere).

This module imports numpy, numba and ``core.compiled.kernels`` only.
"""

from __future__ import annotations

import numba
import numpy as np
from numba.core import types
from numba.extending import intrinsic

from machining_envs.core.compiled.kernels import bits_float

__all__ = [
    "SLOT",
    "PackedArgs",
    "spaced_rows",
    "as_float",
    "as_int",
    "b1_1",
    "b1_2",
    "f4_2",
    "f8_1",
    "f8_2",
    "f8_2_rows",
    "f8_3",
    "i8_1",
    "i8_2",
    "pack",
]

#: Table entries per argument: its kind's code, its address (or a number's bits), three
#: extents.
SLOT = 5

_FLOAT = 1
_INT = 2
#: The array kinds by dtype; an array's code is 8 * kind + dimensions.
_KINDS = {
    np.dtype(np.float64): 1,
    np.dtype(np.float32): 2,
    np.dtype(np.int64): 3,
    np.dtype(np.bool_): 4,
}


def _code(kind: int, ndim: int) -> int:
    return 8 * kind + ndim


# The code f8_2_rows checks (a module global: a constant to the compiled code).
_F8_2 = _code(1, 2)
#: Code of a 2-d float64 array whose rows are contiguous but further apart than a row
#: (a view of some columns of a wider array), its row stride in the slot's last entry.
_ROWS_APART = 14


def _rows_apart(a: np.ndarray) -> bool:
    s0, s1 = a.strides
    return a.dtype == np.float64 and s1 == 8 and s0 % 8 == 0 and s0 >= 8 * a.shape[1]


def spaced_rows(n_rows: int, n: int) -> np.ndarray:
    """An uninitialised float64 table of ``n_rows`` rows of ``n`` values (one per lane)
    whose rows lie 64 bytes more than ``n`` values apart: a view of a wider array, which
    :func:`pack` hands to a kernel as rows apart (:func:`f8_2_rows`). For a kernel that
    writes a lane's column at once: with rows a multiple of 4 kB apart (``n = 1024``:
    8 kB) its stores alias one another in the cache and stall, several times over."""
    return np.empty((n_rows, n + 8))[:, :n]


def pack(args: tuple) -> np.ndarray:
    """The int64 table of ``args`` (arrays of float64, float32, int64 or bool with one to
    three dimensions, C-contiguous, or 2-d float64 with contiguous rows further apart;
    Python floats and ints), :data:`SLOT` entries each."""
    table = np.zeros(SLOT * len(args), dtype=np.int64)
    for i, a in enumerate(args):
        o = SLOT * i
        if isinstance(a, np.ndarray):
            kind = _KINDS.get(a.dtype)
            if a.ndim == 2 and not a.flags.c_contiguous and a.size and _rows_apart(a):
                table[o : o + 5] = (_ROWS_APART, a.ctypes.data, *a.shape, a.strides[0] // 8)
                continue
            if kind is None or not 1 <= a.ndim <= 3 or not a.flags.c_contiguous:
                raise TypeError(
                    f"pack: argument {i} is a {a.ndim}-d {a.dtype} array"
                    f"{'' if a.flags.c_contiguous else ' (not C-contiguous)'}; expected a "
                    "C-contiguous float64, float32, int64 or bool array of 1-3 dimensions, "
                    "or a 2-d float64 array of contiguous rows"
                )
            table[o] = _code(kind, a.ndim)
            table[o + 1] = a.ctypes.data
            table[o + 2 : o + 2 + a.ndim] = a.shape
        elif isinstance(a, float):
            table[o] = _FLOAT
            table[o + 1] = np.float64(a).view(np.int64)
        elif isinstance(a, int) and not isinstance(a, bool):
            table[o] = _INT
            table[o + 1] = a
        else:
            raise TypeError(
                f"pack: argument {i} is a {type(a).__name__}; expected an array, a float or an int"
            )
    return table


class PackedArgs:
    """The table of the last argument tuple given, packed again when the tuple is another
    object (the tuple is kept, so its arrays outlive the table)."""

    __slots__ = ("_args", "_table")

    def __init__(self) -> None:
        self._args: tuple | None = None
        self._table: np.ndarray | None = None

    def __call__(self, args: tuple) -> np.ndarray:
        if args is not self._args:
            self._table = pack(args)
            self._args = args
        return self._table

    def __getstate__(self) -> dict:
        return {}  # addresses mean nothing elsewhere: the copy packs its own tuple

    def __setstate__(self, state: dict) -> None:
        self._args = None
        self._table = None


@intrinsic
def _address(typingctx, address):
    """A ``void *`` of an int64 address (a packed array's data)."""
    if address != types.int64:
        return None

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_value_type(types.voidptr))

    return types.voidptr(types.int64), codegen


@numba.njit(cache=True, inline="always")
def _at(t, i, code):
    """The offset of argument ``i``'s slot, after checking its code."""
    o = SLOT * i
    if t[o] != code:
        raise TypeError("packed argument read as another kind")
    return o


def _reader(dtype, ndim: int):
    """The reader of an argument packed from a C-contiguous ``ndim``-d array of ``dtype``:
    the array over the same memory (numba has no tuple of a length its argument gives,
    so each number of dimensions has its own body)."""
    code = _code(_KINDS[np.dtype(dtype)], ndim)
    if ndim == 1:

        @numba.njit(cache=True, inline="always")
        def read(t, i):
            o = _at(t, i, code)
            return numba.carray(_address(t[o + 1]), (t[o + 2],), dtype)

    elif ndim == 2:

        @numba.njit(cache=True, inline="always")
        def read(t, i):
            o = _at(t, i, code)
            return numba.carray(_address(t[o + 1]), (t[o + 2], t[o + 3]), dtype)

    else:

        @numba.njit(cache=True, inline="always")
        def read(t, i):
            o = _at(t, i, code)
            return numba.carray(_address(t[o + 1]), (t[o + 2], t[o + 3], t[o + 4]), dtype)

    return read


f8_1, f8_2, f8_3 = (_reader(np.float64, d) for d in (1, 2, 3))
f4_2 = _reader(np.float32, 2)
i8_1, i8_2 = _reader(np.int64, 1), _reader(np.int64, 2)
b1_1, b1_2 = _reader(np.bool_, 1), _reader(np.bool_, 2)


@numba.njit(cache=True, inline="always")
def f8_2_rows(t, i):
    """A 2-d float64 argument whose rows may lie further apart than a row (a view of some
    columns of a wider array; a C-contiguous one too): an array of layout ``A``."""
    o = SLOT * i
    if t[o] == _F8_2:  # C-contiguous: its rows one row apart
        stride = t[o + 3]
    elif t[o] == _ROWS_APART:
        stride = t[o + 4]
    else:
        raise TypeError("packed argument read as another kind")
    rows, cols = t[o + 2], t[o + 3]
    span = (rows - 1) * stride + cols if rows > 0 else 0
    base = numba.carray(_address(t[o + 1]), (span,), np.float64)
    return np.lib.stride_tricks.as_strided(base, shape=(rows, cols), strides=(8 * stride, 8))


@numba.njit(cache=True, inline="always")
def as_float(t, i):
    """Argument ``i`` as a float (an int argument converted, as a direct call would)."""
    o = SLOT * i
    if t[o] == _INT:
        return float(t[o + 1])
    if t[o] != _FLOAT:
        raise TypeError("packed argument read as another kind")
    return bits_float(t[o + 1])


@numba.njit(cache=True, inline="always")
def as_int(t, i):
    o = _at(t, i, _INT)
    return t[o + 1]
