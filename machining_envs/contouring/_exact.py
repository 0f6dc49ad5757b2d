"""Arithmetic of numpy, OpenBLAS and CPython, reproduced to the last bit in compiled code.

The contouring envs were first written with numpy arrays, BLAS products and Python floats;
their compiled kernels (numba) must give the same numbers to the last bit, so that
recorded episodes stay valid and a lane of a vector env equals the single env. The
operations here are those whose rounding differs from a plain loop:

- :func:`py_hypot`: CPython's ``math.hypot`` (an exactly rounded sum of squares; libm's
  ``hypot``, which numpy and numba use, differs in the last bit for about 1 pair in 200);
- :func:`np_sum` / :func:`np_mean`: numpy's pairwise summation of a contiguous float64
  array (``np.sum``, ``np.mean``);
- :func:`gemv_row`: one element of OpenBLAS's ``dgemv`` (``A @ x`` of a C-ordered float64
  matrix, x86-64 Haswell kernels, one thread): four interleaved FMA chains per row
  (``machining_envs.core.compiled.kernels.fma``: one rounding, as the BLAS kernels use).

CPython's ``x ** 2`` is libm's ``pow``, which differs from ``x * x`` for about one value
in a thousand; compiled code gets it from ``math.pow(x, two)`` with ``two`` read at run
time (a constant exponent is rewritten into ``x * x`` by the compiler), and
``machining_envs.core.compiled.kernels.py_square`` calls it only where ``x * x`` could differ.

The tests in ``tests/contouring/test_exact.py`` compare every function here with the
operation it reproduces on random data.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from machining_envs.core.compiled.kernels import bits_float, float_bits, fma

__all__ = [
    "py_hypot",
    "np_sum",
    "np_mean",
    "gemv_row",
    "py_mod",
    "vecmat_rows",
]


@numba.njit(cache=True, inline="always")
def _exact_mul(x, y):
    """``(hi, lo)``: ``hi`` the rounded product, ``hi + lo == x * y`` exactly."""
    hi = x * y
    return hi, fma(x, y, -hi)


@numba.njit(cache=True)
def py_hypot(a, b):
    """CPython's ``math.hypot(a, b)``: the Euclidean norm rounded from an exact sum of
    squares, with one differential correction (the same bits for every result of normal
    size; a subnormal result, below 2.2e-308, may differ in its last bit)."""
    a = abs(a)
    b = abs(b)
    if math.isinf(a) or math.isinf(b):
        return math.inf
    if math.isnan(a) or math.isnan(b):
        return math.nan
    mx = a if a > b else b
    if mx == 0.0:
        return mx
    biased = float_bits(mx) >> 52  # mx > 0: its exponent field
    if 0 < biased < 2045:  # normal: frexp's exponent e is biased - 1022, and 2**-e normal
        scale = bits_float((2045 - biased) << 52)  # 2**-e, without frexp's and ldexp's calls
    else:
        _, e = math.frexp(mx)
        if e < -1023:  # subnormal: rescale (as CPython does) and try again
            return 2.2250738585072014e-308 * py_hypot(
                a / 2.2250738585072014e-308, b / 2.2250738585072014e-308
            )
        scale = math.ldexp(1.0, -e)
    csum = 1.0
    frac1 = 0.0
    frac2 = 0.0
    for v in (a, b):
        x = v * scale
        ph, pl = _exact_mul(x, x)
        s = csum + ph
        lo = ph - (s - csum)
        csum = s
        frac1 += pl
        frac2 += lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    ph, pl = _exact_mul(-h, h)
    s = csum + ph
    lo = ph - (s - csum)
    csum = s
    frac1 += pl
    frac2 += lo
    x = csum - 1.0 + (frac1 + frac2)
    h += x / (2.0 * h)
    return h / scale


@numba.njit(cache=True, inline="always")
def py_mod(a, b):
    """Python's (and numpy's) floating-point ``a % b``: the sign follows ``b``."""
    return a % b


@numba.njit(cache=True)
def _pairwise_block(a, lo, n):
    """numpy's ``pairwise_sum`` of ``a[lo : lo + n]`` for ``n <= 128`` (no split)."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0 = a[lo]
    r1 = a[lo + 1]
    r2 = a[lo + 2]
    r3 = a[lo + 3]
    r4 = a[lo + 4]
    r5 = a[lo + 5]
    r6 = a[lo + 6]
    r7 = a[lo + 7]
    i = 8
    while i < n - (n % 8):
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


