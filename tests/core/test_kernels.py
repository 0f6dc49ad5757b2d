"""The shared compiled products, powers, sines, cosines and norms
(``machining_envs.core.compiled.kernels``) against numpy's products and libm's ``pow``, ``sin``,
``cos`` and ``hypot``."""

import math

import numba
import numpy as np
import pytest

from machining_envs.core.compiled.kernels import (
    add8,
    add_scaled8,
    fma,
    get8,
    load8,
    matvec,
    powers,
    py_square,
    row_max,
    row_min,
    sincos_row,
    store8,
    vector_hypot,
)


def _random_matrix(rng, shape):
    """Entries over sixteen decades, both signs, with zeros and negative zeros."""
    v = rng.standard_normal(shape) * 10.0 ** rng.uniform(-8, 8, size=shape)
    u = rng.random(shape)
    v[u < 0.05] = 0.0
    v[(u >= 0.05) & (u < 0.08)] = -0.0
    return v


def _numpy_blas_orders_as_matvec() -> bool:
    """numpy's matrix-vector products come from OpenBLAS's x86-64 dgemv kernel for Haswell
    and its successors (the order ``matvec`` follows, in which the golden data were
    recorded); other libraries or processors may sum in another order."""
    from threadpoolctl import threadpool_info

    blas = [i for i in threadpool_info() if "numpy" in i.get("filepath", "")]
    arch = str(blas[0].get("architecture", "")).lower() if blas else ""
    return (
        bool(blas)
        and blas[0].get("internal_api") == "openblas"
        and arch
        in {
            "haswell",
            "zen",
            "steamroller",
            "excavator",
            "skylakex",
            "cooperlake",
            "sapphirerapids",
        }
    )


def _shapes(substeps):
    """The plants' shapes at ``substeps`` sub-steps: milling's servo (2M + 3, 4) and lag
    (M, M + 2), turning's servo (2M + 3, 4 (L + 1)) and sensor filter (2, M + 3), and
    every kind of tail: rows in whole groups of four or not, columns 0-3 past them."""
    m = substeps
    return [(2 * m + 3, 4), (m, m + 2), (2 * m + 3, 16), (2, m + 3), (1, m + 3), (5, 1)]


@pytest.mark.skipif(not _numpy_blas_orders_as_matvec(), reason="numpy's BLAS sums in another order")
@pytest.mark.parametrize("substeps", [1, 2, 3, 6, 10, 14, 30, 50])
def test_matvec_rounds_as_numpy_does(substeps):
    """The kernel's matrix-vector products equal numpy's to the last bit (those numpy's
    order does not cover go to np.dot), one matrix for all rows or one per row, with inf
    and NaN too."""
    rng = np.random.default_rng(substeps)
    for n, m in _shapes(substeps):
        for shared in (True, False):
            rows = 50
            a = _random_matrix(rng, (1 if shared else rows, n * m))
            x = _random_matrix(rng, (rows, m))
            x[7, rng.integers(m)] = np.inf
            a[-1, rng.integers(n * m)] = np.nan
            out = np.full((rows, n), 7.0)
            matvec(a, n, m, x, out)
            for k in range(rows):
                with np.errstate(invalid="ignore"):
                    expected = a[0 if shared else k].reshape(n, m) @ x[k]
                assert out[k].tobytes() == expected.tobytes(), (n, m, k)


@numba.njit
def _eight_wide(acc, a, b, o, sa, sb):
    """The eight-wide fused multiply-adds, read back value by value (``get8``), the
    eight-wide sum of that and ``acc``, and the scalar operations they stand for, for the
    values ``o .. o + 7``."""
    out = np.empty((4, 8))
    v = add_scaled8(load8(acc, o), a, b, o, sa, sb)
    store8(out[0], 0, add8(v, load8(acc, o)))
    w = (
        get8(v, 0),
        get8(v, 1),
        get8(v, 2),
        get8(v, 3),
        get8(v, 4),
        get8(v, 5),
        get8(v, 6),
        get8(v, 7),
    )
    for i in range(8):
        out[1, i] = w[i]
        out[2, i] = fma(b[o + i], sb, fma(a[o + i], sa, acc[o + i]))
        out[3, i] = out[2, i] + acc[o + i]
    return out


