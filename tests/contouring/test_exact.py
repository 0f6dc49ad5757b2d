"""The compiled contouring kernels give the numbers the numpy, BLAS and Python forms of the
same equations give: to the last bit for the arithmetic primitives (``_exact``) and the path
geometry over ``Path.table()``, to rounding for the lifted block product of the servo loop."""

import math

import numpy as np
import pytest

from machining_envs.contouring import _exact, paths
from machining_envs.contouring.paths import Arc, Involute, Line, Path
from machining_envs.contouring.plant import ContouringParams
from machining_envs.contouring.servo import (
    LANES,
    LANES_STATE_SIZE,
    ServoBlock,
    ServoLanes,
    ServoLoop,
    gather_states,
    lane_loops,
    lifted_matrix,
    run_block,
    run_lanes,
    scatter_lanes,
    servo_design,
)

RNG = np.random.default_rng(20240)


@pytest.mark.parametrize(
    "shape", [(314, 212), (308, 206), (13, 9), (7, 5), (6, 6), (6, 7), (15, 15), (3, 3)]
)
def test_gemv_row_is_numpys_matrix_vector_product(shape):
    """Every residue of rows and columns modulo four (the BLAS kernel's cases)."""
    for _ in range(30):
        a = RNG.normal(size=shape)
        x = RNG.normal(size=shape[1])
        out = np.empty(shape[0])
        _exact.gemv(a, x, out)
        np.testing.assert_array_equal(out, a @ x)


@pytest.mark.parametrize("shape", [(6, 8), (7, 9), (13, 15), (10, 10), (5, 3), (4, 4), (42, 44)])
@pytest.mark.parametrize("n", [1, 3, 4, 9, 100])
def test_vecmat_rows_gives_each_rows_product_alone(shape, n):
    """Each row of a batch as :func:`gemv_row` gives that row's product alone (numpy's 1-D
    product on the CPU the kernels follow: every residue of the outputs and inputs modulo
    four, batches below and above the lane-vectorised path's smallest), to the last bit,
    signed zeros and NaN included."""
    for _ in range(10):
        mt = RNG.normal(size=shape)
        z = RNG.normal(size=(n, shape[1])) * 10.0 ** RNG.uniform(-3, 3, (n, shape[1]))
        z[0, 0] = -0.0
        if n > 2:
            z[1] = 0.0
            z[2, -1] = np.nan
        out = np.empty((n, shape[0]))
        _exact.vecmat_rows(z, mt, out)
        want = np.array(
            [[_exact.gemv_row(mt, z[i], r, shape[0]) for r in range(shape[0])] for i in range(n)]
        )
        assert out.tobytes() == want.tobytes()
        if n > 2:
            assert np.isnan(out[2]).any() and (np.signbit(out[1]) == np.signbit(want[1])).all()


@pytest.mark.parametrize("n", [1, 5, 8, 50, 128, 129, 300, 1000, 5000, 16384])
def test_np_sum_and_mean_are_numpys_pairwise_sums(n):
    for _ in range(20):
        a = RNG.normal(size=n) * 10.0 ** RNG.uniform(-3, 3, n)
        assert _exact.np_sum(a) == np.sum(a)
        assert _exact.np_mean(a) == np.mean(a)


def test_py_hypot_is_pythons_math_hypot():
    """CPython's hypot differs from libm's (numpy's, numba's) in the last bit now and then;
    the kernels that reproduce Python code use this one."""
    differs = 0
    for scale in (1e-300, 1e-6, 1.0, 1e3, 1e200):
        x = RNG.normal(size=20000) * scale
        y = RNG.normal(size=20000) * scale * RNG.uniform(0, 3, 20000)
        py = [math.hypot(a, b) for a, b in zip(x.tolist(), y.tolist(), strict=True)]
        for a, b, h in zip(x.tolist(), y.tolist(), py, strict=True):
            assert _exact.py_hypot(a, b) == h
        differs += int(np.sum(np.hypot(x, y) != py))
    assert differs > 0  # so the distinction is needed
    big = RNG.uniform(4.5e307, 1.2e308, 2000)  # 2**1022 and over: through frexp
    for a, b in zip(big.tolist(), (big * RNG.uniform(0, 1, 2000)).tolist(), strict=True):
        assert _exact.py_hypot(a, b) == math.hypot(a, b) == _exact.py_hypot(b, -a)
    assert _exact.py_hypot(0.0, 0.0) == 0.0 and _exact.py_hypot(-3.0, 4.0) == 5.0
    assert _exact.py_hypot(math.inf, math.nan) == math.inf