# numpy's pairwise_sum halves (at a multiple of 8) every run of more than 128 numbers and
# adds the halves' sums. A compiled function cannot call itself here (numba's cache of a
# recursive function crashes when loaded), so each level is its own function, made by
# :func:`_wider` from the one below it: level k takes runs of up to 2**k * 128 (no recursion
# and no allocation, so that code without a runtime can use them).


@numba.njit(cache=True, inline="always")
def _halves(part, a, lo, n, n2):
    """``part(a, lo, n2) + part(a, lo + n2, n - n2)``, with one call of ``part`` in a loop:
    two calls would be inlined as two copies of everything below, so that the chain of
    levels compiled 2**7 copies of the block sum (seconds of compiling)."""
    left = 0.0
    right = 0.0
    for h in range(2):
        v = part(a, lo + h * n2, n - n2 if h else n2)
        if h:
            right = v
        else:
            left = v
    return left + right


def _wider(part):
    """The pairwise sum one level up from ``part``: runs of up to twice ``part``'s length."""

    @numba.njit(cache=True)
    def level(a, lo, n):
        if n <= 128:
            return _pairwise_block(a, lo, n)
        n2 = n // 2
        n2 -= n2 % 8
        return _halves(part, a, lo, n, n2)

    return level


_pairwise7 = _pairwise_block
for _ in range(7):
    _pairwise7 = _wider(_pairwise7)


@numba.njit(cache=True)
def _pairwise(a, lo, n):
    """numpy's ``pairwise_sum`` of ``a[lo : lo + n]`` (``n`` up to 16384)."""
    return _pairwise7(a, lo, n)


@numba.njit(cache=True)
def np_sum(a):
    """``np.sum(a)`` of a 1-d contiguous float64 array (of up to 16384 numbers)."""
    return _pairwise(a, 0, a.size)


@numba.njit(cache=True)
def np_mean(a):
    """``np.mean(a)`` of a 1-d float64 array."""
    return np_sum(a) / float(a.size)


@numba.njit(cache=True)
def gemv_row(a, x, r, n_rows):
    """``(a @ x)[r]`` as OpenBLAS's ``dgemv`` computes it for a C-ordered ``a`` of
    ``n_rows`` rows (``a[r]`` may be any row of the product).

    The columns are taken in blocks of four, whatever is left (one to three) after them.
    Rows in whole groups of four: four FMA chains, column ``c`` in chain ``c % 4``, summed
    as ``(c0 + c2) + (c1 + c3)``; the last ``n_rows % 4`` rows: two chains of separate
    multiplies and adds (two rows left) or four of them summed pairwise (one row left).
    The columns left over are added at the end, with the compiler's FMA contractions.
    """
    n_cols = a.shape[1]
    m3 = n_cols & 3
    nb = n_cols - m3
    v = 0.0
    if nb > 0:
        full = n_rows - (n_rows & 3)
        if r < full:
            c0 = 0.0
            c1 = 0.0
            c2 = 0.0
            c3 = 0.0
            for c in range(0, nb, 4):
                c0 = fma(a[r, c], x[c], c0)
                c1 = fma(a[r, c + 1], x[c + 1], c1)
                c2 = fma(a[r, c + 2], x[c + 2], c2)
                c3 = fma(a[r, c + 3], x[c + 3], c3)
            v = (c0 + c2) + (c1 + c3)
        elif (n_rows & 2) and r < full + 2:
            l0 = 0.0
            l1 = 0.0
            for c in range(0, nb, 2):
                l0 = l0 + a[r, c] * x[c]
                l1 = l1 + a[r, c + 1] * x[c + 1]
            v = l0 + l1
        else:
            l0 = 0.0
            l1 = 0.0
            l2 = 0.0
            l3 = 0.0
            for c in range(0, nb, 4):
                l0 = l0 + a[r, c] * x[c]
                l1 = l1 + a[r, c + 1] * x[c + 1]
                l2 = l2 + a[r, c + 2] * x[c + 2]
                l3 = l3 + a[r, c + 3] * x[c + 3]
            v = (l0 + l2) + (l1 + l3)
    y = 0.0 + v
    if m3 == 1:
        y = fma(a[r, nb], x[nb], y)
    elif m3 == 2:
        y = y + fma(a[r, nb], x[nb], a[r, nb + 1] * x[nb + 1])
    elif m3 == 3:
        y = y + fma(a[r, nb + 2], x[nb + 2], fma(a[r, nb], x[nb], a[r, nb + 1] * x[nb + 1]))
    return y