def test_eight_wide_fused_multiply_adds_are_the_scalar_chain():
    rng = np.random.default_rng(7)
    n = 24
    acc, a, b = (_random_matrix(rng, n) for _ in range(3))
    # Values where a fused multiply-add and a rounded product then a sum differ: with
    # e = 2**-30, (1 + e)(1 - e) - 1 is -2**-60 fused and 0 otherwise.
    e = 2.0**-30
    acc[5], a[5], b[5] = -1.0, 1.0 + e, 0.0
    for o in (0, 3, 16):
        for sa, sb in ((1.0 - e, 0.5), (-3.25e-7, 8.5e4), (0.0, -0.0)):
            got = _eight_wide(acc, a, b, o, sa, sb)
            np.testing.assert_array_equal(got[1], got[2])
            np.testing.assert_array_equal(got[0], got[3])
    fused = _eight_wide(acc, a, b, 0, 1.0 - e, 0.0)
    assert fused[1, 5] == -(2.0**-60)


@numba.njit
def _powers(src, so, dst, do, n, p):
    powers(src, so, dst, do, n, p)


#: The plants' exponents (turning's 0.7525, milling's 0.3999 and its drawn range, the
#: average-force model's 1), and others in the range the parameters allow and beyond.
_EXPONENTS = (0.05, 0.3999, 0.4025, 0.7525, 1.0, 1.3, 2.0, 3.5)


@pytest.mark.parametrize("p", _EXPONENTS)
def test_powers_are_pow_to_a_few_units_in_the_last_place(p):
    """Over 600 decades of bases, each power is libm's ``pow`` (Python's ``**``) to a
    relative error below ``4.5 (|p ln x| + 1) 2**-53`` (measured: at most 3.8), and below
    4e-15 for feeds of 1e-4 to 2 mm and the plants' exponents (up to 1.3). Where
    ``|p ln x| > 700`` (results past 1e+-304) the vector path steps aside and the values
    are ``pow``'s exactly."""
    rng = np.random.default_rng(int(p * 1e4))
    x = 10.0 ** rng.uniform(-307.0, 307.0, 20000)
    x[:2000] = rng.uniform(1e-4, 2.0, 2000)  # feeds per revolution and per tooth, mm
    got = np.empty_like(x)
    _powers(x, 0, got, 0, x.size, p)
    with np.errstate(over="ignore"):  # a numpy scalar's power is pow's, inf on overflow
        expected = np.array([np.float64(v) ** p for v in x])
    y = np.abs(p * np.log(x))
    inside = (y <= 700.0) & np.isfinite(expected) & (expected > 0.0)
    rel = np.abs(got[inside] - expected[inside]) / expected[inside]
    assert np.all(rel <= 4.5 * (y[inside] + 1.0) * 2.0**-53), float(rel.max())
    if p <= 1.3:
        feeds = np.abs(got[:2000] - expected[:2000]) / expected[:2000]
        assert np.all(feeds < 4e-15), float(feeds.max())
    assert got[~inside].tobytes() == expected[~inside].tobytes()
    if p >= 1.0:  # |p ln x| reaches 700: the test takes the libm path too
        assert np.count_nonzero(~inside) > 100


def test_powers_take_special_values_from_pow():
    """Zero, negative zero and negative bases are ``max(x, 0) ** p`` (0, or -0 for p = 1),
    NaN stays NaN, and infinities, subnormals and 1 are ``pow``'s."""
    x = np.array(
        [0.0, -0.0, -1.0, -np.inf, np.nan, np.inf, 5e-324, 1e-310, 2.2250738585072009e-308, 1.0]
    )
    for p in (0.4, 1.0, 2.0):
        got = np.empty_like(x)
        _powers(x, 0, got, 0, x.size, p)
        expected = np.array([max(v, 0.0) ** p for v in x.tolist()])
        assert got.tobytes() == expected.tobytes()


def test_a_power_is_the_same_in_a_row_of_any_length():
    """A value's power does not depend on where it falls in the row: in the processor's
    vectors or in the loop's scalar tail (so a lane's numbers are the same for any number
    of sub-steps around it); ``powers`` writes ``dst[do : do + n]`` and nothing else."""
    rng = np.random.default_rng(11)
    x = rng.uniform(1e-3, 1.5, 53)
    one = np.empty(1)
    alone = np.empty_like(x)
    for j in range(x.size):
        _powers(x, j, one, 0, 1, 0.7525)
        alone[j] = one[0]
    for so, do, n in ((0, 0, 53), (3, 5, 50), (1, 0, 7), (10, 40, 13)):
        dst = np.full(60, 7.0)
        _powers(x, so, dst, do, n, 0.7525)
        assert dst[do : do + n].tobytes() == alone[so : so + n].tobytes()
        assert np.all(np.delete(dst, np.arange(do, do + n)) == 7.0)


