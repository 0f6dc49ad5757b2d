"""Toolpaths and the contour error against closed forms and brute force."""

import math

import numpy as np
import pytest

from machining_envs.contouring.paths import Arc, Involute, Line, Path


def _brute(path: Path, px, py, n=200_001):
    s = np.linspace(0.0, path.length, n)
    x, y = path.points(s)
    return np.array([np.min(np.hypot(x - a, y - b)) for a, b in zip(px, py, strict=True)])


def test_distance_to_a_circle_is_radial_offset():
    path = Path.paper_circle()  # R = 10 mm about the origin, a full turn
    rng = np.random.default_rng(0)
    ang = rng.uniform(-math.pi, math.pi, 200)
    rho = rng.uniform(0.01, 25.0, 200)
    px, py = rho * np.cos(ang), rho * np.sin(ang)
    expected = np.abs(rho - 10.0)
    scalar = np.array([path.distance(a, b) for a, b in zip(px, py, strict=True)])
    np.testing.assert_allclose(scalar, expected, atol=1e-12)
    np.testing.assert_allclose(path.distances(px, py), expected, atol=1e-12)
    # At the centre every point of the circle is R away.
    assert path.distance(0.0, 0.0) == pytest.approx(10.0)


def test_distance_to_a_line_segment():
    path = Path.line((1.0, 2.0), (7.0, 10.0))  # length 10, direction (0.6, 0.8)
    n = np.array([-0.8, 0.6])
    for t, d in [(0.0, 0.3), (5.0, -1.7), (10.0, 2.0), (2.5, 0.0)]:
        p = np.array([1.0, 2.0]) + t * np.array([0.6, 0.8]) + d * n
        assert path.distance(*p) == pytest.approx(abs(d), abs=1e-12)
    # Beyond the ends: the distance to the nearer end point.
    p = np.array([1.0, 2.0]) - 3.0 * np.array([0.6, 0.8]) + 4.0 * n
    assert path.distance(*p) == pytest.approx(5.0)
    p = np.array([7.0, 10.0]) + 6.0 * np.array([0.6, 0.8]) - 8.0 * n
    assert path.distance(*p) == pytest.approx(10.0)


def test_distance_to_an_arc_outside_its_range_is_to_the_nearer_end():
    arc = Path([Arc((0.0, 0.0), 5.0, 0.0, 0.5 * math.pi)])  # quarter circle (5,0)->(0,5)
    assert arc.distance(7.0, 7.0) == pytest.approx(math.hypot(7, 7) - 5.0)
    # Below the x axis: nearest is the start (5, 0).
    assert arc.distance(6.0, -3.0) == pytest.approx(math.hypot(1.0, 3.0))
    assert arc.distance(-2.0, 1.0) == pytest.approx(math.hypot(2.0, 4.0))
    cw = Path([Arc((0.0, 0.0), 5.0, 0.0, -0.5 * math.pi)])  # (5,0) -> (0,-5) clockwise
    assert cw.distance(3.0, -3.0) == pytest.approx(abs(math.hypot(3, 3) - 5.0))
    assert cw.distance(-1.0, 4.0) == pytest.approx(math.hypot(6.0, 4.0))


def test_distance_to_an_involute_along_its_normal():
    """A point offset by d along the involute's normal at theta0 is |d| away.

    The involute's normal at theta is along (sin phi, -cos phi), phi = theta + theta1, and it
    is tangent to the base circle; closed form, independent of the implementation's
    tangent construction.
    """
    r = 50.0
    inv = Involute((-50.0, 0.0), r, theta1=0.3, theta_start=0.0, theta_end=2.0)
    path = Path([inv])
    for th0, d in [(0.4, 0.2), (1.0, -0.5), (1.7, 1.0), (0.9, 0.0), (1.3, -2.0)]:
        phi = th0 + 0.3
        q = np.array(inv.point_at(th0))
        p = q + d * np.array([math.sin(phi), -math.cos(phi)])
        assert path.distance(*p) == pytest.approx(abs(d), abs=1e-9)
        dv, qx, qy = path.closest_many(np.array([p[0]]), np.array([p[1]]))
        assert dv[0] == pytest.approx(abs(d), abs=1e-9)
        np.testing.assert_allclose([qx[0], qy[0]], q, atol=1e-9)
    # Arc length: s = R theta^2 / 2 from theta = 0, so theta = sqrt(2 F t / R) at feed F.
    assert inv.length == pytest.approx(0.5 * r * 4.0)
    f, t = 50.0, 0.7
    x, y = path.points(np.array([f * t]))
    np.testing.assert_allclose([x[0], y[0]], inv.point_at(math.sqrt(2 * f * t / r)), atol=1e-12)