@numba.njit(cache=True)
def gemv(a, x, out):
    """``out[:] = a @ x`` as OpenBLAS's ``dgemv`` computes it (see :func:`gemv_row`)."""
    n = a.shape[0]
    for r in range(n):
        out[r] = gemv_row(a, x, r, n)


@numba.njit(cache=True)
def vecmat_rows(z, mt, out):
    """``out[i] = z[i] @ mt.T`` for every row ``i``, each row exactly as numpy computes the
    1-D product ``z[i] @ m`` alone (``mt`` is ``m.T`` made C-ordered: numpy's ``z @ m`` of
    a 1-D ``z`` is OpenBLAS's ``dgemv`` on ``m.T``, :func:`gemv_row`).

    A batch of rows takes every row through the same operations, :func:`gemv_row`'s for
    output ``r``, in the same order: so the loops run over the rows innermost (``z``
    transposed), where the compiler puts several rows in one vector instruction, and each
    row's numbers stay those of ``gemv_row``."""
    n = z.shape[0]
    n_rows = mt.shape[0]
    if n < 4:
        for i in range(n):
            for r in range(n_rows):
                out[i, r] = gemv_row(mt, z[i], r, n_rows)
        return
    n_cols = mt.shape[1]
    m3 = n_cols & 3
    nb = n_cols - m3
    full = n_rows - (n_rows & 3)
    zt = np.ascontiguousarray(z.T)
    acc = np.zeros((4, n))  # the chains; acc[0] then holds their sum (gemv_row's v)
    v = acc[0]
    for r in range(n_rows):
        a = mt[r]
        acc[:] = 0.0
        if nb > 0:
            if r < full:  # four FMA chains, summed (c0 + c2) + (c1 + c3)
                for c in range(0, nb, 4):
                    a0, a1, a2, a3 = a[c], a[c + 1], a[c + 2], a[c + 3]
                    x0, x1, x2, x3 = zt[c], zt[c + 1], zt[c + 2], zt[c + 3]
                    for i in range(n):
                        acc[0, i] = fma(a0, x0[i], acc[0, i])
                        acc[1, i] = fma(a1, x1[i], acc[1, i])
                        acc[2, i] = fma(a2, x2[i], acc[2, i])
                        acc[3, i] = fma(a3, x3[i], acc[3, i])
                for i in range(n):
                    v[i] = (v[i] + acc[2, i]) + (acc[1, i] + acc[3, i])
            elif (n_rows & 2) and r < full + 2:  # two chains of multiplies and adds
                for c in range(0, nb, 2):
                    a0, a1 = a[c], a[c + 1]
                    x0, x1 = zt[c], zt[c + 1]
                    for i in range(n):
                        acc[0, i] = acc[0, i] + a0 * x0[i]
                        acc[1, i] = acc[1, i] + a1 * x1[i]
                for i in range(n):
                    v[i] = v[i] + acc[1, i]
            else:  # four chains of multiplies and adds, summed pairwise
                for c in range(0, nb, 4):
                    a0, a1, a2, a3 = a[c], a[c + 1], a[c + 2], a[c + 3]
                    x0, x1, x2, x3 = zt[c], zt[c + 1], zt[c + 2], zt[c + 3]
                    for i in range(n):
                        acc[0, i] = acc[0, i] + a0 * x0[i]
                        acc[1, i] = acc[1, i] + a1 * x1[i]
                        acc[2, i] = acc[2, i] + a2 * x2[i]
                        acc[3, i] = acc[3, i] + a3 * x3[i]
                for i in range(n):
                    v[i] = (v[i] + acc[2, i]) + (acc[1, i] + acc[3, i])
        if m3 == 0:
            for i in range(n):
                out[i, r] = 0.0 + v[i]
        elif m3 == 1:
            b0 = a[nb]
            xb0 = zt[nb]
            for i in range(n):
                out[i, r] = fma(b0, xb0[i], 0.0 + v[i])
        elif m3 == 2:
            b0, b1 = a[nb], a[nb + 1]
            xb0, xb1 = zt[nb], zt[nb + 1]
            for i in range(n):
                out[i, r] = (0.0 + v[i]) + fma(b0, xb0[i], b1 * xb1[i])
        else:
            b0, b1, b2 = a[nb], a[nb + 1], a[nb + 2]
            xb0, xb1, xb2 = zt[nb], zt[nb + 1], zt[nb + 2]
            for i in range(n):
                out[i, r] = (0.0 + v[i]) + fma(b2, xb2[i], fma(b0, xb0[i], b1 * xb1[i]))