def _paths():
    out = [Path.paper_corner(), Path.paper_circle(), Path.paper_involute()]
    out += [Path.random_smooth(np.random.default_rng(s), n_segments=(3, 6)) for s in range(6)]
    inv = Involute((-20.0, 5.0), 20.0, 0.3, 0.2, 7.5)  # more than a turn: several feet
    line = Line(inv.end, (inv.end[0] + 5.0, inv.end[1] - 2.0))
    out.append(Path([inv, line]))
    a = Arc((0.0, 0.0), 5.0, 0.0, -math.pi)
    out.append(Path([a, Line(a.end, (a.end[0], a.end[1] + 3.0))]))
    # Arcs of more than half a turn, either way: their wedge is the join of two half-planes.
    for sweep in (1.6 * math.pi, -1.3 * math.pi):
        b = Arc((1.0, -2.0), 4.0, 0.5, sweep)
        out += [Path([b]), Path([b, Line(b.end, (b.end[0] + 2.0, b.end[1] + 1.0))])]
    # Arcs of about half a turn, either side of it: the meet of the half-planes below pi,
    # their join from pi on, where the two tests differ least.
    for d in (-0.05, -1e-6, -1e-12, 1e-12, 1e-6, 0.05):
        for sg in (1.0, -1.0):
            out.append(Path([Arc((3.0, 1.0), 6.0, 2.0, sg * (math.pi + d))]))
    return out


@pytest.mark.parametrize("path", _paths(), ids=lambda p: f"{p.name}-{len(p.segments)}")
def test_compiled_geometry_is_the_path_methods(path):
    tab, length = path.table(), path.length
    s = np.concatenate([RNG.uniform(-1.0, length + 1.0, 300), [0.0, length], tab[1:, 1]])
    x, y = path.points(s)
    for k, sk in enumerate(s.tolist()):
        assert paths.path_point(tab, length, sk) == path.point(sk)
        assert paths.path_point(tab, length, sk) == (x[k], y[k])
        assert paths.path_heading(tab, length, sk) == path.headings(np.array([sk]))[0]
        assert paths.path_segment_index(tab, length, sk) == path.segment_index(sk)
    # Points near and far, inside and outside arcs and base circles.
    px = x + RNG.normal(0, 0.05, x.size) * RNG.choice([0.01, 1.0, 100.0], x.size)
    py = y + RNG.normal(0, 0.05, y.size) * RNG.choice([0.01, 1.0, 100.0], y.size)
    for a, b in zip(px.tolist(), py.tolist(), strict=True):
        assert paths.path_distance(tab, a, b) == path.distance(a, b)
    # Many points at once (the feed env's set points): path_point's formulas with the
    # vector sines and cosines, each within one unit in the last place of libm's: a
    # coordinate ``c + R cos`` within R 2**-52 plus its own rounding (twice for the
    # involute's ``R (cos + theta sin)``); a line's points to the last bit.
    xs, ys, scratch = np.empty(s.size), np.empty(s.size), np.empty(3 * s.size)
    paths.path_points(tab, length, s, s.size, xs, ys, scratch)
    scale = max(abs(r[8]) * (1.0 + (abs(r[11]) if r[0] == 2.0 else 0.0)) for r in tab)
    bound = 2.0 * scale * 2.0**-52 + 2.0 * np.spacing(np.maximum(np.abs(x), np.abs(y)))
    assert np.all(np.abs(xs - x) <= bound) and np.all(np.abs(ys - y) <= bound)
    on_lines = np.array([tab[paths.path_segment_index(tab, length, v), 0] == 0.0 for v in s])
    assert xs[on_lines].tobytes() == x[on_lines].tobytes()
    assert ys[on_lines].tobytes() == y[on_lines].tobytes()
    # In increasing order (a block's set points, every segment's start among them), each
    # point's segment is found walking on from the last point's: path_segment_index's (the
    # scratch keeps it), and the same points.
    up = np.argsort(s, kind="stable")
    xo, yo = np.empty(s.size), np.empty(s.size)
    paths.path_points(tab, length, s[up], s.size, xo, yo, scratch)
    segs = [paths.path_segment_index(tab, length, v) for v in s[up]]
    np.testing.assert_array_equal(scratch[2 * s.size :], segs)
    assert xo.tobytes() == xs[up].tobytes() and yo.tobytes() == ys[up].tobytes()
    # A row within one segment (one loop of that segment's formulas) gives the points the
    # row through every segment gives, to the last bit.
    segs = np.array(segs)
    for k in np.unique(segs).tolist():
        within = np.flatnonzero(segs == k)
        sub = s[up][within]
        xk, yk, sk = np.empty(sub.size), np.empty(sub.size), np.empty(3 * sub.size)
        paths.path_points(tab, length, sub, sub.size, xk, yk, sk)
        assert xk.tobytes() == xo[within].tobytes() and yk.tobytes() == yo[within].tobytes()
        assert (sk[2 * sub.size :] == k).all()
    for lo in range(0, px.size - 50, 37):  # blocks of 50 points, as the feed env asks
        n = 50
        out, scratch = np.empty(n), np.empty(n)
        lower, order = np.empty(len(path.segments)), np.empty(len(path.segments), np.int64)
        paths.path_distances(tab, px[lo : lo + n], py[lo : lo + n], n, out, scratch, lower, order)
        # numpy's array kernels (hypot, sqrt) differ by CPU in the last bit, and a distance is
        # a difference of two lengths: equal to 1e-12 mm.
        ref = path.distances(px[lo : lo + n], py[lo : lo + n])
        np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)


