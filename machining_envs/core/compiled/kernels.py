"""Compiled building blocks the process kernels share: the fused multiply-add, the small
matrix-vector products of the sampled plants with numpy's rounding, eight-value vectors
(fused multiply-adds of whole columns, or of eight lanes' values side by side) for the
contouring servo's closed-loop recursion, the powers of a row of values (the force laws at
a period's sub-steps) and the sines and cosines of a row of angles (the contouring paths'
points) in vectors, and CPython's ``x ** 2`` (libm's ``pow``) to the last bit without
calling it for most values.

The plants' sampled linear parts are products of small matrices with short vectors, once per
lane and control period. A library call for each costs more than the arithmetic, so the
kernels do the products themselves; to keep the numbers numpy gives (and with them the
golden closed-loop data), they sum in the order of numpy's BLAS.

Beside them, :func:`read_only` freezes the cached tables the kernels read.

This module imports numpy and numba only; it knows nothing of gymnasium.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic, models, register_model

from machining_envs.core.notice import announce_compiling

announce_compiling()  # a line on stderr while numba compiles (the first use on a machine)

__all__ = [
    "add8",
    "add_scaled8",
    "clip8",
    "clip_unit",
    "unit_clip",
    "clip_unit_linear",
    "copy_into",
    "data_address",
    "fma",
    "fma8",
    "get8",
    "load8",
    "matvec",
    "mul8",
    "powers",
    "py_square",
    "read_only",
    "set_episode_flags",
    "shift8",
    "sincos_row",
    "store8",
    "sub8",
    "vec8",
    "vector_hypot",
    "zero8",
]


@intrinsic
def fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (the processor's fused multiply-add, or libm's ``fma``)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return sig, codegen


class Vec8Type(types.Type):
    """Eight float64 values held as one LLVM ``<8 x double>`` (a register, or two or four
    on processors with narrower vector units)."""

    def __init__(self) -> None:
        super().__init__(name="Vec8")


vec8 = Vec8Type()
_V8 = ir.VectorType(ir.DoubleType(), 8)
_F64 = types.Array(types.float64, 1, "C")


@register_model(Vec8Type)
class _Vec8Model(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _V8)


def _vector_at(context, builder, ary, idx):
    """Pointer to ``ary[idx : idx + 8]`` (a 1-d float64 array) as one vector."""
    arr = context.make_array(_F64)(context, builder, ary)
    return builder.bitcast(builder.gep(arr.data, [idx]), _V8.as_pointer())


def _fma8_ir(builder, a, b, c):
    """LLVM's fused multiply-add of three ``<8 x double>`` values."""
    fn = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(_V8, [_V8, _V8, _V8]), "llvm.fma.v8f64"
    )
    return builder.call(fn, [a, b, c])


def _splat8(builder, value):
    v = ir.Constant(_V8, ir.Undefined)
    for k in range(8):
        v = builder.insert_element(v, value, ir.Constant(ir.IntType(32), k))
    return v


@intrinsic
def load8(typingctx, x, o):
    """``x[o : o + 8]`` as a :class:`Vec8Type` value (indices not checked)."""
    if x != _F64:
        return None

    def codegen(context, builder, signature, args):
        return builder.load(_vector_at(context, builder, args[0], args[1]), align=8)

    return vec8(_F64, types.intp), codegen


@intrinsic
def store8(typingctx, x, o, v):
    """``x[o : o + 8] = v`` (indices not checked)."""
    if x != _F64 or v != vec8:
        return None

    def codegen(context, builder, signature, args):
        builder.store(args[2], _vector_at(context, builder, args[0], args[1]), align=8)
        return context.get_dummy_value()

    return types.none(_F64, types.intp, vec8), codegen


@intrinsic
def zero8(typingctx):
    """Eight zeros as a :class:`Vec8Type` value."""

    def codegen(context, builder, signature, args):
        return ir.Constant(_V8, [0.0] * 8)

    return vec8(), codegen