def test_py_square_is_pythons_power_of_two():
    """CPython's ``x ** 2`` (libm's pow) differs from ``x * x`` in the last bit for about one
    value in a thousand; ``py_square`` gives its numbers, taking ``pow`` only near a
    midpoint, and every value with that: midpoints, the ends of the range, zeros, inf, NaN."""
    rng = np.random.default_rng(22)
    values = [rng.normal(size=200_000) * s for s in (1e-3, 1.0, 1e3)]
    values.append(rng.uniform(-1, 1, 200_000) * 10.0 ** rng.uniform(-170, 150, 200_000))
    x = np.concatenate(values)
    # x * x exactly halfway between two doubles cannot be; these are as near it as can be
    # (mantissa 1 + 2**-26 +- a little: x**2 = 1 + 2**-25 + 2**-52 + ...)
    near = 1.0 + 2.0**-26 + np.arange(-200, 200) * 2.0**-52
    edges = [0.0, -0.0, 5e-324, 1e-170, 1e-160, 2.0**-486, 1.3e154, -1.4e154, math.inf, -math.inf]
    x = np.concatenate([x, near, -near * 3.0, edges])
    out = np.empty_like(x)
    _square_all(x, 2.0, out)
    np.testing.assert_array_equal(out, [_python_square(v) for v in x.tolist()])
    with np.errstate(over="ignore"):
        assert int(np.sum(out != x * x)) > 100  # so the distinction is needed
    nan = np.array([math.nan])
    _square_all(nan, 2.0, nan)
    assert math.isnan(nan[0])


def _python_square(v: float) -> float:
    try:
        return v**2
    except OverflowError:  # where libm's pow gives inf, CPython raises
        return math.inf


@numba.njit
def _square_all(x, two, out):
    for i in range(x.size):
        out[i] = py_square(x[i], two)


@numba.njit
def _sincos_each(x, s_out, c_out):
    """Each angle alone: a row of one."""
    for j in range(x.size):
        sincos_row(x[j : j + 1], 1, s_out[j : j + 1], c_out[j : j + 1])


@numba.njit
def _sincos_row(x, n, s_out, c_out):
    sincos_row(x, n, s_out, c_out)


def _ulps(got, expected):
    """Distance in units in the last place of the expected values."""
    return np.abs(got - expected) / np.spacing(np.abs(expected))


@pytest.mark.parametrize("span", [1.0, 8.0, 1e3, 2.0**20])
def test_sines_and_cosines_are_libms_to_one_unit_in_the_last_place(span):
    """Over angles up to ``span`` (the contouring paths' arcs and involutes turn a few
    times at most; 2**20 is the vector path's limit), and over the angles nearest the
    multiples of pi / 2 (the hardest to reduce: a sine or cosine near zero), each value is
    libm's or one unit in the last place from it; most are libm's."""
    rng = np.random.default_rng(int(span))
    x = rng.uniform(-span, span, 200_000)
    k = rng.integers(-int(span / 1.5) - 1, int(span / 1.5) + 2, 20_000)
    x[:20_000] = np.nextafter(k * (math.pi / 2.0), rng.choice([-np.inf, np.inf], k.size))
    x[20_000:20_100] = k[:100] * (math.pi / 2.0)
    x = x[(np.abs(x) <= 2.0**20) & (np.abs(x) >= 2.0**-27)]
    s, c = np.empty_like(x), np.empty_like(x)
    _sincos_row(x, x.size, s, c)
    es = np.array([math.sin(v) for v in x.tolist()])
    ec = np.array([math.cos(v) for v in x.tolist()])
    assert _ulps(s, es).max() <= 1.0 and _ulps(c, ec).max() <= 1.0
    assert np.mean(s == es) > 0.9 and np.mean(c == ec) > 0.9


