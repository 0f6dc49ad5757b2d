"""Compiled building blocks the process kernels share: the fused multiply-add and the small
matrix-vector products of the sampled plants, with numpy's rounding.

The plants' sampled linear parts are products of small matrices with short vectors, once per
lane and control period. A library call for each costs more than the arithmetic, so the
kernels do the products themselves; to keep the numbers numpy gives (and with them the
golden closed-loop data), they sum in the order of numpy's BLAS.

This module imports numpy and numba only; it knows nothing of gymnasium.
"""

from __future__ import annotations

import numba
import numpy as np
from numba.core import types
from numba.extending import intrinsic

__all__ = ["fma", "matvec"]


@intrinsic
def fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (the processor's fused multiply-add, or libm's ``fma``)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return sig, codegen


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