@pytest.mark.parametrize(
    "path",
    [
        Path.paper_corner(),
        Path.paper_circle(),
        Path.paper_involute(),
        Path([Involute((0.0, 0.0), 5.0, 1.0, 0.5, 9.0)]),  # more than one turn
        Path.random_smooth(np.random.default_rng(3), n_segments=(5, 5)),
    ],
    ids=["corner", "circle", "involute", "involute_turns", "random"],
)
def test_exact_distance_matches_brute_force(path):
    rng = np.random.default_rng(1)
    xmin, xmax, ymin, ymax = path.bounds()
    px = rng.uniform(xmin - 5, xmax + 5, 150)
    py = rng.uniform(ymin - 5, ymax + 5, 150)
    brute = _brute(path, px, py)
    exact = np.array([path.distance(a, b) for a, b in zip(px, py, strict=True)])
    # The brute force samples the path every length/200000 (< 1 um): it can only be longer.
    assert np.all(exact <= brute + 1e-12)
    np.testing.assert_allclose(exact, brute, atol=2e-6)
    np.testing.assert_allclose(path.distances(px, py), exact, atol=1e-12)


def test_paper_paths():
    corner = Path.paper_corner()
    assert corner.length == pytest.approx(100.0)
    np.testing.assert_allclose(corner.segments[0].end, (35.3553, 35.3553), atol=1e-4)
    np.testing.assert_allclose(corner.end, (70.7107, 0.0), atol=1e-4)
    circle = Path.paper_circle()
    assert circle.length == pytest.approx(20 * math.pi) and circle.start == (10.0, 0.0)
    assert circle.circle() == (0.0, 0.0, 10.0)
    inv = Path.paper_involute()
    assert inv.start == pytest.approx((0.0, 0.0)) and inv.circle() is None
    assert inv.length == pytest.approx(0.5 * 50 * (math.pi / 2) ** 2)


def test_random_smooth_paths_are_tangent_continuous_and_seeded():
    a = Path.random_smooth(np.random.default_rng(7))
    b = Path.random_smooth(np.random.default_rng(7))
    assert repr(a.segments) == repr(b.segments)
    for _ in range(20):
        p = Path.random_smooth(np.random.default_rng(_))
        joints = np.cumsum([s.length for s in p.segments])[:-1]
        eps = 1e-7
        before = p.headings(joints - eps)
        after = p.headings(joints + eps)
        np.testing.assert_allclose(before, after, atol=1e-5)  # no corners
        x0, y0 = p.points(joints - eps)
        x1, y1 = p.points(joints + eps)
        assert np.max(np.hypot(x1 - x0, y1 - y0)) < 1e-6  # continuous


def test_random_smooth_builds_what_the_checked_constructors_build():
    """random_smooth skips re-checking what it drew (a reset builds a path); the path is the
    one the public, checked constructors make of the same numbers, to the last bit."""
    for seed in range(30):
        p = Path.random_smooth(np.random.default_rng(seed), n_segments=(1, 8), name="r")
        segs = [
            Line(s.start, s.end)
            if isinstance(s, Line)
            else Arc(s.center, s.radius, s.start_angle, s.sweep)
            for s in p.segments
        ]
        q = Path(segs, name="r")
        for a, b in zip(p.segments, q.segments, strict=True):
            assert vars(a) == vars(b) and all(type(v) is not np.float64 for v in vars(a).values())
        assert p.table().tobytes() == q.table().tobytes() and not p.table().flags.writeable
        assert p._bounds == q._bounds and p._start_list == q._start_list
        assert (p.length, p.start, p.end, p.name) == (q.length, q.start, q.end, q.name)
        assert p._heading_starts.tobytes() == q._heading_starts.tobytes()
    # numpy bounds give the same Python floats as Python ones.
    a = Path.random_smooth(np.random.default_rng(3), line_mm=(5.0, 30.0), radius_mm=(3.0, 30.0))
    b = Path.random_smooth(
        np.random.default_rng(3), line_mm=np.array([5.0, 30.0]), radius_mm=np.array([3.0, 30.0])
    )
    assert repr(a.segments) == repr(b.segments)
    with pytest.raises(ValueError, match="distinct"):  # a drawn line too short is still refused
        Path.random_smooth(np.random.default_rng(0), line_mm=(1e-12, 1e-12), line_probability=1.0)


def _segments_at_scales(rng):
    """Lines, arcs (every sweep, half a turn and just either side of it included) and
    involutes, about the origin or far from it, tiny to huge."""
    segs = []
    for scale in (1e-150, 1e-6, 1.0, 1e3, 1e150, 1e160):
        sweeps = [*rng.uniform(0.01, 6.28, 8), math.pi, math.pi - 1e-9, math.pi + 1e-9]
        for sweep in sweeps:
            c = tuple(rng.normal(size=2) * scale * 10 ** rng.uniform(-3, 3))
            r = scale * rng.uniform(0.01, 10)
            sign = rng.choice([-1, 1])
            segs.append(Arc(c, r, rng.uniform(-7, 7), sweep * sign))
            segs.append(Involute(c, r, rng.uniform(-7, 7), 0.0, rng.uniform(0.01, 20)))
            if scale >= 1e-6:
                segs.append(Line(c, tuple(np.add(c, rng.normal(size=2) * scale))))
    return segs