def test_sines_and_cosines_outside_the_vector_range_are_libms():
    """Zero keeps its sign, and tiny, huge, infinite and NaN angles are libm's exactly."""
    x = np.array(
        [0.0, -0.0, 1e-9, -(2.0**-28), 5e-324, 2.0**20 + 1.0, -1e7, 1e300, np.inf, -np.inf, np.nan]
    )
    for fn in (_sincos_each, lambda a, s, c: _sincos_row(a, a.size, s, c)):
        s, c = np.empty_like(x), np.empty_like(x)
        with np.errstate(invalid="ignore"):
            fn(x, s, c)
        with np.errstate(invalid="ignore"):
            es = np.sin(x)
            ec = np.cos(x)
        es[:-3] = [math.sin(v) for v in x[:-3].tolist()]
        ec[:-3] = [math.cos(v) for v in x[:-3].tolist()]
        assert s.tobytes() == es.tobytes() and c.tobytes() == ec.tobytes()


def test_a_sine_is_the_same_in_a_row_of_any_length():
    """An angle's sine and cosine do not depend on where it falls in the row (the vector
    loop or its scalar tail, a libm neighbour or none): ``sincos_row`` gives ``sincos``'s
    numbers and writes the first ``n`` values only."""
    rng = np.random.default_rng(5)
    x = rng.uniform(-40.0, 40.0, 61)
    x[[7, 30]] = (0.0, np.inf)  # libm's, amid the others
    s1, c1 = np.empty_like(x), np.empty_like(x)
    with np.errstate(invalid="ignore"):
        _sincos_each(x, s1, c1)
    for lo, n in ((0, 61), (3, 50), (1, 7), (10, 1), (29, 5)):
        s, c = np.full(64, 7.0), np.full(64, 7.0)
        with np.errstate(invalid="ignore"):
            _sincos_row(x[lo:], n, s, c)
        assert s[:n].tobytes() == s1[lo : lo + n].tobytes()
        assert c[:n].tobytes() == c1[lo : lo + n].tobytes()
        assert np.all(s[n:] == 7.0) and np.all(c[n:] == 7.0)


@numba.njit
def _numbas_max_min(a, n):
    return a[:n].max(), a[:n].min()


@numba.njit
def _rows_max_min(a, n):
    return row_max(a, n), row_min(a, n)


def test_row_max_and_min_are_numbas_max_and_min():
    """The loops that kernels compiled without reference counting use in place of an
    array's ``max`` and ``min`` give numba's numbers: the first NaN where there is one, the
    first of equal values (so the sign of a zero), over any length."""
    rng = np.random.default_rng(0)
    for trial in range(400):
        n = int(rng.integers(1, 60))
        a = _random_matrix(rng, n + 3)
        u = rng.random(n + 3)
        if trial % 3 == 0:
            a[u < 0.1] = np.nan
        if trial % 2 == 0:  # the largest value a zero of either sign, or a negative one
            a = -np.abs(a) if trial % 4 == 0 else np.abs(a)
        if trial % 5 == 0 or trial % 4 == 0:
            a[u < 0.4] = np.where(u[u < 0.4] < 0.2, 0.0, -0.0)
        want = _numbas_max_min(a, n)
        got = _rows_max_min(a, n)
        assert np.array(got).tobytes() == np.array(want).tobytes(), (trial, a[:n])


@numba.njit(_nrt=False)
def _product_without_reference_counting(a, n, m, x, out):
    matvec(a, n, m, x, out)


@pytest.mark.parametrize("shape", [(1, 53), (3, 10), (2, 7)])
def test_matvec_runs_inside_a_kernel_without_reference_counting(shape):
    """``matvec`` keeps the runtime it needs for the shapes it hands to ``np.dot`` (one
    row, two or three columns past the groups of four) when a kernel compiled with
    ``_nrt=False`` calls it (the turning kernel, for a first-order sensor filter)."""
    n, m = shape
    rng = np.random.default_rng(1)
    a = rng.standard_normal((1, n * m))
    x = rng.standard_normal((4, m))
    out = np.zeros((4, n))
    _product_without_reference_counting(a, n, m, x, out)
    want = [a[0].reshape(n, m) @ row if n > 1 else [np.dot(a[0], row)] for row in x]
    np.testing.assert_array_equal(out, np.array(want))


@numba.njit
def _hypots(x, y, fast, libm):
    for i in range(x.size):
        fast[i] = vector_hypot(x[i], y[i])
        libm[i] = math.hypot(x[i], y[i])


