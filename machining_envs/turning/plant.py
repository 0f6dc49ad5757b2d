r"""Turning plant of Noh, Kim & Kim (1992): feed servo, feed per revolution, force, sensor.

The chain of their Fig. 1, from the controller's command ``U`` to the measured force ``Fc``:

.. math::

    V_s(s) &= \frac{K_s \omega_n^2}{s^2 + 2\zeta\omega_n s + \omega_n^2} U(s)
        \quad &\text{(eq. 1, feed servo)} \\
    V_f &= K_m V_s \quad &\text{(eq. 2, gear train, mm/s)} \\
    f(t) &= \int_{t-T}^{t} V_f(z)\,dz,\quad T = 60/n \quad &\text{(eq. 4, feed per rev)} \\
    F &= K_f f^{p} a \quad &\text{(eq. 8, cutting force, N)} \\
    F_c &= K_e \, \mathrm{LPF}_{10\,Hz}(F) \quad &\text{(eq. 10, sensor, counts)}

The moving integral of eq. (4) is simulated exactly, not through the Padé form of eq. (7):
the servo and the running integral ``I(t) = \int_0^t V_f`` form one linear system driven by
the held command, discretised exactly on a sub-step grid ``h = Ts / substeps``; the value
``I(t - T)`` between grid points comes from the exact transition over the fractional offset.
Only the force law and the sensor filter input are evaluated on the sub-step grid.

This module imports numpy and scipy only; it knows nothing of gymnasium.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from machining_envs.core.checks import (
    CheckedParams,
    check_integer,
    check_range,
    checked_params,
    fields_of,
    ranged,
    ranged_int,
)
from machining_envs.core.compiled.kernels import fma, matvec, powers, read_only, row_max, row_min
from machining_envs.core.compiled.schema import gather, record
from machining_envs.core.lti import butterworth_lowpass, zoh, zoh_tf
from machining_envs.core.workpieces import SegmentTables, SingleCut, load_segments

__all__ = [
    "TurningParams",
    "TurningPlant",
    "TurningStep",
    "SPINDLE_RPM_RANGE",
    "sampled_model",
    "unit_plant_coefficients",
    "spindle_drive",
    "cutting_power_W",
]

#: Spindle speeds the plant accepts, rpm. A conventional lathe of the paper's size (2.2 kW
#: spindle) runs from a few tens to a few thousand rpm; outside this the moving-integral
#: history (T = 60/n) or the 10 Hz sensor filter would no longer describe the machine.
SPINDLE_RPM_RANGE = (50.0, 3000.0)


#: The range check of this process's parameters and scenarios (a bool is not a number).
_check = check_range


@checked_params()
@dataclass(frozen=True)
class TurningParams(CheckedParams):
    """Identified parameters of the turning plant (Noh, Kim & Kim 1992, seed 001).

    Every field is a physical constant with its unit; derived quantities (rad/s, the
    process gain ``Kp`` of eq. 11, discrete matrices) are computed from the fields.
    """

    servo_gain: float = ranged(0.0, 1e6, default=0.66, lo_open=True)
    """Ks, servo gain from command counts to feed-rod speed, eq. (1); Fig. 2 Bode fit.
    (The OCR'd text calls it "K_f = 0.66"; it is the servo gain.)"""

    servo_natural_freq_hz: float = ranged(0.0, 1e3, default=2.66, lo_open=True)
    """wn of the feed servo, Hz, eq. (1); Fig. 2 (2.66 Hz = 16.71 rad/s)."""

    servo_damping: float = ranged(0.0, 10.0, default=0.43, lo_open=True)
    """zeta of the feed servo, eq. (1); Fig. 2."""

    gear_ratio: float = ranged(0.0, 1e3, default=0.0021414, lo_open=True)
    """Km, gear train from feed-rod speed to tool feed velocity, eq. (2)."""

    force_coefficient: float = ranged(0.0, 1e6, default=1822.0, lo_open=True)
    """Kf, N per (mm/rev)^p per mm of depth, eq. (8); log-linear least squares, Fig. 3."""

    feed_exponent: float = ranged(0.0, 2.0, default=0.7525, lo_open=True)
    """p, feed exponent of the force law, eq. (8); Fig. 3."""

    sensor_gain: float = ranged(0.0, 1e6, default=17.0, lo_open=True)
    """Ke, ADC counts per newton, eq. (10). Not given in the paper: calibrated here as one
    value for which the simulation shows all five behaviours of Fig. 8-15 under the criteria
    of ``agents.bench.turning`` (unstable: breakage or oscillation over 10 % of Fr; slow: first
    entry into the 5 % band later than 3 s after the start). On the 15 mm-per-step bar the
    strict reading ("Kh = 0.04 unstable from 2 mm on") holds for Ke from 17 to 19 counts/N;
    17 is taken. ``machining-bench reproduce turning --sensor-gain K`` explores others."""

    sensor_cutoff_hz: float = ranged(0.0, 1e4, default=10.0, lo_open=True)
    """Cut-off of the dynamometer amplifier's low-pass filter, Hz (paper §4.1)."""

    sensor_filter_order: int = 2
    """Order of that filter. Not given: 2 (Butterworth, -12 dB/oct) is the usual filter of a
    strain amplifier such as the Kyowa DPM-310B the paper used."""

    sample_time_s: float = ranged(0.0, 10.0, default=0.1, lo_open=True)
    """Ts, controller sample time, s (paper §4.1: above the algorithm's run time, below the
    0.188 s the servo's natural frequency allows)."""

    substeps: int = ranged_int(1, 10000, default=50)
    """Sub-steps per sample on which force and filter input are evaluated (h = 2 ms: 8x finer
    than the 16 ms time constant of the 10 Hz filter). Chosen; see ``tests/turning/test_plant.py``."""

    command_max: float = ranged(0.0, 1e9, default=4095.0, lo_open=True)
    """Largest servo command U, DAC counts. Not given: a 12-bit DAC; with eq. (1)-(2) it
    gives a top feed velocity of 5.79 mm/s (0.86 mm/rev at 405 rpm). Commands are clipped
    to [0, command_max]: the feed does not reverse."""

    breakage_force_N: float = ranged(0.0, 1e7, default=3000.0, lo_open=True)
    """Cutting force at which the carbide insert is taken to break, N. Not given: 3x the
    paper's 1 kN reference, about the limit of its 2.2 kW spindle at 405 rpm on a 100 mm
    bar. The episode terminates when the force exceeds it."""

    noise_std_N: float = ranged(0.0, 1e5, default=10.0)
    """Standard deviation of the white measurement noise at the ADC, in newtons (1 % of the
    1 kN reference). Not given; scaled by a scenario's ``noise_scale``."""

    wear_per_100mm: float = ranged(0.0, 10.0, default=0.0)
    """Tool wear within the cut: the force coefficient at position ``x`` along the workpiece
    is ``Kf (1 + w x / 100 mm)``. Cutting forces grow almost linearly with the flank-wear
    land (Koren & Lenz 1972, the flank-wear model for turning steel with carbide that
    Koren's adaptive-control work builds on; Sikdar & Chen 2002 measure it on AISI 4340),
    and the land grows linearly with the length cut in the steady zone of the wear curve,
    so the coefficient is linear in ``x``. 0 (default): the papers' sharp tool; the
    ``wear`` scenarios draw ``w`` (see ``machining_envs.turning.scenarios``)."""

    spindle_power_W: float = float("inf")
    """Spindle drive power P_max, W. inf (default): the papers' ideal spindle, which holds
    its speed whatever the cut asks. Finite: the drive delivers at most ``P_max``; when the
    cutting power ``F v_c`` (``v_c = pi D n``) asks for more, the spindle slows (see
    ``spindle_inertia_kg_m2``). The lathe of the paper is of the 2.2 kW class (about the
    power of a 1 kN cut at 405 rpm on the bar below), so 2200 is a natural setting; the
    ``shopfloor`` scenarios use it."""

    spindle_inertia_kg_m2: float = ranged(0.0, 1e3, default=0.1, lo_open=True)
    """J of the spindle, chuck and workpiece, kg m^2, for the power limit. Not given: a
    100 mm x 300 mm steel bar is 0.023, a 200 mm chuck about 0.05, the spindle and the
    motor's reflected rotor the rest."""

    workpiece_diameter_mm: float = ranged(0.0, 1e4, default=100.0, lo_open=True)
    """Workpiece diameter D, mm, for the cutting speed ``v_c = pi D n`` of the power limit.
    Not given: the 100 mm bar of a lathe of the paper's size."""

    force_scale_N: float = ranged(0.0, 1e7, default=1000.0, lo_open=True)
    """Normalisation of forces in observations, N (the paper's reference force)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if isinstance(self.sensor_filter_order, bool) or self.sensor_filter_order not in (1, 2):
            raise ValueError(
                f"sensor_filter_order must be 1 or 2, got {self.sensor_filter_order!r}"
            )
        if self.spindle_power_W != float("inf"):  # inf: no power limit
            _check("spindle_power_W", self.spindle_power_W, 0.0, 1e7, lo_open=True)

    @classmethod
    def noh_kim_kim_1992(cls) -> TurningParams:
        """The lathe of Noh, Kim & Kim (1992), SM45C with a carbide tool (the defaults)."""
        return cls()

    # ---- derived quantities (never stored) -------------------------------------------------
    @property
    def servo_natural_freq_rad_s(self) -> float:
        """wn in rad/s."""
        return 2.0 * math.pi * self.servo_natural_freq_hz

    @property
    def max_feed_velocity_mm_s(self) -> float:
        """Steady feed velocity at ``command_max``, mm/s: Ks Km U_max (eq. 1-2)."""
        return self.servo_gain * self.gear_ratio * self.command_max

    def feed_for_force(self, force_N: float, depth_mm: float) -> float:
        """Feed per revolution (mm/rev) at which eq. (8) gives ``force_N`` at ``depth_mm``."""
        return (force_N / (self.force_coefficient * depth_mm)) ** (1.0 / self.feed_exponent)

    def command_for_feed(self, feed_mm_per_rev: float, spindle_rpm: float) -> float:
        """Steady command U giving ``feed_mm_per_rev`` at ``spindle_rpm``: f = Ks Km U T."""
        return feed_mm_per_rev / (self.servo_gain * self.gear_ratio * 60.0 / spindle_rpm)

    def process_gain(self, spindle_rpm: float, depth_mm: float, feed_mm_per_rev: float) -> float:
        r"""Open-loop plant gain Kp of eq. (11), counts of force per count of command.

        .. math:: K_p = K_s K_m \frac{60}{n} K_f f^{p-1} a K_e
        """
        return (
            self.servo_gain
            * self.gear_ratio
            * (60.0 / spindle_rpm)
            * self.force_coefficient
            * feed_mm_per_rev ** (self.feed_exponent - 1.0)
            * depth_mm
            * self.sensor_gain
        )

    def open_loop_tf(self, spindle_rpm: float) -> tuple[list[float], list[float]]:
        r"""Unit-gain continuous plant of eq. (11), ``wn^2 / ((s^2 + 2 zeta wn s + wn^2)(tau s + 1))``.

        ``tau = 30 / n`` is the Padé time constant of eq. (7). Returns ``(num, den)``.
        """
        wn = self.servo_natural_freq_rad_s
        tau = 30.0 / spindle_rpm
        den = np.polymul([1.0, 2.0 * self.servo_damping * wn, wn**2], [tau, 1.0])
        return [wn**2], list(den)

    def discrete_open_loop(self, spindle_rpm: float) -> tuple[np.ndarray, np.ndarray]:
        """ZOH discretisation of :meth:`open_loop_tf` at ``sample_time_s`` (eq. 14), in z^-1."""
        num, den = self.open_loop_tf(spindle_rpm)
        return zoh_tf(num, den, self.sample_time_s)


@functools.lru_cache(maxsize=512)
def unit_plant_coefficients(params: TurningParams, spindle_rpm: float) -> np.ndarray:
    """``[b1, b2, b3, a1, a2, a3]`` of the unit-gain discrete plant of eq. (14) at this
    speed (:meth:`TurningParams.discrete_open_loop` padded to third order), for
    controllers that adapt to it (read-only: cached)."""
    numd, dend = params.discrete_open_loop(spindle_rpm)
    numd = np.pad(numd, (0, 4 - numd.size))
    dend = np.pad(dend, (0, 4 - dend.size))
    return read_only(np.concatenate([numd[1:4], dend[1:4]]))


@dataclass(frozen=True)
class _Matrices:
    """Everything the per-step update needs, computed once per (params, spindle speed).

    The memory of the cut is one vector ``z = [x_k, u_k, x_{k-1}, u_{k-1}, ..., x_{k-L},
    u_{k-L}]`` of servo states ``x = [Vf, dVf/dt, I]`` at the last ``L + 1`` sample instants
    and the commands held after each. Since the command is constant over each sample, the
    servo state at any instant is an exact linear function of one pair ``(x_i, u_i)``, so
    the tool position ``I(t_j)``, the feed per revolution ``I(t_j) - I(t_j - T)`` at every
    sub-step ``t_j`` of the coming sample, and the next state ``x_{k+1}`` are all rows of one
    matrix applied to ``z`` (:attr:`big`). Most of its entries are zero: the lanes hold only
    its non-zero groups of four columns (``packed``).
    """

    lags: int  # L
    delay_group: np.ndarray  # (M,): the group of four columns of each feed row's delayed
    # instant (0 where it lies in the current sample, merged with the other terms)
    filt_step: np.ndarray  # (n_f, n_f + M + 1): next filter state from [state, F_1..F_M, F_0]
    packed: np.ndarray  # (2M + 3, 8): the current pair's group, then each feed row's delayed
    # group where that is not the current one (zeros elsewhere); the lanes hold it in two
    # parts (``TurningLanes.base`` and ``feed``)

    @property
    def big(self) -> np.ndarray:
        """The step matrix ``(2M + 3, 4(L + 1))``: rows = positions, feeds, next state."""
        m = self.delay_group.size
        out = np.zeros((2 * m + 3, 4 * (self.lags + 1)))
        out[:, :4] = self.packed[:, :4]
        for j, lag in enumerate(self.delay_group.tolist()):
            if lag > 0:
                out[m + j, 4 * lag : 4 * lag + 4] = self.packed[m + j, 4:]
        return out


class _LinearKey(NamedTuple):
    """The fields the linear blocks depend on (not Kf, p or noise, which vary per cut)."""

    servo_gain: float
    servo_natural_freq_rad_s: float
    servo_damping: float
    gear_ratio: float
    sensor_cutoff_hz: float
    sensor_filter_order: int
    sample_time_s: float
    substeps: int

    of = classmethod(fields_of)


@functools.lru_cache(maxsize=16)
def _servo_system(params: _LinearKey) -> tuple[np.ndarray, np.ndarray]:
    """Continuous servo + running integral, state ``[Vf, dVf/dt, I]``, input U (counts);
    built once per set of linear parameters (every reset reads it), read-only."""
    wn = params.servo_natural_freq_rad_s
    z = params.servo_damping
    a = np.array([[0.0, 1.0, 0.0], [-(wn**2), -2.0 * z * wn, 0.0], [1.0, 0.0, 0.0]])
    b = np.array([[0.0], [params.servo_gain * params.gear_ratio * wn**2], [0.0]])
    return read_only(a, b)


@functools.lru_cache(maxsize=16)
def _speed_free(params: _LinearKey):
    """Parts that do not depend on the spindle speed: servo transitions over i*h, filter;
    read-only (every lane and env of these parameters shares them)."""
    m = params.substeps
    h = params.sample_time_s / m
    a, b = _servo_system(params)
    phi_h, gam_h = zoh(a, b, h)
    phis = np.empty((m + 1, 3, 3))
    gams = np.empty((m + 1, 3))
    phis[0], gams[0] = np.eye(3), 0.0
    for i in range(1, m + 1):
        phis[i] = phi_h @ phis[i - 1]
        gams[i] = phi_h @ gams[i - 1] + gam_h[:, 0]

    fa, fb, fc = butterworth_lowpass(params.sensor_cutoff_hz, params.sensor_filter_order)
    fphi, fgam = zoh(fa, fb, h)
    n_f = fphi.shape[0]
    held = np.empty((n_f, m))  # response at the sample's end to the force held over sub-step j
    acc = np.eye(n_f)
    for j in range(m - 1, -1, -1):
        held[:, j] = (acc @ fgam)[:, 0]
        acc = fphi @ acc
    # The input over each sub-step is the trapezoidal mean of the force at its two ends.
    filt_h = 0.5 * held
    filt_h[:, :-1] += 0.5 * held[:, 1:]
    return read_only(phis, gams, acc, filt_h, 0.5 * held[:, 0], fc)


@functools.lru_cache(maxsize=16)
def _velocity_bound(params: _LinearKey, command_max: float) -> float:
    """Largest |Vf| (mm/s) any command sequence in [0, command_max] can produce from rest.

    BIBO bound: Ks Km U_max times the L1 norm of the servo's unit impulse response, which
    for zeta = 0.43 is about 1.6 (the overshoot and ring-down add to the steady speed);
    5 % is added for safety.
    Integrated on a grid 1/50 of the damped period, over 40 decay time constants.
    """
    wn, z = params.servo_natural_freq_rad_s, params.servo_damping
    a = np.array([[0.0, 1.0], [-(wn**2), -2.0 * z * wn]])
    b = np.array([[0.0], [wn**2]])
    horizon = 40.0 / (z * wn)
    dt = min(2 * np.pi / (wn * 50.0), horizon / 2000.0)
    phi, _ = zoh(a, b, dt)
    x = b[:, 0].copy()  # state just after a unit impulse
    l1 = 0.0
    for _ in range(int(horizon / dt)):
        x_next = phi @ x
        l1 += 0.5 * (abs(x[0]) + abs(x_next[0])) * dt
        x = x_next
    return 1.05 * params.servo_gain * params.gear_ratio * command_max * l1


@functools.lru_cache(maxsize=16)
def _speed_free_rows(params: _LinearKey) -> tuple[np.ndarray, np.ndarray]:
    """Rows of the step matrix on the current pair ``(x_k, u_k)`` and the filter's matrix,
    read-only (shared as :func:`_speed_free`'s)."""
    m = params.substeps
    phis, gams, filt_a_m, filt_h, filt_prev, filt_c = _speed_free(params)
    base = np.zeros((2 * m + 3, 4))
    base[:m, 0:3] = phis[1:, 2]  # positions I(t_j), j = 1..M
    base[:m, 3] = gams[1:, 2]
    base[m : 2 * m] = base[:m]  # feeds start from the same, less the delayed value
    base[2 * m :, 0:3] = phis[m]  # next state
    base[2 * m :, 3] = gams[m]
    # The filter's output is its first state (both orders): y = x_f[0].
    assert filt_c[0] == 1.0 and not np.any(filt_c[1:])
    filt_step = np.hstack([filt_a_m, filt_h, filt_prev[:, None]])
    return read_only(base, filt_step)


@functools.lru_cache(maxsize=256)
def _matrices(params: _LinearKey, spindle_rpm: float) -> _Matrices:
    """The step matrices at ``spindle_rpm`` (:class:`_Matrices`), read-only: cached, every
    lane at that speed reads them."""
    m = params.substeps
    feed = np.empty((4, m)).T  # column after column, as the lanes hold it
    lag = np.empty(m, dtype=np.int64)
    lags = _fill_matrices(params, spindle_rpm, feed, lag)
    base, filt = _speed_free_rows(params)
    packed = np.zeros((2 * m + 3, 8))
    packed[:, :4] = base
    now = lag == 0
    packed[m : 2 * m][now, :4] = feed[now]
    packed[m : 2 * m][~now, 4:] = feed[~now]
    read_only(lag, packed)
    return _Matrices(lags, lag, filt, packed)


def _fill_matrices(params: _LinearKey, spindle_rpm: float, feed, lag) -> int:
    """A lane's own coefficients of the step matrix's feed rows at ``spindle_rpm`` into
    ``feed`` (``(M, 4)``; :func:`_delayed_rows`) and their delay groups into ``lag``; returns
    ``lags``."""
    lags = _lane_matrices(*_speed_free_tables(params), float(spindle_rpm), feed, lag)
    if lags < 0:  # Phi(rho) is zoh's job (never in the plant's ranges): as below, by zoh
        lags = _fill_matrices_zoh(params, spindle_rpm, feed, lag)
    return lags


#: What :func:`start_lane` reads of the linear blocks besides the speed, which every lane
#: shares (:func:`_speed_free_tables`): the servo's transitions over ``i h``, the step
#: matrix's rows on the current pair, the continuous servo ``(A, B)``, the sample time.
SpeedFree = record(
    "SpeedFree",
    __name__,
    """
    phis: shared f8_3
    gams base sa sb: shared f8_2
    ts: shared f8
    """,
)


@functools.lru_cache(maxsize=16)
def _speed_free_tables(params: _LinearKey) -> tuple:
    """What :func:`_lane_matrices` reads besides the speed: ``(phis, gams, base, A, B,
    Ts)`` (the servo's transitions over ``i h``, the step matrix's rows on the current
    pair, the continuous servo, the sample time), read-only."""
    phis, gams = _speed_free(params)[:2]
    a, b = _servo_system(params)
    return SpeedFree(phis, gams, _speed_free_rows(params)[0], a, b, float(params.sample_time_s))


@numba.njit(cache=True)
def _lane_matrices(phis, gams, base, sa, sb, ts, spindle_rpm, feed, lag):
    """:func:`_fill_matrices` from its tables (:func:`_speed_free_tables`): the lane's feed
    rows and their delay groups at ``spindle_rpm``, and ``lags``; -1 (nothing written)
    where ``Phi(rho)`` lies outside :func:`_exp_row`'s reach.

    Every delayed instant ``t_j - T`` sits the same fraction ``rho`` of a sub-step past a
    sub-step point, so one exponential over ``rho`` and the powers over ``i h`` give all of
    them exactly."""
    period, lags, rho = _delays(spindle_rpm, ts, lag.size)
    i_row = np.zeros(4)  # the I-rows of Phi(rho) and Gamma(rho), side by side
    i_row[2] = 1.0
    if rho > 0 and not _exp_row(sa, sb, rho, 2, i_row):
        return -1
    _delayed_rows(phis, gams, base, i_row[:3], i_row[3], period, ts, rho, feed, lag)
    return lags


@numba.njit(cache=True)
def _delays(spindle_rpm, ts, m):
    """``(T, lags, rho)`` at ``spindle_rpm``: the revolution time ``T``, the samples of
    command history the step matrix reaches back (``lags``) and the fraction of a sub-step
    ``h = Ts / m`` by which every delayed instant ``t_j - T`` lies past a sub-step point."""
    h = ts / m
    period = 60.0 / spindle_rpm
    lags = int(math.ceil(period / ts + 1e-12)) + 1
    rho = (-period) % h
    if rho > h - 1e-12 * h:
        rho = 0.0
    return period, lags, rho


def _fill_matrices_zoh(params: _LinearKey, spindle_rpm: float, feed, lag) -> int:
    """:func:`_lane_matrices` with ``Phi(rho)`` and ``Gamma(rho)`` from ``zoh``."""
    phis, gams, base, sa, sb, ts = _speed_free_tables(params)
    period, lags, rho = _delays(float(spindle_rpm), ts, params.substeps)
    i_row = np.zeros(4)  # the I-rows of Phi(rho) and Gamma(rho), side by side
    i_row[2] = 1.0
    if rho > 0:
        phi_r, gam_r = zoh(sa, sb, rho)
        i_row[:3], i_row[3] = phi_r[2], gam_r[2, 0]
    _delayed_rows(phis, gams, base, i_row[:3], i_row[3], period, ts, rho, feed, lag)
    return lags


@numba.njit(cache=True)
def _exp_row(a, b, dt, row, out):
    """Row ``row`` of ``[Phi(dt), Gamma(dt)]``, the exact discretisation of ``x' = A x + B u``
    (one input) over ``dt``, into ``out``: row ``row`` of the exponential of the augmented
    matrix ``M dt = [[A, B], [0, 0]] dt`` by its Taylor series, one row times ``M dt`` per
    term, the terms summed smallest first. Where ``||M dt||_1 <= 1`` (every delayed instant
    of the plant's ranges: at most 0.56) the 24 terms leave a remainder below ``1 / 24!``,
    far under a unit in the last place, and the result is that of
    :func:`~machining_envs.core.lti.zoh` to a few units in the last place, for a
    microsecond instead of some 60; elsewhere returns False and writes nothing."""
    n = a.shape[0]
    md = np.zeros((n + 1, n + 1))
    for i in range(n):  # loops, not slices set from arrays (core.compiled.kernels.copy_into)
        for j in range(n):
            md[i, j] = a[i, j] * dt
        md[i, n] = b[i, 0] * dt
    norm = 0.0
    for c in range(n + 1):
        norm = max(norm, np.abs(md[:, c]).sum())
    if not norm <= 1.0:
        return False
    terms = np.zeros((24, n + 1))
    terms[0, row] = 1.0
    for k in range(1, 24):
        for c in range(n + 1):
            acc = 0.0
            for q in range(n + 1):
                acc += terms[k - 1, q] * md[q, c]
            terms[k, c] = acc / k
    for c in range(n + 1):
        acc = 0.0
        for k in range(23, -1, -1):
            acc += terms[k, c]
        out[c] = acc
    return True


@numba.njit(cache=True)
def _delayed_rows(phis, gams, base, phi_r2, gam_r2, period, ts, rho, feed, lag):
    """A lane's own part of the step matrix (``_Matrices.packed``): each feed row's delayed
    group ``lag`` and its coefficients ``feed`` (``(M, 4)``, and may be a view of an array
    stored column after column). Feed row ``m + j`` is the row on the current pair
    (``base``), less the position at its delayed instant ``t_j - T`` (``period``), which
    lies ``lag[j]`` samples back, ``i h + rho`` past that sample's start: the I-row of
    ``Phi(rho) Phi(i h)`` and the I-entry of ``Phi(rho) Gamma(i h) + Gamma(rho)``
    (``phi_r2``, ``gam_r2``: the I-row of ``Phi(rho)`` and the I-entry of ``Gamma(rho)``).
    Where that instant lies in the current sample (``lag[j]`` 0) ``feed[j]`` is the whole
    row on the current pair (``base`` less it), else the delayed group's four numbers
    (``0 - it``), the row's current group being ``base``'s, which all lanes share. Each sum
    in a fixed order."""
    m = lag.size
    h = ts / m
    for j in range(m):
        back = float(j + 1) * h - period  # t_j - T relative to t_k
        lj = int(math.ceil(-back / ts - 1e-9)) if back < 0 else 0
        i = int(np.rint((back + lj * ts - rho) / h))  # offset = i h + rho in [0, Ts)
        if not 0 <= i <= m:
            raise ValueError("a delayed instant fell outside its sample")
        lag[j] = lj
        row = feed[j]
        for c in range(4):  # group 0 overlaps the current pair's terms
            row[c] = base[m + j, c] if lj == 0 else 0.0
        for c in range(3):
            d = phi_r2[0] * phis[i, 0, c] + phi_r2[1] * phis[i, 1, c] + phi_r2[2] * phis[i, 2, c]
            row[c] -= d
        d = gams[i, 0] * phi_r2[0] + gams[i, 1] * phi_r2[1] + gams[i, 2] * phi_r2[2] + gam_r2
        row[3] -= d


def sampled_model(params: TurningParams, spindle_rpm: float) -> tuple[np.ndarray, int]:
    """The plant's exact sampled linear part at ``spindle_rpm``: ``(big, m)``.

    ``big @ z`` gives, for the memory ``z = [x_k, u_k, x_{k-1}, u_{k-1}, ...]`` of servo
    states ``x = [Vf, dVf/dt, I]`` and held commands (``TurningLanes.z``), the tool
    position at the ``m`` sub-steps of the coming sample (rows ``0 .. m-1``), the feed per
    revolution there (rows ``m .. 2m-1``) and the next servo state (rows ``2m .. 2m+2``);
    the force is ``Kf max(feed, 0)^p a(position)`` (eq. 8). For model-based agents that
    may know the truth (``agents.oracle``); controllers do not read it.
    """
    return _matrices(_LinearKey.of(params), float(spindle_rpm)).big, params.substeps


@dataclass(slots=True)
class TurningStep:
    """Signals of one control period, at its end (the sample instant) unless stated."""

    force_N: float
    """Cutting force Kf f^p a at the sample instant, N."""
    peak_force_N: float
    """Largest cutting force over the period's sub-steps, N."""
    measured_counts: float
    """Filtered, noisy sensor output Fc, counts (eq. 10)."""
    feed_mm_per_rev: float
    feed_velocity_mm_s: float
    position_mm: float
    """Distance fed along the workpiece since the start, mm."""
    depth_mm: float
    segment: int
    """Index of the workpiece segment the tool is in (``DepthProfile`` segment)."""
    finish_time_s: float | None = None
    """Time at which ``position_mm`` first reached the workpiece length, if in this period."""


# ---- the batched physics: N cuts stepped as arrays, one kernel for one lane or many --------


@numba.njit(cache=True, inline="always")
def _profile_depths(y, edges, d0, slope, nseg, i, force, m, kf):
    """``force[j] *= depth(y[j]) * Kf`` for the sub-steps ``j < m`` of a sample whose
    positions may cross the profile's edges, and the last depth. A depth is
    ``DepthProfile.__call__``'s at the position (zero outside ``[0, length)``, NaN read as
    outside), its segment found by walking from segment ``i`` (the positions of a sample
    lie close together: a step or two), not searched afresh. The edges are sorted, so the
    walk ends on the segment ``np.searchsorted`` finds (the last whose edge is at or below
    the position, or the first) and every depth is its number to the last bit."""
    top = edges[nseg]
    depth = 0.0
    for j in range(m):
        x = y[j]
        if not (x >= 0.0 and x < top):
            depth = 0.0
        else:
            while i + 1 < nseg and edges[i + 1] <= x:
                i += 1
            while i > 0 and edges[i] > x:
                i -= 1
            depth = d0[i] + slope[i] * (x - edges[i])
        force[j] = force[j] * depth * kf
    return depth


@numba.njit(cache=True)
def _step_lanes(a, commands, noise):
    """Advance every lane of the arrays ``a`` (:data:`TurningArrays`) by one sample
    (:func:`step_lane` on each)."""
    for k in range(a.z.shape[0]):
        step_lane(k, a, commands[k], noise[k])


@numba.njit(cache=True, inline="always")
def lane_ints(li):
    """The first columns of ``TurningLanes.li``: ``(cols, nseg, seg, out_segment)``; lane
    ``k``'s delay groups follow them (``li[k, 4:]``, which the compiler knows to be one
    contiguous row, where ``li[:, 4:][k]`` is strided)."""
    return li[:, 0], li[:, 1], li[:, 2], li[:, 3]


@numba.njit(cache=True, inline="always")
def _current_rows(base, n, z0, z1, z2, z3, lo, hi, y):
    """Rows ``lo .. hi - 1`` of ``y = A @ zk`` that read the current pair only (``base``'s
    four columns of ``n`` values), each summed as a fused group of four."""
    for i in range(lo, hi):
        r = np.uint64(i)
        s0 = fma(base[r], z0, 0.0)
        s1 = fma(base[r + n], z1, 0.0)
        s2 = fma(base[r + np.uint64(2) * n], z2, 0.0)
        s3 = fma(base[r + np.uint64(3) * n], z3, 0.0)
        y[r] = 0.0 + ((s0 + s2) + (s1 + s3))


@numba.njit(cache=True)
def _sampled_rows(base, feed, lag, zk, m, y):
    """``y = A @ zk`` for a lane's step matrix ``A`` (``(2M + 3, 4 (L + 1))``), held as its
    non-zero groups of four columns only, in two parts (:func:`_delayed_rows`): ``base``,
    the rows on the current pair ``(x_k, u_k)`` (columns 0-3 of ``A``) that every lane
    shares, and ``feed``, the lane's own numbers of its feed rows ``M .. 2M - 1``; both
    column after column (``base.reshape(4, 2M + 3)``, ``feed.reshape(4, M)``).

    A position or next-state row reads the current pair only, with ``base``'s numbers. A
    feed row whose delayed instant lies in another sample (group ``lag[j]`` of ``A``) reads
    the current pair with ``base``'s numbers and that group with ``feed``'s; one whose
    delayed instant lies in the current sample (``lag[j]`` 0) reads the current pair with
    ``feed``'s. The other groups are zero, and
    :func:`~machining_envs.core.compiled.kernels.matvec`'s sums gain nothing from a zero group (a
    fused ``0 x + s`` is ``s`` for finite ``x``), so the rows here, summed in its order over
    the non-zero groups only, are its numbers for ``A @ zk`` (numpy's) to the last bit.

    The rows in whole groups of four (every position and feed row) go in runs that read
    the same numbers (the positions, the feed rows of one delay group after another, the
    next state): each run is one loop of the same operations for every row, which runs in
    the processor's vectors, a row per value.
    """
    n_rows = 2 * m + 3
    nb = n_rows & ~3  # rows summed in fused groups of four; the feed rows are among them
    z0 = zk[0]
    z1 = zk[1]
    z2 = zk[2]
    z3 = zk[3]
    n = np.uint64(n_rows)  # unsigned indices: the compiler knows they are not negative
    nm = np.uint64(m)
    _current_rows(base, n, z0, z1, z2, z3, 0, m, y)
    lo = 0
    while lo < m:  # the feed rows, in runs of one delay group
        g = lag[np.uint64(lo)]
        hi = lo + 1
        while hi < m and lag[np.uint64(hi)] == g:
            hi += 1
        if g > 0:
            q = 4 * g
            d0 = zk[q]
            d1 = zk[q + 1]
            d2 = zk[q + 2]
            d3 = zk[q + 3]
            for j in range(lo, hi):
                u = np.uint64(j)
                r = u + nm
                s0 = fma(feed[u], d0, fma(base[r], z0, 0.0))
                s1 = fma(feed[u + nm], d1, fma(base[r + n], z1, 0.0))
                s2 = fma(feed[u + np.uint64(2) * nm], d2, fma(base[r + np.uint64(2) * n], z2, 0.0))
                s3 = fma(feed[u + np.uint64(3) * nm], d3, fma(base[r + np.uint64(3) * n], z3, 0.0))
                y[r] = 0.0 + ((s0 + s2) + (s1 + s3))
        else:
            yf = y[m:]
            _current_rows(feed, nm, z0, z1, z2, z3, lo, hi, yf)
        lo = hi
    _current_rows(base, n, z0, z1, z2, z3, 2 * m, nb, y)
    r = nb
    a = base
    if (n_rows - nb) & 2:  # two rows of two sums of rounded products
        for r in range(nb, nb + 2):
            s0 = 0.0 + a[r] * z0
            s1 = 0.0 + a[n_rows + r] * z1
            y[r] = 0.0 + ((s0 + a[2 * n_rows + r] * z2) + (s1 + a[3 * n_rows + r] * z3))
        r = nb + 2
    if (n_rows - nb) & 1:  # one row of four sums of rounded products
        y[r] = 0.0 + (
            ((0.0 + a[r] * z0) + (0.0 + a[2 * n_rows + r] * z2))
            + ((0.0 + a[n_rows + r] * z1) + (0.0 + a[3 * n_rows + r] * z3))
        )


@numba.njit(cache=True)
def _filter_pair(f, x, w, out):
    """``out[:2] = F @ x[:w]`` for the filter's step matrix ``F`` of two rows (a
    second-order filter; ``w`` values a row, row after row in ``f``), summed as
    :func:`~machining_envs.core.compiled.kernels.matvec` sums two rows (two interleaved sums of
    rounded products over the columns in whole groups of four, added, and a last column
    fused on), so to the last bit numpy's product, the two rows in one loop (four
    independent sums, where one row after the other leaves two). False, writing nothing,
    for a ``w`` that ``matvec`` sums otherwise."""
    tail = w & 3
    if tail > 1 or w < 5 or w >= 2048:
        return False
    s0 = 0.0
    s1 = 0.0
    t0 = 0.0
    t1 = 0.0
    for q in range(0, w - tail, 2):
        x0 = x[q]
        x1 = x[q + 1]
        s0 = s0 + f[q] * x0
        s1 = s1 + f[q + 1] * x1
        t0 = t0 + f[w + q] * x0
        t1 = t1 + f[w + q + 1] * x1
    o0 = 0.0 + (s0 + s1)
    o1 = 0.0 + (t0 + t1)
    if tail:
        o0 = fma(f[w - 1], x[w - 1], o0)
        o1 = fma(f[2 * w - 1], x[w - 1], o1)
    out[0] = o0
    out[1] = o1
    return True


@numba.njit(cache=True)
def step_lane(k, a, command, noise):
    """Advance lane ``k`` of the arrays ``a`` (:data:`TurningArrays`; see
    :class:`TurningLanes` for the layout; ``a.li`` is ``TurningLanes.li``, of which
    :func:`lane_ints` names the first columns) by one sample.

    ``lane_f[k]`` holds ``[Kf, p, Ke, U_max, length, t, margin, Ts, wear per mm]``;
    ``out_f[k]`` gets
    ``[force, peak force, measured counts, feed per rev, feed velocity, position, depth]``.
    The arithmetic is that of one cut, whatever the number of lanes.
    """
    feed, base, li, filt, z, buf, work = a.feed, a.base, a.li, a.filt, a.z, a.buf, a.work
    edges, d0, slope, lane_f, finished = a.edges, a.d0, a.slope, a.lane_f, a.finished
    m, n_f, out_f, out_finish = a.m, a.n_f, a.out, a.out_finish
    cols, nseg, seg, out_seg = lane_ints(li)
    n_rows = 2 * m + 3
    kf, pexp, gain, cmax, length, t, margin, ts, wear = lane_f[k]
    c = cols[k]
    zk = z[k, :c]
    zk[3] = min(max(command, 0.0), cmax)
    y = work[k, :n_rows]
    _sampled_rows(base, feed[k], li[k, 4:], zk, m, y)
    p_start = zk[2]
    p_end = y[m - 1]
    b = buf[k]
    force = b[n_f : n_f + m]
    powers(y, m, b, n_f, m, pexp)  # force[j] = max(y[m + j], 0) ** p
    e = edges[k]
    i = seg[k]
    lo, hi = (p_start, p_end) if p_start <= p_end else (p_end, p_start)
    one_segment = e[i] <= lo - margin and hi + margin < e[i + 1]
    if not one_segment and e[i] <= lo and hi < e[i + 1]:
        one_segment = e[i] <= row_min(y, m) and row_max(y, m) < e[i + 1]
    if one_segment:
        sl = slope[k, i]
        if sl == 0.0:
            depth_end = d0[k, i]
            scale = kf * depth_end
            for j in range(m):
                force[j] *= scale
        else:
            for j in range(m):
                depth = (y[j] - e[i]) * sl + d0[k, i]
                force[j] = force[j] * depth * kf
            depth_end = (y[m - 1] - e[i]) * sl + d0[k, i]
    else:
        depth = _profile_depths(y, e, d0[k], slope[k], nseg[k], i, force, m, kf)
        depth_end = depth
        i = np.searchsorted(e[: nseg[k] + 1], p_end, side="right") - 1
        i = min(max(i, 0), nseg[k] - 1)
        seg[k] = i
    if wear != 0.0:  # Kf (1 + w x): the tool dulls along the cut (wear_per_100mm)
        for j in range(m):
            force[j] *= 1.0 + wear * y[j]
    fo = work[k, n_rows:]
    if not (n_f == 2 and _filter_pair(filt[0], b, b.shape[0], fo)):
        matvec(filt, n_f, b.shape[0], buf[k : k + 1], work[k : k + 1, n_rows:])
    for q in range(n_f):
        b[q] = fo[q]
    f_end = force[m - 1]
    out = out_f[k]
    out[0] = f_end
    out[1] = row_max(force, m)
    out[2] = gain * fo[0] + noise
    out[3] = y[2 * m - 1]
    b[b.shape[0] - 1] = f_end
    for q in range(c - 1, 3, -1):
        zk[q] = zk[q - 4]
    zk[0] = y[2 * m]
    zk[1] = y[2 * m + 1]
    zk[2] = y[2 * m + 2]
    zk[3] = 0.0
    out[4] = zk[0]
    out[5] = p_end
    out[6] = depth_end
    out_seg[k] = seg[k]
    out_finish[k] = np.nan
    if not finished[k] and p_end >= length:
        j = 0
        while y[j] < length:
            j += 1
        out_finish[k] = t + (j + 1) * ts / m
        finished[k] = True
    lane_f[k, 5] = t + ts


def cutting_power_W(force_N, spindle_rpm, diameter_mm):
    """Cutting power ``F v_c`` (W) of a force ``force_N`` (N, negative read as 0) at
    ``spindle_rpm`` on a workpiece of ``diameter_mm``: ``F w D / 2``. Scalars or arrays."""
    return np.maximum(force_N, 0.0) * (spindle_rpm * (math.pi / 30.0)) * (diameter_mm * 0.0005)


def spindle_drive(params: TurningParams, rpm: float, rpm_set: float, force_N: float):
    """One control period of a power-limited spindle: ``(next rpm, drive power W, cutting
    power W)`` for a spindle at ``rpm`` set to ``rpm_set``, under the cutting force
    ``force_N`` at the period's end.

    The cutting power is ``P_c = F v_c``, ``v_c = pi D n / 60`` (m/s with D in m). The speed
    regulator asks for the power that brings the spindle back to its set speed within the
    period, ``P_c + J (w_set^2 - w^2) / (2 Ts)``; the drive delivers that, at most
    ``P_max``, and the energy balance ``J (w'^2 - w^2) / 2 = (P_drive - P_c) Ts`` gives the
    next speed ``w'``. So the drive never delivers more than ``P_max``; a cut that asks for
    more slows the spindle (its kinetic energy pays the difference), which raises the feed
    per revolution and with it the force: the stall of an overloaded lathe. The speed does
    not fall below the lowest the plant accepts (``SPINDLE_RPM_RANGE``).
    """
    j = params.spindle_inertia_kg_m2
    ts = params.sample_time_s
    w = rpm * (math.pi / 30.0)
    w_set = rpm_set * (math.pi / 30.0)
    p_cut = float(cutting_power_W(force_N, rpm, params.workpiece_diameter_mm))
    p_need = p_cut + j * (w_set * w_set - w * w) / (2.0 * ts)
    if p_need <= params.spindle_power_W:
        return rpm_set, max(p_need, 0.0), p_cut
    p_drive = params.spindle_power_W
    w2 = w * w + 2.0 * ts * (p_drive - p_cut) / j
    w_min = SPINDLE_RPM_RANGE[0] * (math.pi / 30.0)
    w_next = math.sqrt(max(w2, w_min * w_min))
    return min(w_next * (30.0 / math.pi), rpm_set), p_drive, p_cut


#: The arrays of :class:`TurningLanes` its kernels read and write (its attributes of
#: these names), as one argument: :func:`step_lane`'s and :func:`start_lane`'s.
TurningArrays = record(
    "TurningArrays",
    __name__,
    """
    feed z buf work edges d0 slope lane_f out: lanes f8_2
    li: lanes i8_2
    finished: lanes b1_1
    out_finish spindle_rpm: lanes f8_1
    base: shared f8_1
    filt: shared f8_2
    m n_f: shared i8
    """,
)

#: Fields of ``TurningLanes.out`` (one row per lane after each step).
LANE_SIGNALS = (
    "force_N",
    "peak_force_N",
    "measured_counts",
    "feed_mm_per_rev",
    "feed_velocity_mm_s",
    "position_mm",
    "depth_mm",
)


@numba.njit(cache=True)
def start_lane(k, rpm, full_history, consts, segments, free, a):
    """Lane ``k``'s arrays (``a``, :data:`TurningArrays`) at the start of a cut at ``rpm``
    on the workpiece ``segments`` (``DepthProfile.segment_array``; the tables must hold its
    segments), the machine at rest at its start: the step matrix at that speed
    (:func:`_lane_matrices` of the tables ``free``, :data:`SpeedFree`, padded to the
    slowest speed's memory with ``full_history``), the lane's ``consts``
    (:meth:`TurningLanes.lane_constants`) and clock. Returns False where the step matrix
    is left for ``zoh`` (:meth:`TurningLanes._load_matrices`)."""
    li, z, buf, lane_f, finished, ts = a.li, a.z, a.buf, a.lane_f, a.finished, free.ts
    m = li.shape[1] - 4
    phis, gams, base, sa, sb = free.phis, free.gams, free.base, free.sa, free.sb
    lags = _lane_matrices(phis, gams, base, sa, sb, ts, rpm, a.feed[k].reshape((4, m)).T, li[k, 4:])
    li[k, 0] = z.shape[1] if full_history else 4 * (lags + 1)
    z[k, :] = 0.0
    buf[k, :] = 0.0
    ns = segments.shape[1] - 1
    load_segments(segments, k, a.edges, a.d0, a.slope)
    li[k, 1] = ns
    li[k, 2] = 0
    kf, p, ke, cmax, margin, wear = consts
    row = lane_f[k]
    row[0] = kf
    row[1] = p
    row[2] = ke
    row[3] = cmax
    row[4] = segments[0, ns]
    row[5] = 0.0
    row[6] = margin
    row[7] = ts
    row[8] = wear
    finished[k] = False
    a.spindle_rpm[k] = rpm
    return lags >= 0


class TurningLanes(SegmentTables):
    """N independent cuts stepped together: the physics of every turning env.

    Each lane has its own true parameters, spindle speed and workpiece
    (:meth:`start`); :meth:`step` advances every lane by one sample with one compiled
    kernel whose arithmetic per lane is exactly that of a single cut, so lane ``i`` of a
    batch and a batch of one give the same numbers to the last bit. All lanes share the
    parameters the linear blocks depend on (servo, filter, sample time, sub-steps): those
    of the ``params`` given here; ``start`` refuses a lane whose parameters differ in them.

    Parameters
    ----------
    params : TurningParams
        Parameters of the linear blocks (and the defaults of every lane).
    n : int
        Number of lanes.
    """

    STEP_KERNEL = staticmethod(_step_lanes)
    T_COLUMN = 5

    def __init__(self, params: TurningParams, n: int = 1) -> None:
        check_integer("n", n, 1, 1 << 24)
        self.n = int(n)
        self.params = params
        self._key = _LinearKey.of(params)
        m = params.substeps
        lags_max = int(math.ceil(60.0 / SPINDLE_RPM_RANGE[0] / params.sample_time_s + 1e-12)) + 1
        c_max = 4 * (lags_max + 1)
        filt = _speed_free_rows(self._key)[1]
        self.m, self.n_f = m, filt.shape[0]
        #: The lanes' step matrices, each as its non-zero groups of columns
        #: (``_Matrices.packed``) in two parts (``_sampled_rows``): the rows on the current
        #: pair, which every lane shares (``base``, column after column: four columns of
        #: ``2M + 3`` values), and each lane's own numbers of its feed rows (``feed[k]``,
        #: four columns of ``M`` values, ``_delayed_rows``).
        self.base = np.ascontiguousarray(_speed_free_rows(self._key)[0].T).ravel()
        self.feed = np.zeros((self.n, 4 * m))
        #: The lanes' integers in one array (one argument of the kernel), read through the
        #: views below: the step matrix's columns, the workpiece's segments, the segment the
        #: tool is in and was in after the last step, and the delay groups of the feed rows.
        self.li = np.zeros((self.n, 4 + m), dtype=np.int64)
        self._bind_views()
        self.cols[:] = 4
        self.nseg[:] = 1
        #: The sensor filter's step matrix, which every lane shares (one row).
        self.filt = filt.reshape(1, -1).copy()
        self.z = np.zeros((self.n, c_max))
        self.buf = np.zeros((self.n, filt.shape[1]))
        #: Scratch of the kernel: the step matrix's rows, then the filter's next state.
        self.work = np.zeros((self.n, 2 * m + 3 + self.n_f))
        self._new_segment_tables(self.n)  # the workpieces' tables (SegmentTables)
        #: Per lane ``[Kf, p, Ke, U_max, length, t, margin, Ts, wear per mm]``.
        self.lane_f = np.zeros((self.n, 9))
        self.finished = np.zeros(self.n, dtype=np.bool_)
        self.spindle_rpm = np.zeros(self.n)
        #: Signals of the last step, one row per lane (columns: ``LANE_SIGNALS``).
        self.out = np.zeros((self.n, len(LANE_SIGNALS)))
        #: Time at which each lane finished its workpiece in the last step (NaN if not).
        self.out_finish = np.full(self.n, np.nan)

    def _bind_views(self) -> None:
        """Name the columns of ``li``."""
        self.cols, self.nseg, self.seg, self.out_segment = (self.li[:, i] for i in range(4))
        self.lag = self.li[:, 4:]

    def __getstate__(self) -> dict:
        # A pickled view is a copy: the views are made anew from li on loading.
        views = {"cols", "nseg", "seg", "out_segment", "lag"}
        return {k: v for k, v in self.__dict__.items() if k not in views}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._bind_views()

    def start(self, lane: int, params: TurningParams, spindle_rpm: float, profile) -> None:
        """Start a new cut in ``lane``: machine at rest at the workpiece's start."""
        _check("spindle_rpm", spindle_rpm, *SPINDLE_RPM_RANGE)
        if _LinearKey.of(params) != self._key:
            raise ValueError(
                "a lane's servo, filter, sample time and sub-steps must be those of the "
                f"batch ({self._key}), got {_LinearKey.of(params)}"
            )
        segments = profile.segment_copy()
        self.fit_segments(segments.shape[1] - 1)
        rpm = float(spindle_rpm)
        full = math.isfinite(params.spindle_power_W)
        consts = self.lane_constants(params)
        if not start_lane(lane, rpm, full, consts, segments, self.speed_free, self.arrays()):
            self._load_matrices(lane, rpm, full)

    def arrays(self):
        """The lanes' arrays as the kernels take them (:data:`TurningArrays`; a new record
        after ``fit_segments`` replaced some)."""
        return gather(TurningArrays, self)

    @property
    def speed_free(self) -> SpeedFree:
        """What :func:`start_lane` reads of the linear blocks (:func:`_speed_free_tables`)."""
        return _speed_free_tables(self._key)

    def lane_constants(self, params: TurningParams) -> tuple:
        """``lane_f``'s constants of a cut with the true ``params`` (:func:`start_lane`):
        ``(Kf, p, Ke, U_max, margin, wear per mm)``."""
        margin = _velocity_bound(self._key, params.command_max) * params.sample_time_s
        return (
            params.force_coefficient,
            params.feed_exponent,
            params.sensor_gain,
            params.command_max,
            margin,
            params.wear_per_100mm / 100.0,
        )

    def _load_matrices(self, lane: int, spindle_rpm: float, full_history: bool) -> None:
        """The step matrix of ``lane`` at ``spindle_rpm``. With ``full_history`` it is padded
        with zero columns to the memory of the slowest speed, so that the lane keeps every
        sample instant it could ever need and its speed may change between samples."""
        m = self.m
        lags = _fill_matrices(
            self._key, spindle_rpm, self.feed[lane].reshape(4, m).T, self.lag[lane]
        )
        self.cols[lane] = self.z.shape[1] if full_history else 4 * (lags + 1)

    def set_speed(self, lane: int, spindle_rpm: float) -> None:
        """Change the spindle speed of a running ``lane`` from the next sample on (a lane
        started with a finite ``spindle_power_W``). The feed per revolution is then the
        travel over the last ``60 / n`` seconds at the new speed ``n``: the revolution time is
        taken at the speed of the sample (quasi-static), exact while the speed is constant."""
        if self.cols[lane] != self.z.shape[1]:
            raise RuntimeError("set_speed: the lane was started without a power limit")
        self._load_matrices(lane, float(spindle_rpm), True)
        self.spindle_rpm[lane] = float(spindle_rpm)


class TurningPlant(SingleCut):
    """Simulates one cut at a constant spindle speed: a :class:`TurningLanes` of one lane
    (:class:`~machining_envs.core.workpieces.SingleCut`, with :class:`TurningParams`; the
    depth of cut is zero past the profile's end)."""

    LANES = TurningLanes
    STEP = TurningStep

    def __init__(self, params: TurningParams, spindle_rpm: float, profile) -> None:
        _check("spindle_rpm", spindle_rpm, *SPINDLE_RPM_RANGE)
        super().__init__(params, spindle_rpm, profile)

    @property
    def _margin(self) -> float:
        """Farthest the tool can move in one sample, mm (the kernel's one-segment test)."""
        return float(self._lanes.lane_f[0, 6])

    @property
    def z(self) -> np.ndarray:
        """The cut's memory (see ``_Matrices``)."""
        return self._lanes.z[0, : self._lanes.cols[0]]

    @property
    def state(self) -> np.ndarray:
        """Servo state ``[Vf (mm/s), dVf/dt (mm/s^2), position (mm)]`` now."""
        return self.z[:3].copy()
