"""The shared linear-systems tools (``machining_envs.core.lti``) against closed forms."""

import numpy as np
import pytest

from machining_envs.core.lti import butterworth_lowpass, critical_gain, zoh


def test_critical_gain_of_a_known_loop():
    # L(z) = K z^-1 / (1 - 0.5 z^-1): pole 0.5 - K, unstable past K = 1.5.
    assert critical_gain([0.0, 1.0], [1.0, -0.5]) == pytest.approx(1.5, rel=1e-8)


def test_zoh_matches_scalar_closed_form():
    phi, gam = zoh(np.array([[-2.0]]), np.array([[3.0]]), 0.1)
    assert phi[0, 0] == pytest.approx(np.exp(-0.2))
    assert gam[0, 0] == pytest.approx(1.5 * (1 - np.exp(-0.2)))


def test_butterworth_half_power_at_cutoff():
    a, b, c = butterworth_lowpass(10.0, 2)
    w = 2 * np.pi * 10.0
    h = c @ np.linalg.solve(1j * w * np.eye(2) - a, b)
    assert abs(h[0]) == pytest.approx(1 / np.sqrt(2), rel=1e-9)
    assert abs(c @ np.linalg.solve(-a, b))[0] == pytest.approx(1.0)