def test_vector_hypot_is_libms_hypot_where_it_takes_the_values():
    """The norms the contour errors are made of, in vectors: within one unit in the last
    place of libm's ``hypot`` wherever both magnitudes are ordinary, and its number to the
    last bit where libm computes glibc's baseline form (which the first 20 000 random
    pairs tell: there about one pair in eight differs by a unit under the other forms);
    NaN, for ``math.hypot`` to take, only outside that (one magnitude beyond 2**511, the
    other below 2**-459 but not zero, or either not finite), and never for the contour
    errors' sizes."""
    rng = np.random.default_rng(2)
    n = 400_000
    x = rng.standard_normal(n) * 2.0 ** np.round(rng.uniform(-540, 540, n))
    ratio = rng.choice([1.0, -1e-17, 1e-8, 0.3, -2.0, 1e20, 0.0], n)
    y = x * ratio + rng.standard_normal(n) * rng.choice([0.0, 1e-300, 1.0], n)
    special = [0.0, -0.0, np.inf, -np.inf, np.nan, 5e-324, 2.0**511, 2.0**-459, 1e308, 1.0]
    sx, sy = np.meshgrid(special, special)
    # Equal magnitudes, one a few units from twice the other: the two branches of the
    # correction and the edge between them.
    a = rng.uniform(1e-3, 1e3, 2000)
    x = np.concatenate([x, sx.ravel(), a, a, 2.0 * a])
    y = np.concatenate([y, sy.ravel(), a, np.nextafter(a, 0.0), np.nextafter(a, np.inf)])
    fast, libm = np.empty(x.size), np.empty(x.size)
    _hypots(x, y, fast, libm)
    hi = np.maximum(np.abs(x), np.abs(y))
    lo = np.minimum(np.abs(x), np.abs(y))
    with np.errstate(invalid="ignore"):
        ordinary = (hi <= 2.0**511) & ((lo >= 2.0**-459) | (lo == 0.0))
    taken = ~np.isnan(fast)
    assert np.array_equal(taken, ordinary)
    assert taken.mean() > 0.5
    assert np.all(np.abs(fast[taken] - libm[taken]) <= np.spacing(libm[taken]))
    probe = slice(0, 20_000)
    if fast[probe][taken[probe]].tobytes() == libm[probe][taken[probe]].tobytes():
        assert fast[taken].tobytes() == libm[taken].tobytes()
    # The contour errors' sizes (mm: 1e-9 to 1e4) are always taken.
    d = rng.uniform(-1e4, 1e4, (2, 10000)) * 10.0 ** rng.uniform(-13, 0, (2, 10000))
    fast, libm = np.empty(10000), np.empty(10000)
    _hypots(d[0], d[1], fast, libm)
    assert not np.isnan(fast).any()


def test_clip_unit_is_numpys_clip_and_linear_map_to_the_last_bit():
    """The vector envs' one-pass clip (and linear command) against the numpy expressions
    they replace, on strided outputs, the edges, -0.0 and values far outside."""
    from machining_envs.core.compiled.kernels import clip_unit, clip_unit_linear

    rng = np.random.default_rng(3)
    a = np.concatenate(
        [
            rng.uniform(-3.0, 3.0, 500),
            [-1.0, 1.0, -0.0, 0.0, 1e300, -1e300, np.nextafter(1.0, 2.0), np.nextafter(-1.0, -2.0)],
        ]
    )
    n = a.size
    table = np.zeros((n, 3))
    flags = np.zeros((n, 2), dtype=bool)
    ints = np.zeros((n, 2), dtype=np.int64)
    want = np.minimum(np.maximum(a, -1.0), 1.0)
    want_clipped = (a < -1.0) | (a > 1.0)
    clip_unit(a, table[:, 0], ints[:, 1])
    assert table[:, 0].tobytes() == want.tobytes()
    assert np.array_equal(ints[:, 1], want_clipped.astype(np.int64))
    mid, half = 0.5 * (150.0 + 3.0), 0.5 * (150.0 - 3.0)
    clip_unit_linear(a, table[:, 1], flags[:, 1], table[:, 2], mid, half)
    assert table[:, 1].tobytes() == want.tobytes()
    assert np.array_equal(flags[:, 1], want_clipped)
    assert table[:, 2].tobytes() == (mid + half * want).tobytes()