def _all_segments(tab, px, py):
    """Each point's least distance over every segment of ``tab``, none skipped."""
    best, d = np.full(px.size, np.inf), np.empty(px.size)
    for row in tab:
        paths._segment_distances(row, px, py, px.size, d)
        best = np.where(d < best, d, best)
    return best


def _blocks(path):
    """Blocks of 50 points as the feed env asks for them (a block's set points along the
    path, the tool's positions near them: close, or up to a tenth of the segments away),
    starting anywhere, at every junction and just before it; and clouds about each arc's
    centre and ends (the edges of its wedge), from tight to as wide as the arc."""
    tab, length = path.table(), path.length
    starts = np.concatenate([RNG.uniform(0.0, length, 30), tab[:, 1], tab[:, 1] - 0.3])
    for s0 in starts.tolist():
        for step, off in ((0.01, 1e-4), (0.1, 0.01), (0.5, 0.3), (2.0, 2.0)):
            x, y = path.points(np.clip(s0 + step * np.arange(50), 0.0, length))
            yield x + RNG.normal(0.0, off, 50), y + RNG.normal(0.0, off, 50)
    for row in tab[tab[:, 0] == 1.0]:
        for cx, cy in ((row[6], row[7]), (row[12], row[13]), (row[14], row[15])):
            for spread in (1e-7, 1e-3, 0.1 * row[8], row[8]):
                yield cx + RNG.normal(0.0, spread, 50), cy + RNG.normal(0.0, spread, 50)


@pytest.mark.parametrize("path", _paths(), ids=lambda p: f"{p.name}-{len(p.segments)}")
def test_distances_skip_no_segment_that_is_nearer(path):
    """``path_distances`` skips a segment by a lower bound of its distance (from a centre
    of the block's points, ``_near_distance``): every block gives each point's least
    distance over all the segments, to the last bit. And the bound is one, rounding
    included: never above the segment's distance, for points anywhere about each
    segment."""
    tab = path.table()
    lower, order = np.empty(len(tab)), np.empty(len(tab), np.int64)
    out, scratch = np.empty(50), np.empty(50)
    for i, (px, py) in enumerate(_blocks(path)):
        paths.path_distances(tab, px, py, 50, out, scratch, lower, order)
        assert out.tobytes() == _all_segments(tab, px, py).tobytes()
        if i < 12:  # a point not finite (the centre's too at 0 and 49): nothing skipped
            bad = (np.nan, np.inf, -np.inf, -np.abs(np.float64(np.nan)))[i % 4]
            j = (0, 17, 49)[i % 3]
            qx = px.copy()
            qx[j] = bad
            paths.path_distances(tab, qx, py, 50, out, scratch, lower, order)
            others = np.arange(50) != j
            assert out[others].tobytes() == _all_segments(tab, qx, py)[others].tobytes()
            assert not np.isfinite(out[j])
    for row in tab:
        cx, cy, r = row[3], row[4], row[5]  # the segment's bounding circle
        for spread in (1e-6 * r, 0.01 * r, r, 10.0 * r):
            for x, y in RNG.normal((cx, cy), spread, (200, 2)).tolist():
                assert paths._near_distance(row, x, y) <= paths._segment_distance(row, x, y)


