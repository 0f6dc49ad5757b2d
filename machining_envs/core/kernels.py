"""Compiled building blocks the process kernels share: the fused multiply-add, the small
matrix-vector products of the sampled plants with numpy's rounding, and eight-value vectors
(fused multiply-adds of whole columns) for the contouring servo's closed-loop recursion.

The plants' sampled linear parts are products of small matrices with short vectors, once per
lane and control period. A library call for each costs more than the arithmetic, so the
kernels do the products themselves; to keep the numbers numpy gives (and with them the
golden closed-loop data), they sum in the order of numpy's BLAS.

This module imports numpy and numba only; it knows nothing of gymnasium.
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic, models, register_model

__all__ = ["add8", "add_scaled8", "fma", "get8", "load8", "matvec", "store8", "vec8", "zero8"]


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
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(_V8, [_V8, _V8, _V8]), "llvm.fma.v8f64"
        )
        ta = builder.load(_vector_at(context, builder, av, o_), align=8)
        tb = builder.load(_vector_at(context, builder, bv, o_), align=8)
        accv = builder.call(fn, [ta, _splat8(builder, sa_), accv])
        return builder.call(fn, [tb, _splat8(builder, sb_), accv])

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


@intrinsic
def add8(typingctx, a, b):
    """``a + b`` for two :class:`Vec8Type` values, value by value."""
    if not (a == vec8 and b == vec8):
        return None

    def codegen(context, builder, signature, args):
        return builder.fadd(args[0], args[1])

    return vec8(vec8, vec8), codegen


@numba.njit(cache=True)
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
    own product would.
    """
    shared = a.shape[0] == 1
    tail = m & 3
    if tail > 1 or (tail and m < 5) or n < 2 or m >= 2048:
        for k in range(x.shape[0]):
            i = 0 if shared else k
            if n == 1:  # numpy takes a one-row product as a dot product
                out[k, 0] = np.dot(a[i, :m], x[k, :m])
            else:
                out[k, :n] = np.dot(a[i, : n * m].reshape(n, m), x[k, :m])
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
