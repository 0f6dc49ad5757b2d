"""Exact discretisation of linear time-invariant blocks, done once at construction.

The plants keep their linear parts (servo drives, sensor filters) in continuous-time state
space and discretise them here with a zero-order hold (ZOH), exactly, through the matrix
exponential. What runs every step is then a handful of small numpy products.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

__all__ = ["zoh", "zoh_tf", "critical_gain", "butterworth_lowpass"]


def zoh(a: np.ndarray, b: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation of ``dx/dt = A x + B u`` over ``dt``.

    Returns ``(Phi, Gamma)`` with ``x[k+1] = Phi x[k] + Gamma u[k]`` when ``u`` is held
    constant over the interval: ``Phi = e^{A dt}``, ``Gamma = int_0^dt e^{A s} ds B``, both read
    off one exponential of the block matrix ``[[A, B], [0, 0]] dt``.

    The blocks here are a few rows square (4x4 for the resets that discretise a lane's
    plant), far below the sizes at which OpenBLAS uses its threads, so the exponential
    runs as it is: limiting them to one around each call cost a third more time and did
    not shorten its tail on a loaded machine (median 52 -> 70-80 us; the 99th
    percentile, some ms under two busy processes, set by the scheduler either way).
    """
    a = np.atleast_2d(np.asarray(a, dtype=np.float64))
    b = np.asarray(b, dtype=np.float64).reshape(a.shape[0], -1)
    if not dt > 0:
        raise ValueError(f"dt must be > 0, got {dt!r}")
    n, m = b.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n] = a
    block[:n, n:] = b
    e = expm(block * dt)
    return e[:n, :n], e[:n, n:]


def zoh_tf(num, den, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """ZOH-discretise a transfer function; coefficients in powers of ``z^-1``, ``den[0] = 1``."""
    from scipy.signal import cont2discrete  # here: scipy.signal takes seconds to import

    numd, dend, _ = cont2discrete((num, den), dt, method="zoh")
    numd = np.atleast_1d(np.squeeze(numd))
    dend = np.atleast_1d(np.squeeze(dend))
    return numd / dend[0], dend / dend[0]


def butterworth_lowpass(cutoff_hz: float, order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous state-space ``(A, B, C)`` of a unit-DC-gain Butterworth low-pass filter.

    Controllable canonical form of ``wc^n / B_n(s)``; ``order`` 1 or 2 (the 2nd-order form
    ``wc^2 / (s^2 + sqrt(2) wc s + wc^2)`` is the usual -12 dB/octave strain-amplifier filter).
    """
    wc = 2.0 * np.pi * cutoff_hz
    if order == 1:
        return np.array([[-wc]]), np.array([[wc]]), np.array([1.0])
    if order == 2:
        a = np.array([[0.0, 1.0], [-(wc**2), -np.sqrt(2.0) * wc]])
        return a, np.array([[0.0], [wc**2]]), np.array([1.0, 0.0])
    raise ValueError(f"order must be 1 or 2, got {order!r}")


def critical_gain(num_z, den_z, k_max: float = 1e3) -> float:
    """Smallest loop gain ``K > 0`` at which ``den + K num`` has a root on the unit circle.

    ``num_z`` and ``den_z`` are the open-loop numerator and denominator in powers of ``z^-1``
    (equal length after padding). The closed loop is stable for ``0 < K < critical_gain``:
    the value a root-locus plot such as Noh, Kim & Kim (1992) Fig. 4 reads off by eye. Found
    by a logarithmic scan for the first unstable gain, then bisection to 1e-10 relative.
    """
    num = np.asarray(num_z, dtype=np.float64)
    den = np.asarray(den_z, dtype=np.float64)
    size = max(num.size, den.size)
    num = np.pad(num, (0, size - num.size))
    den = np.pad(den, (0, size - den.size))

    def radius(k: float) -> float:
        return float(np.max(np.abs(np.roots(den + k * num))))

    if radius(1e-9) >= 1.0:
        return 0.0
    grid = np.geomspace(1e-6, k_max, 400)
    lo = 1e-9
    for k in grid:
        if radius(k) >= 1.0:
            hi = k
            break
        lo = k
    else:
        return float("inf")
    while hi - lo > 1e-10 * hi:
        mid = 0.5 * (lo + hi)
        if radius(mid) < 1.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