@pytest.mark.parametrize("kind", ["hinf", "pi"])
def test_block_kernel_is_the_lifted_matrix_product(kind):
    """Unclipped, a block is ``lifted_matrix(...) @ [state, inputs]`` (numpy, BLAS) to
    rounding: the compiled kernel runs the closed loop period by period, so a value after
    period ``j`` carries the roundings of ``j`` periods (each some ten fused multiply-adds
    and three sums, carried on by a stable loop), not BLAS's sum of its row. Bound: 8 units
    in the last place of the sum of the terms' magnitudes (``|big| @ |vec|``) per period
    (the largest seen over 1800 random blocks is 2.4); a wrong coefficient or a missed
    input moves a row by far more."""
    p = ContouringParams()
    designs = tuple(servo_design(kind, p, ax) for ax in "xy")
    for scale in (1.0, 0.8, 1.3):
        truth = p.replace(inertia_x_kgm2=p.inertia_x_kgm2 * scale)
        big = lifted_matrix(truth, designs, 50)
        loop = ServoLoop(truth, designs, 50)
        n = loop.n_states // 2
        # The periods each value has run: positions, velocities, commands, end state.
        periods = np.concatenate([np.tile(np.arange(1, 51), 3), np.full(n, 50)])
        for _ in range(5):
            state = RNG.normal(0, 1e-3, loop.n_states)
            ref = np.cumsum(RNG.normal(0, 0.01, (50, 2)), axis=0)
            load = np.repeat(RNG.uniform(-1, 1, (1, 2)), 50, axis=0)
            vec = np.concatenate([state, ref[:, 0], load[:, 0], ref[:, 1], load[:, 1]])
            want = big @ vec
            bound = 8 * np.finfo(float).eps * (np.abs(big) @ np.abs(vec))
            s = state.copy()
            pos, vel, cmd, _, clipped = loop.run(s, ref, load)
            assert not clipped
            rows = 3 * 50 + 1 + n
            for k in range(2):
                r0 = k * rows
                got = np.concatenate([pos[:, k], vel[:, k], cmd[:, k], s[k * n : k * n + n]])
                sl = np.r_[
                    r0 : r0 + 50, r0 + 51 : r0 + 101, r0 + 101 : r0 + 151, r0 + 151 : r0 + rows
                ]
                err = np.abs(got - want[sl])
                tol = bound[sl] * periods
                assert np.all(err <= tol), (k, np.max(err / tol))
                # and a coefficient off by one part in 1e9 is seen
                assert np.max(np.abs(want[sl]) * 1e-9) > np.max(tol)


def _bits(x):
    return np.ascontiguousarray(x, dtype=np.float64).view(np.int64)


