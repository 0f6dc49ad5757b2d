"""Four float64 lanes in one machine register, for the compiled lifted product.

OpenBLAS's dgemv kernel keeps the four FMA chains of a row in one 256-bit register and
advances them four columns at a time; :class:`Lanes4` is that register in numba code (the
same rounding lane by lane: one fused multiply-add per column), so the compiled block
update (``servo.run_block``) runs at the kernel's pace:

- :func:`lanes_zero`: four zero chains;
- :func:`lanes_fma`: ``acc + coef[i : i + 4] * x[j : j + 4]`` (one FMA per lane);
- :func:`lanes_fma_masked`: the same with the lanes outside ``[lo, hi)`` left as they are;
- :func:`lanes_fma_one`: ``coef * xv`` added to one lane only;
- :func:`lanes_sum`: ``(c0 + c2) + (c1 + c3)``, the kernel's sum of its chains.

Indices are not checked: the callers keep them inside their arrays.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.core.extending import intrinsic, models, register_model

__all__ = ["lanes_zero", "lanes_fma", "lanes_fma_masked", "lanes_fma_one", "lanes_sum"]


class Lanes4Type(types.Type):
    """Four float64 chains held as one LLVM ``<4 x double>``."""

    def __init__(self) -> None:
        super().__init__(name="Lanes4")


lanes4 = Lanes4Type()
_V = ir.VectorType(ir.DoubleType(), 4)


@register_model(Lanes4Type)
class _Lanes4Model(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _V)


def _fma(builder, a, b, c):
    fn = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(_V, [_V, _V, _V]), "llvm.fma.v4f64"
    )
    return builder.call(fn, [a, b, c])


def _load4(context, builder, aryty, ary, idx):
    """``ary[idx : idx + 4]`` of a 1-d float64 array as one vector (unaligned load)."""
    arr = context.make_array(aryty)(context, builder, ary)
    ptr = builder.gep(arr.data, [idx])
    return builder.load(builder.bitcast(ptr, _V.as_pointer()), align=8)


@intrinsic
def lanes_zero(typingctx):
    """Four chains at zero."""

    def codegen(context, builder, signature, args):
        return ir.Constant(_V, [0.0, 0.0, 0.0, 0.0])

    return lanes4(), codegen


@intrinsic
def lanes_fma(typingctx, acc, coef, ci, x, xi):
    """``acc + coef[ci : ci + 4] * x[xi : xi + 4]``, one FMA per lane."""
    if not (isinstance(coef, types.Array) and isinstance(x, types.Array)):
        return None
    sig = lanes4(lanes4, coef, types.intp, x, types.intp)

    def codegen(context, builder, signature, args):
        a, c, i, xa, j = args
        cv = _load4(context, builder, signature.args[1], c, i)
        xv = _load4(context, builder, signature.args[3], xa, j)
        return _fma(builder, cv, xv, a)

    return sig, codegen


@intrinsic
def lanes_fma_masked(typingctx, acc, coef, ci, x, xi, lo, hi):
    """As :func:`lanes_fma` for the lanes ``lo <= lane < hi``; the others unchanged (their
    coefficients taken as zero: an FMA with a zero coefficient leaves a finite chain as
    it is)."""
    if not (isinstance(coef, types.Array) and isinstance(x, types.Array)):
        return None
    sig = lanes4(lanes4, coef, types.intp, x, types.intp, types.intp, types.intp)

    def codegen(context, builder, signature, args):
        a, c, i, xa, j, lo_, hi_ = args
        cv = _load4(context, builder, signature.args[1], c, i)
        xv = _load4(context, builder, signature.args[3], xa, j)
        lanes = ir.Constant(ir.VectorType(ir.IntType(64), 4), [0, 1, 2, 3])
        inside = builder.and_(
            builder.icmp_signed(">=", lanes, _splat(builder, lo_)),
            builder.icmp_signed("<", lanes, _splat(builder, hi_)),
        )
        cv = builder.select(inside, cv, ir.Constant(_V, [0.0, 0.0, 0.0, 0.0]))
        return _fma(builder, cv, xv, a)

    return sig, codegen


def _splat(builder, value):
    vty = ir.VectorType(value.type, 4)
    v = ir.Constant(vty, ir.Undefined)
    for k in range(4):
        v = builder.insert_element(v, value, ir.Constant(ir.IntType(32), k))
    return v


@intrinsic
def lanes_fma_one(typingctx, acc, lane, coef, xv):
    """``coef * xv`` added (one FMA) to chain ``lane`` only."""
    sig = lanes4(lanes4, types.intp, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        a, lane_, c, xv_ = args
        zero = ir.Constant(_V, [0.0, 0.0, 0.0, 0.0])
        cv = builder.insert_element(zero, c, lane_)
        return _fma(builder, cv, _splat(builder, xv_), a)

    return sig, codegen


@intrinsic
def lanes_sum(typingctx, acc):
    """``(c0 + c2) + (c1 + c3)``: the chains summed as the BLAS kernel sums them."""
    sig = types.float64(lanes4)

    def codegen(context, builder, signature, args):
        (a,) = args
        c = [builder.extract_element(a, ir.Constant(ir.IntType(32), k)) for k in range(4)]
        return builder.fadd(builder.fadd(c[0], c[2]), builder.fadd(c[1], c[3]))

    return sig, codegen