@intrinsic
def add_scaled8(typingctx, acc, a, b, o, sa, sb):
    """``acc + a[o : o + 8] * sa + b[o : o + 8] * sb`` as two fused multiply-adds per value
    (``fma(b, sb, fma(a, sa, acc))``, each rounded once), so the result does not depend on
    how many lanes the processor's vectors have. Indices not checked: the caller keeps
    ``[o, o + 8)`` inside the 1-d float64 arrays ``a`` and ``b``."""
    if not (acc == vec8 and a == _F64 and b == _F64):
        return None
    sig = vec8(vec8, _F64, _F64, types.intp, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        accv, av, bv, o_, sa_, sb_ = args
        ta = builder.load(_vector_at(context, builder, av, o_), align=8)
        tb = builder.load(_vector_at(context, builder, bv, o_), align=8)
        accv = _fma8_ir(builder, ta, _splat8(builder, sa_), accv)
        return _fma8_ir(builder, tb, _splat8(builder, sb_), accv)

    return sig, codegen


@intrinsic
def get8(typingctx, v, i):
    """Value ``i`` of a :class:`Vec8Type` value; ``i`` must be a literal integer 0-7."""
    if v != vec8 or not isinstance(i, types.IntegerLiteral) or not 0 <= i.literal_value < 8:
        return None
    idx = ir.Constant(ir.IntType(32), i.literal_value)

    def codegen(context, builder, signature, args):
        return builder.extract_element(args[0], idx)

    return types.float64(vec8, i), codegen


def _binary8(name: str, op: str, doc: str):
    """The intrinsic ``name`` of two :class:`Vec8Type` values: LLVM's ``op`` (``fadd``,
    ...) value by value."""

    def typer(typingctx, a, b):
        if not (a == vec8 and b == vec8):
            return None

        def codegen(context, builder, signature, args):
            return getattr(builder, op)(args[0], args[1])

        return vec8(vec8, vec8), codegen

    typer.__name__ = typer.__qualname__ = name
    typer.__doc__ = doc
    return intrinsic(typer)


add8 = _binary8("add8", "fadd", "``a + b`` for two :class:`Vec8Type` values, value by value.")
mul8 = _binary8("mul8", "fmul", "``a * b`` for two :class:`Vec8Type` values, value by value.")
sub8 = _binary8("sub8", "fsub", "``a - b`` for two :class:`Vec8Type` values, value by value.")


@intrinsic
def data_address(typingctx, x):
    """The address of ``x[0]`` (a 1-d float64 array) as an integer: where a kernel
    places vectors of eight values on 64-byte boundaries, which one load reads at once
    (a vector across two cache lines costs about twice as much)."""
    if x != _F64:
        return None

    def codegen(context, builder, signature, args):
        arr = context.make_array(_F64)(context, builder, args[0])
        return builder.ptrtoint(arr.data, ir.IntType(64))

    return types.int64(_F64), codegen


@intrinsic
def fma8(typingctx, a, b, c):
    """``a * b + c`` for three :class:`Vec8Type` values, value by value, each rounded once
    (:func:`fma`'s number)."""
    if not (a == vec8 and b == vec8 and c == vec8):
        return None

    def codegen(context, builder, signature, args):
        return _fma8_ir(builder, *args)

    return vec8(vec8, vec8, vec8), codegen


@intrinsic
def clip8(typingctx, u, limit):
    """Each value of ``u`` past ``+-limit`` set to the bound it passed, any other (NaN
    too) left as it is: ``limit if u > limit else -limit`` where ``u > limit or u <
    -limit``, else ``u``, value by value (two :class:`Vec8Type` values)."""
    if not (u == vec8 and limit == vec8):
        return None

    def codegen(context, builder, signature, args):
        u_, hi = args
        lo = builder.fneg(hi)
        over = builder.fcmp_ordered(">", u_, hi)
        under = builder.fcmp_ordered("<", u_, lo)
        return builder.select(builder.or_(over, under), builder.select(over, hi, lo), u_)

    return vec8(vec8, vec8), codegen


@intrinsic
def shift8(typingctx, z, g, u, applied):
    """``z + g * (applied - u)`` (a product, then a sum) where ``applied != u`` (a command
    :func:`clip8` clipped), else ``z``, value by value (four :class:`Vec8Type` values)."""
    if not (z == vec8 and g == vec8 and u == vec8 and applied == vec8):
        return None

    def codegen(context, builder, signature, args):
        z_, g_, u_, ua = args
        moved = builder.fcmp_ordered("!=", ua, u_)
        shifted = builder.fadd(z_, builder.fmul(g_, builder.fsub(ua, u_)))
        return builder.select(moved, shifted, z_)

    return vec8(vec8, vec8, vec8, vec8), codegen


@numba.njit(cache=True, inline="always")
def set_episode_flags(row, diverged, breakage, finished, terminated, truncated, over):
    """A lane's episode flags after a step into ``row[:6]``, in the lanes' common order:
    diverged, tool breakage, workpiece finished, terminated, truncated, over the limit."""
    flags = (diverged, breakage, finished, terminated, truncated, over)
    for i in range(6):
        row[i] = flags[i]


@numba.njit(cache=True, inline="always")
def unit_clip(x):
    """``x`` clipped to ``[-1, 1]`` (numpy's ``minimum(maximum(x, -1), 1)``, ``-0.0`` kept),
    and whether it was outside."""
    return min(max(x, -1.0), 1.0), x < -1.0 or x > 1.0


@numba.njit(cache=True)
def clip_unit(a, action, clipped):
    """A vector env's actions into its lanes' inputs in one pass: ``action[k]`` is ``a[k]``
    clipped to ``[-1, 1]`` and ``clipped[k]`` whether it was outside (:func:`unit_clip`). The
    actions are finite (the vector env checked them); any of the outputs may be a strided
    column."""
    for k in range(a.shape[0]):
        action[k], clipped[k] = unit_clip(a[k])


@numba.njit(cache=True)
def clip_unit_linear(a, action, clipped, command, mid, half):
    """:func:`clip_unit`, and ``command[k] = mid + half * action[k]``: the command of a
    linear ``ActionMap`` (``_mid``, ``_half``), rounded as numpy rounds it (a product, then
    a sum; no fused multiply-add)."""
    for k in range(a.shape[0]):
        y, clipped[k] = unit_clip(a[k])
        action[k] = y
        command[k] = mid + half * y


def read_only(*arrays: np.ndarray):
    """``arrays`` made read-only in place: the array, or a tuple of them when given several.
    What a cache (``functools.lru_cache``) hands to every env of the same parameters is made
    so where it is made, since a write to it would change them all. (A read-only array is a
    type of its own to a compiled kernel: made so once, every call hands the same type.)"""
    for a in arrays:
        a.flags.writeable = False
    return arrays[0] if len(arrays) == 1 else arrays


@numba.njit(cache=True)
def copy_into(dst, src):
    """``dst[:src.size] = src`` for 1-d arrays, value by value. Compiled code copies with
    this, not by setting a slice from an array: numba compiles that statement's message for
    a shape mismatch (string formatting) into every kernel that holds one, seconds each."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


@numba.njit(cache=True, inline="always")
def row_max(a, n):
    """``a[:n].max()`` (``n >= 1``) as numba's ``max`` gives it, the first NaN if any, in
    plain loops: a kernel compiled without reference counting (``_nrt=False``) cannot call
    ``max``, whose iterator needs it.

    Four running maxima over every fourth value, so that four comparisons are under way at
    once where one chain waits for each (a row of 50 took a tenth of the turning kernel);
    where that finds a NaN, the values are taken again one by one as numba does. A
    largest value of zero is the first zero of the row (numba keeps the first of equal
    values, and every value before it is negative); any other largest value is the same
    number wherever it occurs."""
    if n < 8:
        return _row_extreme_in_order(a, n, True)
    m0 = a[0]
    m1 = a[1]
    m2 = a[2]
    m3 = a[3]
    nan = (m0 != m0) | (m1 != m1) | (m2 != m2) | (m3 != m3)
    j = 4
    while j + 4 <= n:
        v0 = a[j]
        v1 = a[j + 1]
        v2 = a[j + 2]
        v3 = a[j + 3]
        nan = nan | (v0 != v0) | (v1 != v1) | (v2 != v2) | (v3 != v3)
        m0 = v0 if v0 > m0 else m0
        m1 = v1 if v1 > m1 else m1
        m2 = v2 if v2 > m2 else m2
        m3 = v3 if v3 > m3 else m3
        j += 4
    while j < n:
        v0 = a[j]
        nan = nan | (v0 != v0)
        m0 = v0 if v0 > m0 else m0
        j += 1
    m01 = m1 if m1 > m0 else m0
    m23 = m3 if m3 > m2 else m2
    top = m23 if m23 > m01 else m01
    if nan:
        return _row_extreme_in_order(a, n, True)
    if top == 0.0:  # value by value, the first zero: every value before it is negative
        j = 0
        while a[j] != 0.0:
            j += 1
        return a[j]
    return top


@numba.njit(cache=True, inline="always")
def _row_extreme_in_order(a, n, largest):
    """``a[:n].max()`` (``largest``) or ``.min()`` as numba gives them, value by value:
    the first NaN if any, else the first of the equal extreme values."""
    top = a[0]
    if top != top:
        return top
    for j in range(1, n):
        v = a[j]
        if v != v:
            return v
        if (v > top) if largest else (v < top):
            top = v
    return top


@numba.njit(cache=True, inline="always")
def row_min(a, n):
    """``a[:n].min()`` (``n >= 1``), as :func:`row_max` gives the max (value by value: the
    turning kernel asks for it only where a sample may cross a depth edge)."""
    return _row_extreme_in_order(a, n, False)


@numba.njit(cache=True, _nrt=True)
def matvec(a, n, m, x, out):
    """``out[k, :n] = A_k @ x[k, :m]`` for every row ``k`` of ``x``, with numpy's rounding.

    ``A_k`` is the ``(n, m)`` matrix stored row after row in ``a[k]``, or in ``a[0]`` for
    every ``k`` when ``a`` holds one matrix.

    numpy hands such a product to OpenBLAS's ``dgemv`` (transposed kernel), whose x86-64
    kernels (Haswell and later) sum each row in a fixed order: over the columns in whole
    groups of four, rows in groups of four accumulate four interleaved partial sums with
    fused multiply-adds, the rows left over two or one interleaved sums of rounded products;
    the partial sums are then added pairwise and the result is added to a zeroed output; a
    last column past the groups of four is then fused onto it. Done here in that order, for
    all the lanes in one call, the products cost a few nanoseconds each instead of a library
    call, and are the numbers numpy gives to the last bit (``tests/core/test_kernels.py``
    checks them on random matrices). Shapes outside that scheme (two or three columns past
    the groups of four, a single row, 2048 columns or more) go to ``np.dot``, as numpy's
    own product would; that allocates, so it is compiled with the runtime (``_nrt=True``)
    even where a kernel compiled without it (``_nrt=False``) calls it.
    """
    shared = a.shape[0] == 1
    tail = m & 3
    if tail > 1 or (tail and m < 5) or n < 2 or m >= 2048:
        for k in range(x.shape[0]):
            i = 0 if shared else k
            if n == 1:  # numpy takes a one-row product as a dot product
                out[k, 0] = np.dot(a[i, :m], x[k, :m])
            else:
                copy_into(out[k], np.dot(a[i, : n * m].reshape(n, m), x[k, :m]))
        return
    mg = m - tail  # columns in whole groups of four
    nb = n & ~3
    for k in range(x.shape[0]):
        i = 0 if shared else k
        if mg == 4 and tail == 0:  # one group of four columns: every kind of row sums alike
            x0 = x[k, 0]
            x1 = x[k, 1]
            x2 = x[k, 2]
            x3 = x[k, 3]
            for r in range(n):
                b = 4 * r
                p02 = a[i, b] * x0 + a[i, b + 2] * x2
                out[k, r] = 0.0 + (p02 + (a[i, b + 1] * x1 + a[i, b + 3] * x3))
            continue
        for r in range(nb):
            b = r * m
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            s3 = 0.0
            for q in range(0, mg, 4):
                s0 = fma(a[i, b + q], x[k, q], s0)
                s1 = fma(a[i, b + q + 1], x[k, q + 1], s1)
                s2 = fma(a[i, b + q + 2], x[k, q + 2], s2)
                s3 = fma(a[i, b + q + 3], x[k, q + 3], s3)
            out[k, r] = 0.0 + ((s0 + s2) + (s1 + s3))
        r = nb
        if (n - nb) & 2:
            for r in range(nb, nb + 2):
                b = r * m
                s0 = 0.0
                s1 = 0.0
                for q in range(0, mg, 2):
                    s0 = s0 + a[i, b + q] * x[k, q]
                    s1 = s1 + a[i, b + q + 1] * x[k, q + 1]
                out[k, r] = 0.0 + (s0 + s1)
            r = nb + 2
        if (n - nb) & 1:
            b = r * m
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            s3 = 0.0
            for q in range(0, mg, 4):
                s0 = s0 + a[i, b + q] * x[k, q]
                s1 = s1 + a[i, b + q + 1] * x[k, q + 1]
                s2 = s2 + a[i, b + q + 2] * x[k, q + 2]
                s3 = s3 + a[i, b + q + 3] * x[k, q + 3]
            out[k, r] = 0.0 + ((s0 + s2) + (s1 + s3))
        if tail:
            q = m - 1
            for r in range(n):
                out[k, r] = fma(a[i, r * m + q], x[k, q], out[k, r])


# ---- powers of a row of values ------------------------------------------------------------


@intrinsic
def float_bits(typingctx, x):
    """The 64 bits of the float64 ``x``, as an int64 (its sign bit the int's)."""
    if x != types.float64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(types.float64), codegen


@intrinsic
def bits_float(typingctx, i):
    """The float64 whose 64 bits are those of the int64 ``i`` (:func:`float_bits` undone)."""
    if i != types.int64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(types.int64), codegen


#: glibc's ``pow`` (2.28 on) is within 0.54 units in the last place of the exact power
#: (its source's worst case); 0.45 leaves a margin. A C library whose ``pow`` errs by more
#: could differ from ``py_square`` in the last bit, rarely (the golden data, recorded on
#: glibc, are compared to 1e-9 elsewhere); a lane still equals the single env.
_POW_ULP = 0.45


@numba.njit(cache=True, inline="always")
def py_square(x, two):
    """CPython's ``x ** 2`` (libm's ``pow(x, two)``, ``two`` = 2.0 read at run time).

    ``x * x`` is the double nearest ``x**2``; where ``x**2`` lies within 0.45 of a unit
    in the last place of it (``fma`` gives the exact remainder), any other double is more
    than 0.55 units away, so ``pow``, within 0.54 units, returns it too. It calls
    ``pow`` only near a midpoint between two doubles (about one value in ten) or where
    ``x * x`` is below 2**-970 or overflows: a few nanoseconds for most values instead
    of some tens (``tests/core/test_kernels.py`` compares it with CPython).
    """
    p = x * x
    biased = (float_bits(p) >> 52) & 0x7FF  # p >= 0: its exponent field; a unit in its last
    if 52 < biased < 0x7FF:  # place is 2**(biased - 1075), a normal double here
        if abs(fma(x, x, -p)) < _POW_ULP * bits_float((biased - 52) << 52):
            return p
    elif x == 0.0:
        return 0.0  # pow(+-0, 2) is +0
    return math.pow(x, two)


@intrinsic
def quotient(typingctx, a, b):
    """``a / b`` for float64s, as the processor divides (no Python ``ZeroDivisionError``
    check, whose branch keeps a loop out of the processor's vectors)."""
    if not (a == types.float64 and b == types.float64):
        return None

    def codegen(context, builder, signature, args):
        return builder.fdiv(*args)

    return types.float64(types.float64, types.float64), codegen


#: ln 2 in two parts: the first with 32 significant bits (so that ``n * _LN2_HI`` is exact
#: for every exponent ``n`` of a float64), the second the rest (ln 2 - ``_LN2_HI``, rounded).
_LN2_HI = 0.6931471806019545  # 0x1.62e42ffp-1
_LN2_LO = -4.2009150726810846e-11
_INV_LN2 = 1.4426950408889634
#: 1.5 * 2**52: a float64 of magnitude below 2**51 added to it is rounded to an integer,
#: which the low bits of the sum hold; an int64 of that size added to its bits is that float.
_ROUND = 6755399441055744.0
_ROUND_BITS = 0x4338000000000000
#: The bits of sqrt(1/2): ``x`` is split as ``z 2**k`` with ``z`` in [sqrt(1/2), sqrt(2)).
_SQRT_HALF_BITS = 0x3FE6A09E667F3BCD
#: Normal positive finite float64s have bits in [_MIN_NORMAL_BITS, _INF_BITS).
_MIN_NORMAL_BITS = 0x0010000000000000
_INF_BITS = 0x7FF0000000000000
#: Largest |p ln x| taken by the vector path: 2**n stays a normal number.
_Y_MAX = 700.0


@numba.njit(cache=True, inline="always")
def _pow_vector(x, p):
    """``x ** p`` as ``exp(p ln x)`` from multiplies, fused multiply-adds, one division and
    bit operations only, so that a loop of them runs in the processor's vectors; NaN where
    ``x`` is not a normal positive finite number or ``|p ln x|`` exceeds 700 (the caller
    takes those from libm's ``pow``).

    ``ln x = k ln 2 + ln z`` with ``x = z 2**k``, ``z`` in [sqrt(1/2), sqrt(2)), and
    ``ln z = 2 atanh(s)``, ``s = (z - 1) / (z + 1)`` (``|s| <= 0.172``), by its series to
    ``s**23`` (the next term is below 2**-60 of the sum); ``exp y = 2**n exp r`` with
    ``n = round(y / ln 2)``, ``|r| <= ln(2) / 2``, by its Taylor series to ``r**13`` (the
    next term below 2**-58 of the sum). Both series are summed by Estrin's scheme. The
    relative error stays below ``4.5 (|p ln x| + 1) 2**-53``, most of it the rounding of
    ``p ln x`` (``tests/core/test_kernels.py`` measures it against ``pow``)."""
    b = float_bits(x)
    t = b - _SQRT_HALF_BITS
    k = t >> 52
    z = bits_float(b - (k << 52))
    kf = bits_float(k + _ROUND_BITS) - _ROUND  # k as a float64, exactly
    f = z - 1.0
    s = quotient(f, 2.0 + f)
    # ln z = 2s + s w q(w), q(w) = sum 2 w**i / (2i + 3) for i <= 10, by Estrin's scheme
    # (pairs, then powers of w**2): a short chain of dependent operations, which the
    # processor overlaps from value to value, where Horner's is one long chain.
    w = s * s
    w2 = w * w
    w4 = w2 * w2
    q01 = fma(w, 2.0 / 5.0, 2.0 / 3.0)
    q23 = fma(w, 2.0 / 9.0, 2.0 / 7.0)
    q45 = fma(w, 2.0 / 13.0, 2.0 / 11.0)
    q67 = fma(w, 2.0 / 17.0, 2.0 / 15.0)
    q89 = fma(w, 2.0 / 21.0, 2.0 / 19.0)
    q03 = fma(w2, q23, q01)
    q47 = fma(w2, q67, q45)
    q8x = fma(w2, 2.0 / 23.0, q89)
    q = fma(w4 * w4, q8x, fma(w4, q47, q03))
    ln_z = fma(s * w, q, 2.0 * s)
    y = p * fma(kf, _LN2_HI, fma(kf, _LN2_LO, ln_z))
    nr = fma(y, _INV_LN2, _ROUND)  # n + 1.5 * 2**52: n in its low bits
    n = nr - _ROUND
    r = fma(-n, _LN2_HI, y)
    r = fma(-n, _LN2_LO, r)
    # exp r = sum r**i / i! for i <= 13, by Estrin's scheme as above.
    r2 = r * r
    r4 = r2 * r2
    e01 = r + 1.0
    e23 = fma(r, 1.0 / 6.0, 0.5)
    e45 = fma(r, 1.0 / 120.0, 1.0 / 24.0)
    e67 = fma(r, 1.0 / 5040.0, 1.0 / 720.0)
    e89 = fma(r, 1.0 / 362880.0, 1.0 / 40320.0)
    eab = fma(r, 1.0 / 39916800.0, 1.0 / 3628800.0)
    ecd = fma(r, 1.0 / 6227020800.0, 1.0 / 479001600.0)
    e03 = fma(r2, e23, e01)
    e47 = fma(r2, e67, e45)
    e8b = fma(r2, eab, e89)
    e = fma(r4 * r4, fma(r4, ecd, e8b), fma(r4, e47, e03))
    scale = bits_float((float_bits(nr) - _ROUND_BITS + 1023) << 52)
    ok = (b >= _MIN_NORMAL_BITS) & (b < _INF_BITS) & (abs(y) <= _Y_MAX)
    return e * scale if ok else np.nan


@numba.njit(cache=True, inline="always")
def powers(src, so, dst, do, n, p):
    """``dst[do + j] = max(src[so + j], 0.0) ** p`` for ``j < n`` (1-d float64 arrays; NaN
    stays NaN), in the processor's vectors.

    The force laws of the turning and milling plants raise the feed at every sub-step of a
    period to a power, and the drilling plant's spindle friction the speed at every RK4
    stage; libm's ``pow``, one value at a time, was a fifth to a third of those kernels. Here the values go through :func:`_pow_vector`, and those it does not take
    (zero, negative, subnormal, infinite or NaN values, results beyond about 1e+-304)
    through ``pow`` after it, so that every special case is libm's. A value differs from
    ``pow``'s by a few units in the last place (below 4e-15 for the plants' feeds and
    exponents), and is the same wherever it falls in the row, so on any number of lanes or
    threads. ``src`` and ``dst`` may be one array if the two ranges do not overlap.
    """
    x = src[so : so + n]  # views: indices from 0, which the compiler knows are not negative
    y = dst[do : do + n]
    for j in range(n):
        y[j] = _pow_vector(x[j], p)
    for j in range(n):
        if y[j] != y[j]:
            y[j] = max(x[j], 0.0) ** p


# ---- the Euclidean norm of a pair, in vectors ---------------------------------------------

#: glibc's bounds of ``hypot``'s common case: no scaling between them (``e_hypot.c``).
_HYPOT_LARGE = 2.0**511
_HYPOT_TINY = 2.0**-459
_HYPOT_EPS = 2.0**-54


@numba.njit(cache=True, inline="always")
def vector_hypot(x, y):
    """``math.hypot(x, y)`` (libm's) for ordinary values, NaN for the others: the larger
    magnitude above 2**511, the smaller below 2**-459 but not zero, or either not finite,
    which the caller then hands to ``math.hypot``.

    This is the common case of glibc's ``hypot`` (2.35 on), in the form glibc compiles for
    the baseline x86-64 processor (no fused multiply-add): the square root of the sum of
    squares, corrected once by the rounding errors of the squares, and the larger magnitude
    alone where the smaller is below 2**-54 of it. Without branches or library calls, a loop
    of it runs in the processor's vectors, where ``math.hypot`` is a call per value. Where
    libm is that glibc it is libm's value to the last bit; elsewhere (an older glibc, a
    build for processors with a fused multiply-add, another C library) within a unit in the
    last place of it, both being within one of the exact norm.
    """
    ax = abs(x)
    ay = abs(y)
    swap = ax < ay
    hi = ay if swap else ax
    lo = ax if swap else ay
    h = math.sqrt(hi * hi + lo * lo)
    if h <= 2.0 * lo:
        delta = h - lo
        t1 = hi * (2.0 * delta - hi)
        t2 = (delta - 2.0 * (hi - lo)) * delta
    else:
        delta = h - hi
        t1 = 2.0 * delta * (hi - 2.0 * lo)
        t2 = (4.0 * delta - lo) * lo + delta * delta
    h = h - quotient(t1 + t2, 2.0 * h)
    r = hi + lo if lo <= hi * _HYPOT_EPS else h
    ok = (hi <= _HYPOT_LARGE) & ((lo >= _HYPOT_TINY) | (lo == 0.0))
    return r if ok else np.nan


# ---- sines and cosines of a row of angles -------------------------------------------------

#: pi / 2 in three parts: the double nearest it, then the double nearest the rest, then the
#: next (their sum is pi / 2 to about 160 bits).
_PIO2_HI = 1.5707963267948966
_PIO2_MID = 6.123233995736766e-17
_PIO2_LO = -1.4973849048591698e-33
_TWO_OVER_PI = 0.6366197723675814
#: The angles the vector path takes: up to 2**20 rad, where ``n pi / 2`` (``n`` below
#: 2**20) is still subtracted exactly enough; from 2**-27 rad, where the sine is the
#: angle itself to the last bit (libm gives that, and the sign of zero).
_SINCOS_MAX = 1048576.0
_SINCOS_MIN = 7.450580596923828e-09


@numba.njit(cache=True, inline="always")
def _sincos_vector(x):
    """``(sin x, cos x)`` from multiplies, fused multiply-adds and bit operations only, so
    that a loop of them runs in the processor's vectors; ``(NaN, NaN)`` where ``|x|`` is
    not within [2**-27, 2**20] or lies within ``|n| 2**-30`` of a multiple ``n pi / 2``
    (the caller takes those from libm).

    ``x = n pi / 2 + r`` with ``n = round(2 x / pi)``, ``|r| <= pi / 4``: ``x - n pi_hi``
    is exact (both are multiples of a unit in the last place of ``pi_hi`` or ``x``, and
    the difference is below 1), and the next two parts of ``pi / 2`` leave ``r`` rounded
    plus the tail it lost (exact unless ``r`` is that near zero, a sine or cosine whose
    bits the subtraction cancelled). ``sin r`` and ``cos r`` are their Taylor series to
    ``r**19`` and ``r**18`` (the next terms are below 2**-60 of the sums), summed by
    Estrin's scheme; the cosine adds ``1 - r**2 / 2`` with its rounding error carried.
    ``n mod 4`` then picks and signs the pair. Within 0.91 units in the last place of the
    exact values in 20 000 angles of [-50, 50] checked with 200-bit arithmetic, and never
    more than one unit from libm's (``tests/core/test_kernels.py`` measures it).
    """
    nr = fma(x, _TWO_OVER_PI, _ROUND)  # n + 1.5 * 2**52: n (mod 4 too) in its low bits
    n = nr - _ROUND
    r0 = fma(-n, _PIO2_HI, x)
    r = fma(-n, _PIO2_MID, r0)
    # the part of r lost to its rounding (r0 - r is exact unless r cancels, see ``ok``)
    tail = fma(-n, _PIO2_LO, fma(-n, _PIO2_MID, r0 - r))
    z = r * r
    z2 = z * z
    z4 = z2 * z2
    # sin r = r + r z p(z), p(z) = sum (-1)**(i+1) z**i / (2i + 3)! for i <= 8
    p01 = fma(z, 1.0 / 120.0, -1.0 / 6.0)
    p23 = fma(z, 1.0 / 362880.0, -1.0 / 5040.0)
    p45 = fma(z, 1.0 / 6227020800.0, -1.0 / 39916800.0)
    p67 = fma(z, 1.0 / 355687428096000.0, -1.0 / 1307674368000.0)
    p = fma(z4 * z4, -1.0 / 121645100408832000.0, fma(z4, fma(z2, p67, p45), fma(z2, p23, p01)))
    sin_r = r + fma(r * z, p, tail)
    # cos r = 1 - z / 2 + z**2 q(z), q(z) = sum (-1)**i z**i / (2i + 4)! for i <= 7
    q01 = fma(z, -1.0 / 720.0, 1.0 / 24.0)
    q23 = fma(z, -1.0 / 3628800.0, 1.0 / 40320.0)
    q45 = fma(z, -1.0 / 87178291200.0, 1.0 / 479001600.0)
    q67 = fma(z, -1.0 / 6402373705728000.0, 1.0 / 20922789888000.0)
    q = fma(z4, fma(z2, q67, q45), fma(z2, q23, q01))
    half = 0.5 * z
    w = 1.0 - half
    cos_r = w + (((1.0 - w) - half) + fma(z2, q, -r * tail))
    # quadrant n mod 4: (sin, cos) = (s, c), (c, -s), (-s, -c), (-c, s)
    quadrant = float_bits(nr)
    odd = (quadrant & 1) != 0
    a = cos_r if odd else sin_r
    b = sin_r if odd else cos_r
    sin_x = bits_float(float_bits(a) ^ ((quadrant & 2) << 62))
    cos_x = bits_float(float_bits(b) ^ (((quadrant + 1) & 2) << 62))
    # An angle within |n| 2**-30 of a multiple of pi / 2 (a sine or cosine near zero; about
    # one in 1e9 |n| of all) loses bits of r to the cancellation: libm takes it.
    ok = (abs(x) <= _SINCOS_MAX) & (abs(x) >= _SINCOS_MIN) & (abs(r) >= abs(n) * 2.0**-30)
    return (sin_x if ok else np.nan), (cos_x if ok else np.nan)


@numba.njit(cache=True, inline="always")
def sincos_row(x, n, s_out, c_out):
    """``s_out[j], c_out[j] = sin(x[j]), cos(x[j])`` for ``j < n`` (1-d float64 arrays, not
    overlapping): :func:`_sincos_vector` over the whole row, then libm where it took none
    (tiny, huge, infinite or NaN angles, and those nearest a multiple of pi / 2). Each value
    is the same wherever it falls in the row. About 2 ns an angle where libm takes some 12
    (a 2-core Xeon with AVX-512, numba's 256-bit vectors)."""
    xs = x[:n]  # views: indices from 0, which the compiler knows are not negative
    ss = s_out[:n]
    cs = c_out[:n]
    for j in range(n):
        ss[j], cs[j] = _sincos_vector(xs[j])
    for j in range(n):
        if ss[j] != ss[j]:
            ss[j] = math.sin(xs[j])
            cs[j] = math.cos(xs[j])