@pytest.mark.parametrize("kind", ["hinf", "pi"])
@pytest.mark.parametrize("generic", [False, True])
def test_eight_lanes_at_once_are_run_block_to_the_last_bit(kind, generic):
    """``run_lanes`` (the lanes side by side) gives each lane ``run_block``'s numbers to the
    last bit: positions, velocities, commands, torques and end states, over lanes on their
    own plants, clipped commands, a lane with NaN inputs (the same values NaN, the others
    equal), and a group of fewer than eight lanes after a full one (the places left over
    hold zeros, a zero state and zero inputs: they stay at rest).
    ``generic``: the kernel compiled for any number of states (``ns`` 8, the rows past the
    design's zero), where the designs' own have theirs unrolled."""
    p = ContouringParams()
    designs = tuple(servo_design(kind, p, ax) for ax in "xy")
    nb, n = 50, 13
    lanes = ServoLanes(designs, nb, n)
    for k in range(n):
        lanes.start(
            k,
            p.replace(
                inertia_x_kgm2=p.inertia_x_kgm2 * RNG.uniform(0.7, 1.4),
                inertia_y_kgm2=p.inertia_y_kgm2 * RNG.uniform(0.7, 1.4),
            ),
        )
    ns = lanes.n_states_axis
    state = RNG.normal(0, 1e-3, (n, 2 * ns))
    ref = np.cumsum(RNG.normal(0, 0.02, (n, nb, 2)), axis=1)
    load = RNG.uniform(-1, 1, (n, nb, 2))
    ref[2, 20:, 0] += 50.0  # a step far past what the drive can follow: clipped commands
    ref[4, 30:, 1] -= 50.0
    ref[9, 7, 1] = np.nan  # NaN from period 7 on
    # run_block, lane by lane
    want = [
        np.empty((n, nb, 2)),
        np.empty((n, nb + 1, 2)),
        np.empty((n, nb, 2)),
        np.empty((n, nb, 2)),
    ]
    want_state = state.copy()
    clipped = []
    for k in range(n):
        ac, bc, cu, du, gu, tq, umax = lane_loops(lanes.buf[k])
        block = ServoBlock(ref[k], load[k], *(w[k] for w in want))
        loop = (ac, bc, cu, du, gu, tq, umax[0])
        clipped.append(run_block(loop, want_state[k], block, np.zeros(16)))
    assert clipped[2] and clipped[4] and not clipped[0]
    # run_lanes, LANES at a time ([row, axis, place] arrays)
    z = np.zeros(LANES_STATE_SIZE)
    got_state = state.copy()
    for k0 in range(0, n, LANES):
        m = min(LANES, n - k0)
        g_ref = np.zeros((nb, 2, LANES))
        g_load = np.zeros((nb, 2, LANES))
        g_ref[:, :, :m] = ref[k0 : k0 + m].transpose(1, 2, 0)
        g_load[:, :, :m] = load[k0 : k0 + m].transpose(1, 2, 0)
        outs = [
            np.full((nb, 2, LANES), 7.0),
            np.full((nb + 1, 2, LANES), 7.0),
            np.full((nb, 2, LANES), 7.0),
            np.full((nb, 2, LANES), 7.0),
        ]
        gather_states(got_state, k0, m, z)
        run_lanes(
            lanes.groups[k0 // LANES],
            8 if generic else ns,
            nb,
            z,
            g_ref.ravel(),
            g_load.ravel(),
            outs[0].reshape(-1),
            outs[1].reshape(-1),
            outs[2].reshape(-1),
            outs[3].reshape(-1),
        )
        scatter_lanes(got_state, k0, m, z)
        for g, w in zip(outs, want, strict=True):
            got = g[:, :, :m].transpose(2, 0, 1)
            np.testing.assert_array_equal(np.isnan(got), np.isnan(w[k0 : k0 + m]))
            fin = ~np.isnan(got)
            assert np.array_equal(_bits(got[fin]), _bits(w[k0 : k0 + m][fin]))
            if m < LANES:  # the places without a lane stayed at rest
                assert not np.any(g[:, :, m:])
    assert np.isnan(want_state[9, ns:]).all()  # the Y axis (the axes are apart)
    np.testing.assert_array_equal(np.isnan(got_state), np.isnan(want_state))
    fin = ~np.isnan(want_state)
    assert np.array_equal(_bits(got_state[fin]), _bits(want_state[fin]))


def test_row_largest_is_the_largest_or_the_last_nan():
    """``row_largest`` (the peak contour error; the distances' skip test) is the largest
    value of a row, or its last NaN, to the last bit: rows of distances (+0 to +inf, the
    path through the values' bits) and rows with a NaN of either sign, a negative value or
    -0 (value by value)."""

    def want(row):
        m = row[0]
        for v in row[1:]:
            if v > m or v != v:
                m = v
        return m

    nan_neg = -np.abs(np.float64(np.nan))  # x86's default NaN: the sign bit set
    specials = [0.0, np.inf, 5e-324, 1e300, np.nan, nan_neg, -0.0, -1.0, -np.inf]
    rows = [RNG.uniform(0, 2, n) for n in (1, 2, 7, 8, 9, 50, 64)]
    for n in (1, 3, 50):
        for v in specials:
            for at in {0, n // 2, n - 1}:
                row = RNG.uniform(0, 2, n)
                row[at] = v
                rows.append(row)
    row = RNG.uniform(0, 2, 50)
    row[[3, 40]] = [np.nan, nan_neg]  # two NaNs: the last one's bits
    rows.append(row)
    row = RNG.uniform(0, 2, 50)
    row[[3, 40]] = np.array([0x7FF8000000000001, 0x7FF8000000000000]).view(np.float64)
    rows.append(row)  # two NaNs, both of the sign bit clear
    for row in rows:
        got, ref = paths.row_largest(row, row.size), want(row)
        assert _bits(np.array([got])) == _bits(np.array([ref])), (row, got, ref)
