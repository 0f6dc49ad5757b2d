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
