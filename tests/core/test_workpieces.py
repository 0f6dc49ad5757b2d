"""Depth profiles (``machining_envs.core.workpieces``): steps, tapers, random draws, checks."""

import numpy as np
import pytest

from machining_envs.core.workpieces import DepthProfile


def test_depth_profiles():
    prof = DepthProfile.steps((1.0, 2.0, 3.0), 10.0)
    np.testing.assert_allclose(prof([-1.0, 0.0, 9.99, 10.0, 25.0, 30.0]), [0, 1, 1, 2, 3, 0])
    assert prof.change_positions_mm() == (10.0, 20.0)
    taper = DepthProfile.taper(1.0, 3.0, 40.0)
    assert taper(20.0) == pytest.approx(2.0)
    rng = np.random.default_rng(1)
    for _ in range(200):
        r = DepthProfile.random(rng)
        ends = np.array(r.end_depths_mm[:-1])
        starts = np.array(r.start_depths_mm[1:])
        assert np.all(np.maximum(starts / ends, ends / starts) <= 2.5 + 1e-12)
    with pytest.raises(ValueError, match="edges_mm"):
        DepthProfile((0.0, 5.0, 3.0), (1.0, 1.0), (1.0, 1.0))
    with pytest.raises(ValueError, match="start_depths_mm"):
        DepthProfile((0.0, 5.0), (-1.0,), (1.0,))


def test_random_profiles_are_those_the_public_constructor_makes():
    """``random`` builds its profiles without checking them again (they are valid by
    construction): each equals, field for field and in every table, the profile the checked
    constructor makes of the same numbers, and survives pickling."""
    import pickle

    rng = np.random.default_rng(7)
    ranges = [((0.5, 3.0), (2, 5), (4.0, 12.0)), ((0.4, 3.5), (1, 6), (5, 12))]
    for i in range(300):
        depth, segments, lengths = ranges[i % 2]
        p = DepthProfile.random(rng, depth, segments, lengths, 0.3, name="drawn")
        q = DepthProfile(p.edges_mm, p.start_depths_mm, p.end_depths_mm, "drawn")
        assert p == q
        assert p.segment_table() == q.segment_table()
        assert all(type(v) is float for v in p.edges_mm + p.start_depths_mm + p.end_depths_mm)
        x = np.linspace(-1.0, p.length_mm + 1.0, 97)
        np.testing.assert_array_equal(p(x), q(x))
        assert p.traverse_time_s(0.3, 0.7, 5.0) == q.traverse_time_s(0.3, 0.7, 5.0)
        np.testing.assert_array_equal(p.segment_array(), q.segment_array())
        assert not p.segment_array().flags.writeable and not q.segment_array().flags.writeable
        back = pickle.loads(pickle.dumps(p))
        assert back.segment_table() == q.segment_table()
        np.testing.assert_array_equal(back.segment_array(), q.segment_array())
        assert not back.segment_array().flags.writeable


def _reference_random(rng, lo, hi, n_segments, s_lo, s_hi, taper_p, max_jump):
    """``DepthProfile.random``'s draws and arithmetic written out plainly in Python."""
    n = int(rng.integers(n_segments[0], n_segments[1] + 1))
    lengths, starts_u, taper_u, ends_u = rng.random((4, n)).tolist()
    edges, starts, ends = [0.0], [], []
    for k in range(n):
        edges.append(edges[-1] + s_lo + (s_hi - s_lo) * lengths[k])
        a, b = (lo, hi) if k == 0 else (max(lo, ends[-1] / max_jump), min(hi, ends[-1] * max_jump))
        starts.append(a + (b - a) * starts_u[k])
        ends.append(lo + (hi - lo) * ends_u[k] if taper_u[k] < taper_p else starts[-1])
    return tuple(edges), tuple(starts), tuple(ends)


@pytest.mark.parametrize(
    "ranges",
    [
        ((0.5, 3.0), (2, 5), (4.0, 12.0), 0.3, 2.5),
        ((0.5, 3.5), (2, 6), (5.0, 12.0), 0.3, 2.5),
        ((0.4, 3.5), (1, 8), (1.0, 30.0), 1.0, 1.1),
    ],
)
def test_random_profiles_draw_the_numbers_of_their_description(ranges):
    """The compiled arithmetic of ``random`` gives, to the last bit, the profile its plain
    description gives from the same generator state (so the splits' fixed episodes stay
    what they are)."""
    (lo, hi), segments, (s_lo, s_hi), taper_p, jump = ranges
    for seed in range(400):
        p = DepthProfile.random(
            np.random.default_rng(seed), (lo, hi), segments, (s_lo, s_hi), taper_p, jump
        )
        ref = _reference_random(
            np.random.default_rng(seed), lo, hi, segments, s_lo, s_hi, taper_p, jump
        )
        assert (p.edges_mm, p.start_depths_mm, p.end_depths_mm) == ref


def test_random_profile_refuses_bad_ranges():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="segment_mm must satisfy 0 < lo <= hi"):
        DepthProfile.random(rng, segment_mm=(0.0, 5.0))
    with pytest.raises(ValueError, match="segment_mm must satisfy 0 < lo <= hi"):
        DepthProfile.random(rng, segment_mm=(6.0, 5.0))
    with pytest.raises(ValueError, match="segment_mm"):
        DepthProfile.random(rng, segment_mm=(1.0, np.inf))
    with pytest.raises(ValueError, match="n_segments must be a range of integers >= 1"):
        DepthProfile.random(rng, n_segments=(0, 0))


def test_the_ranges_a_factory_checks_once_are_those_random_checks():
    DepthProfile.check_random_ranges((0.5, 3.0), (2, 5), (4.0, 12.0))
    for bad, match in [
        (((0.0, 3.0), (2, 5), (4.0, 12.0)), "depth_range_mm"),
        (((0.5, 3.0), (0, 5), (4.0, 12.0)), "n_segments"),
        (((0.5, 3.0), (3, 2), (4.0, 12.0)), "n_segments"),
        (((0.5, 3.0), (2, 5), (0.0, 12.0)), "segment_mm"),
    ]:
        with pytest.raises(ValueError, match=match):
            DepthProfile.check_random_ranges(*bad)
    with pytest.raises(ValueError, match="max_jump_ratio"):
        DepthProfile.check_random_ranges((0.5, 3.0), (2, 5), (4.0, 12.0), 1.0)