def test_bounding_circles_hold_their_segments():
    """Each row's bounding circle (table columns 3-5) holds its whole segment: the contour
    error skips segments by it. Paths as drawn, and single segments of every kind and
    sweep at every scale (5001 points along each)."""
    from machining_envs.contouring.paths import _bounding_circle

    rng = np.random.default_rng(2)
    paths = [Path.random_smooth(rng, n_segments=(6, 6)) for _ in range(5)]
    paths += [Path.paper_involute(), Path.paper_corner(), Path.paper_circle()]
    for p in paths:
        for seg, (cx, cy, r) in zip(p.segments, p.table()[:, 3:6], strict=True):
            assert (cx, cy, r) == _bounding_circle(seg)
            x, y = seg.points(np.linspace(0.0, seg.length, 5001))
            assert np.max(np.hypot(x - cx, y - cy)) <= r
    for seg in _segments_at_scales(rng):
        cx, cy, r = _bounding_circle(seg)
        x, y = seg.points(np.linspace(0.0, seg.length, 5001))
        assert np.max(np.hypot(x - cx, y - cy)) <= r


def test_bounding_circles_of_lines_and_arcs_are_the_least():
    """A line's and an arc's bounding circle is the least that holds it, but for the
    widening (1e-9 of the segment's magnitudes): the midpoint and half length; the circle
    on the chord of an arc of half a turn or less; the arc's own circle beyond."""
    from machining_envs.contouring.paths import _bounding_circle

    for seg in _segments_at_scales(np.random.default_rng(3)):
        if isinstance(seg, Involute):
            continue
        cx, cy, r = _bounding_circle(seg)
        if isinstance(seg, Line):
            (x0, y0), (x1, y1) = seg.start, seg.end
            size = abs(x0) + abs(y0) + seg.length
            least = (0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * seg.length)
        elif abs(seg.sweep) <= math.pi:
            (x0, y0), (x1, y1) = seg.start, seg.end
            size = abs(seg.center[0]) + abs(seg.center[1]) + seg.radius
            least = (0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * math.hypot(x1 - x0, y1 - y0))
        else:
            size = abs(seg.center[0]) + abs(seg.center[1]) + seg.radius
            least = (*seg.center, seg.radius)
        tol = 1e-12 * size
        assert abs(cx - least[0]) <= tol and abs(cy - least[1]) <= tol
        assert least[2] < r <= least[2] + 1.01e-9 * size


def test_bounding_circles_of_involutes_are_numpys_to_the_last_bit():
    """An involute's compiled bounding circle (which takes hypot only near the largest sums
    of squares) gives numpy's numbers over 257 points, at any scale."""
    from machining_envs.contouring.paths import _bounding_circle

    for seg in _segments_at_scales(np.random.default_rng(4)):
        if not isinstance(seg, Involute):
            continue
        x, y = seg.points(np.linspace(0.0, seg.length, 257))
        cx, cy = np.mean(x), np.mean(y)
        far = np.max(np.hypot(x - cx, y - cy))
        gap = np.max(np.hypot(np.diff(x), np.diff(y)))
        assert _bounding_circle(seg) == (cx, cy, far + gap)


def test_headings_and_scalar_queries_agree_with_vector_ones():
    p = Path.random_smooth(np.random.default_rng(11), n_segments=(6, 6))
    s = np.linspace(0.0, p.length, 301)
    x, y = p.points(s)
    for k in range(0, 301, 10):
        assert p.point(s[k]) == pytest.approx((x[k], y[k]), abs=1e-12)
        assert p.segment_index(s[k]) == int(p._index(s[k : k + 1])[0])
    # Heading = direction of motion (finite differences away from joints).
    h = p.headings(s[1:-1])
    fd = np.arctan2(np.gradient(y, s), np.gradient(x, s))[1:-1]
    err = np.angle(np.exp(1j * (h - fd)))
    assert np.percentile(np.abs(err), 90) < 1e-3
    # The corner turns right by 90 degrees.
    c = Path.paper_corner()
    assert c.headings(np.array([c.length]))[0] - c.headings(np.array([0.0]))[0] == pytest.approx(
        -0.5 * math.pi
    )


def test_bad_paths_raise_naming_the_problem():
    with pytest.raises(ValueError, match="continuous"):
        Path([Line((0, 0), (1, 0)), Line((2, 0), (3, 0))])
    with pytest.raises(ValueError, match="radius"):
        Arc((0, 0), -1.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="sweep"):
        Arc((0, 0), 1.0, 0.0, 7.0)
    with pytest.raises(ValueError, match="distinct"):
        Line((1, 1), (1, 1))
    with pytest.raises(ValueError, match="theta_start"):
        Involute((0, 0), 1.0, 0.0, 2.0, 1.0)
    with pytest.raises(ValueError, match="start"):
        Line((math.nan, 0), (1, 0))
    with pytest.raises(ValueError, match="segments"):
        Path([])
    with pytest.raises(ValueError, match="n_segments"):
        Path.random_smooth(np.random.default_rng(0), n_segments=(0, 3))
