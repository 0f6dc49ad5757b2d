r"""End-milling plant of Park & Yoon (1986): CNC feed servo, feed per tooth, torque, sensor.

The chain of their Fig. 2, from the AC unit's command ``U`` to the measured torque ``Tc``:

.. math::

    \ddot V_f + 2\xi\omega_n \dot V_f + \omega_n^2 V_f &= \omega_n^2 K_n U
        \quad &\text{(eq. 5-7, CNC feed servo, mm/s)} \\
    f = \frac{60}{N} V_f,\quad f_t &= f / P \quad &\text{(eq. 6, feed per rev and per tooth)} \\
    T_s &= K_s\, d^{\,l} f_t^{\,m} D \quad &\text{(eq. 8, torque law)} \\
    \tau \dot T + T &= T_s \quad &\text{(eq. 10, process lag)} \\
    T_c &= K_e T + \text{noise} \quad &\text{(eq. 9, sensor, counts)}

``force_model="average_force"`` replaces eq. (8) by the mean torque of Altintas' average
cutting-force model for flat end mills (Ahn & Choi, seed 002, eq. 1):

.. math::

    \bar T = R \cdot \frac{N_f a f_t K_t}{2\pi}\,(\cos\phi_{st} - \cos\phi_{ex})
           = \frac{N_f K_t a f_t d_r}{2\pi}

(the tangential force ``K_t a h`` on each tooth, ``h = f_t \sin\phi``, times the radius,
averaged over a revolution; the immersion angles of up- and down-milling give the same
``\cos\phi_{st} - \cos\phi_{ex} = d_r / R``). :func:`mean_forces` gives the three mean
force components of the same model.

The servo and the tool position form one linear system driven by the held command; it is
discretised exactly (ZOH) on a sub-step grid once, at construction. The torque law is
evaluated at the sub-step points and drives the process lag, whose update is exact for an
input linear between sub-step points (first-order hold). All of a sample's sub-steps are a
few small matrix products.

:class:`MillingLanes` holds N cuts as arrays and advances them with one compiled kernel
(:func:`step_lanes`, numba, cached on disk); :class:`MillingPlant` is one lane of it.

This module imports numpy, scipy and numba; it knows nothing of gymnasium.
"""

from __future__ import annotations

import enum
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
    one_of,
    ranged,
    ranged_int,
)
from machining_envs.core.compiled.kernels import copy_into, matvec, powers, read_only
from machining_envs.core.compiled.schema import gather, record
from machining_envs.core.lti import zoh, zoh_tf
from machining_envs.core.workpieces import SegmentTables, SingleCut, load_segments

__all__ = [
    "MillingParams",
    "MillingPlant",
    "MillingStep",
    "CutModel",
    "FORCE_MODELS",
    "KGF",
    "SPINDLE_RPM_RANGE",
    "immersion_angles",
    "mean_forces",
    "mean_torque_average_force",
]

#: Newtons per kilogram-force: Park & Yoon give torques in kgf·mm; the library uses N·mm.
KGF = 9.80665

#: Torque laws the plant can use (``MillingParams.force_model``).
FORCE_MODELS = ("power_law", "average_force")

#: Spindle speeds the plant accepts, rpm: a vertical machining centre of the VA-40's class
#: runs from a few tens of rpm to about 6000 rpm.
SPINDLE_RPM_RANGE = (20.0, 6000.0)


@checked_params()
@dataclass(frozen=True)
class MillingParams(CheckedParams):
    """Identified parameters of the end-milling plant.

    The defaults are Park & Yoon (1986, seed 000): HSS end mill, SM45C steel, power-law
    torque. :meth:`ahn_choi_al6061` gives the average-force set of seed 002. Every field is
    a physical constant with its unit; derived quantities (process lag in seconds, discrete
    matrices, process gains) are computed from the fields.
    """

    # ---- tool and set-up -----------------------------------------------------------------
    tool_diameter_mm: float = ranged(0.0, 200.0, default=16.0, lo_open=True)
    """D, end-mill diameter, mm (paper §3.1: HSS, phi 16)."""

    n_teeth: int = ranged_int(1, 50, default=4)
    """P (N_f in seed 002), number of teeth (paper §3.1: p = 4)."""

    helix_angle_deg: float = ranged(0.0, 80.0, default=30.0)
    """Helix angle, degrees (paper Fig. 4: 30°). Mean torque and mean forces do not depend
    on it; kept to describe the tool."""

    axial_depth_mm: float = ranged(0.0, 500.0, default=32.0, lo_open=True)
    """w, axial depth of cut, mm (paper §3.1 and Fig. 4)."""

    spindle_rpm: float = ranged(*SPINDLE_RPM_RANGE, default=400.0)
    """N, nominal spindle speed, rpm (paper §3.1). Scenarios may scale it."""

    # ---- torque law ----------------------------------------------------------------------
    force_model: str = one_of(FORCE_MODELS, f"one of {FORCE_MODELS}", default="power_law")
    """``"power_law"`` (eq. 8 of seed 000) or ``"average_force"`` (eq. 1 of seed 002)."""

    torque_coefficient_kgfmm: float = ranged(0.0, 1e7, default=118.0, lo_open=True)
    """Ks of eq. (8), kgf·mm per (mm^l · mm^m · mm): T = Ks d^l f_t^m D with d and f_t in
    mm. Fitted by multiple regression on the paper's central-composite cuts (§4; the text
    calls it "K_c = 118"). In kgf·mm as published; the plant converts to N·mm."""

    depth_exponent: float = ranged(0.0, 2.0, default=0.4236, lo_open=True)
    """l, radial-depth exponent of eq. (8) (§4)."""

    feed_exponent: float = ranged(0.0, 2.0, default=0.3999, lo_open=True)
    """m, feed-per-tooth exponent of eq. (8) (§4). The feed in eq. (8) is per tooth: the
    regression cuts were set as feed per tooth, 0.025-0.1 mm (§3.1)."""

    tangential_coefficient_N_mm2: float = ranged(0.0, 1e6, default=3220.0, lo_open=True)
    """Kt of the average-force model, N/mm². Used when ``force_model="average_force"``.
    For SM45C it is not measured in either paper: chosen so that the average-force torque
    equals eq. (8) at the centre of Park & Yoon's cut design (d = 2 mm, f_t = 0.0625 mm)."""

    radial_coefficient_N_mm2: float = ranged(0.0, 1e6, default=1290.0)
    """Kr of the average-force model, N/mm² (SM45C: not measured; 0.4 Kt, typical of a
    steel cut with an HSS tool of small rake)."""

    axial_coefficient_N_mm2: float = ranged(0.0, 1e6, default=645.0)
    """Ka of the average-force model, N/mm² (SM45C: not measured; 0.2 Kt, typical of a 30°
    helix)."""

    milling_mode: str = one_of(("up", "down"), "'up' or 'down'", default="up")
    """``"up"`` (phi_st = 0, phi_ex = arccos(1 - d/R)) or ``"down"`` (phi_st = arccos(d/R - 1),
    phi_ex = pi, seed 002 eq. 5). Park & Yoon milled up (§2.4). The mean torque is the same
    for both; the mean forces differ."""

    # ---- CNC feed servo, eq. (5)-(7) -----------------------------------------------------
    servo_gain: float = ranged(0.0, 1e6, default=0.02, lo_open=True)
    """Kn, steady feed velocity per command count, mm/s per count (eq. 5; paper: 0.02 and
    0.025)."""

    servo_natural_freq_hz: float = ranged(0.0, 1e3, default=3.0, lo_open=True)
    """wn of the CNC servo loop, Hz (eq. 7). Not given: the AC command reaches the axis
    through the CNC's feed override, its cutting-feed acceleration filter (tens of ms) and
    the position loop (gain about 30 1/s on drives of the period); together they answer
    like a pair near 3 Hz, the order of the 2.66 Hz feed servo identified in seed 001."""

    servo_damping: float = ranged(0.0, 10.0, default=0.7, lo_open=True)
    """xi of the CNC servo loop (eq. 7). Not given: 0.7, the usual tuning of a position
    loop (about 5 % overshoot)."""

    # ---- process and sensor, eq. (9)-(10) ------------------------------------------------
    process_lag_rev: float = ranged(0.0, 100.0, default=0.5, lo_open=True)
    """tau of eq. (10), in spindle revolutions (tau = 60 * process_lag_rev / N s). Not
    given ("a revolution or less"): the torque the sensor reports is the mean over a
    revolution (tooth-passing and run-out ripple removed), and a one-revolution moving
    mean is, to first order, a lag of half a revolution (0.075 s at 400 rpm)."""

    sensor_gain: float = ranged(0.0, 1e6, default=0.30, lo_open=True)
    """Ke, counts per N·mm (eq. 9). Not given: chosen so that the fixed-gain integral
    controller at the paper's Kc = 0.2 is stable at Kn = 0.02 and unstable at Kn = 0.025 on
    the 3 mm step, as Fig. 5 reports (larger Kn, faster but unstable as the depth grows).
    The linearised loop puts the critical Kn at 3 mm between the two for Ke from 0.29 to
    0.36 counts per N·mm; 0.30 is taken because the torque law's gain rises as the feed
    falls, so an oscillation at 3 mm sustains itself a little below the linear bound: with
    0.30 and the nominal noise, Kn = 0.025 oscillates by about 60 % of the reference and
    Kn = 0.02 by under 8 % (``machining-bench reproduce milling``). The reference torque
    then reads about 1100 counts: a 12-bit converter spanning about twice the reference."""

    noise_std_Nmm: float = ranged(0.0, 1e6, default=36.0)
    """Standard deviation of white measurement noise, N·mm (1 % of the reference torque).
    Not given; scaled by a scenario's ``noise_scale``."""

    # ---- AC unit timing and limits -------------------------------------------------------
    sample_time_s: float = ranged(0.0, 10.0, default=0.1, lo_open=True)
    """Ts, sample time of the AC unit, s. Not given: 0.1 s, as for the turning AC of
    seed 001; about two-thirds of a revolution at 400 rpm, and three samples per period of
    the servo."""

    substeps: int = ranged_int(1, 10000, default=10)
    """Sub-steps per sample at which the torque law is evaluated. Chosen: h = 10 ms, under a
    seventh of the 75 ms process lag and of the servo's 76 ms decay time 1/(xi wn); the
    torque then stays within 0.1 % of a fine ODE solution (``tests/milling/test_plant.py``)."""

    command_max: float = ranged(0.0, 1e9, default=150.0, lo_open=True)
    """Largest command U, counts; commands are clipped to [0, command_max] (the feed does
    not reverse). Not given: with Kn = 0.02 it is 3 mm/s = 180 mm/min, 0.11 mm per tooth at
    400 rpm, just above the paper's largest test feed (0.1 mm per tooth)."""

    torque_limit_Nmm: float = ranged(0.0, 1e8, default=3600.0, lo_open=True)
    """L, the process torque limit, N·mm (367 kgf·mm): the paper's reference (constraint)
    torque, at which its controllers regulated. Not given: chosen so that
    holding Tr at every depth of the step workpiece takes, by eq. (20), the paper's
    machining time with AC (3.117 min, Table 1): 3613 N·mm exactly, rounded to 3600
    (3.145 min). Observations are normalised by it."""

    wear_per_100mm: float = ranged(0.0, 10.0, default=0.0)
    """Tool wear within the cut: the torque coefficient (Ks of eq. 8, or Kt of the
    average-force model) at position ``x`` along the workpiece is ``Ks (1 + w x / 100 mm)``.
    The tangential cutting coefficient grows almost linearly with the flank-wear land, and
    the land grows linearly with the length cut in the steady zone of the wear curve (the
    law of ``TurningParams.wear_per_100mm``, Koren & Lenz 1972, applied to the tangential
    force of each tooth). 0 (default): the papers' sharp tool; the ``wear`` scenarios draw
    ``w``."""

    breakage_torque_Nmm: float = ranged(0.0, 1e9, default=15000.0, lo_open=True)
    """Torque at which the tool is taken to break, N·mm (1530 kgf·mm). Not given: above the
    ~1200 kgf·mm that the paper's own regression cuts reached without failure (3 mm,
    0.1 mm/tooth), and about half the transverse rupture strength of HSS in bending at the
    flutes of the 152 mm overhang. The episode terminates past it."""

    # ---- parameter sets ------------------------------------------------------------------
    @classmethod
    def park_yoon_1986(cls) -> MillingParams:
        """Park & Yoon (1986): HSS 16 mm 4-tooth end mill, SM45C, 400 rpm (the defaults)."""
        return cls()

    @classmethod
    def ahn_choi_al6061(cls) -> MillingParams:
        """Ahn & Choi (seed 002): 12 mm 2-flute carbide flat end mill, Al6061, 1000 rpm.

        Average-force model with down-milling immersion (their eq. 5). The paper reports
        only the fitted [C] matrix, not Kt, Kr, Ka: Kt = 700 N/mm² sits in the middle of
        the 0.4-1.1 J/mm³ specific cutting energy tabulated for aluminium alloys; Kr and
        Ka are 0.3 and 0.2 of it, usual for a sharp positive-rake (11°), 42° helix
        carbide tool. The reference torque is the model's torque at the centre of their
        cut design (f_t = 0.05 mm, a = 10 mm) at 2 mm radial depth; the sensor gain maps
        it to the same ~1200 counts as the SM45C set (a range matched to the cut).
        """
        kt = 700.0
        ref = 2 * kt * 10.0 * 0.05 * 2.0 / (2 * math.pi)
        return cls(
            tool_diameter_mm=12.0,
            n_teeth=2,
            helix_angle_deg=42.0,
            axial_depth_mm=10.0,
            spindle_rpm=1000.0,
            force_model="average_force",
            tangential_coefficient_N_mm2=kt,
            radial_coefficient_N_mm2=0.3 * kt,
            axial_coefficient_N_mm2=0.2 * kt,
            milling_mode="down",
            sensor_gain=round(1200.0 / ref, 2),
            noise_std_Nmm=round(0.01 * ref, 2),
            torque_limit_Nmm=round(ref, 1),
            breakage_torque_Nmm=round(4.0 * ref, 0),
        )

    # ---- derived quantities (never stored) -----------------------------------------------
    @property
    def tool_radius_mm(self) -> float:
        return 0.5 * self.tool_diameter_mm

    @property
    def servo_natural_freq_rad_s(self) -> float:
        return 2.0 * math.pi * self.servo_natural_freq_hz

    def process_lag_s(self, spindle_rpm: float | None = None) -> float:
        """tau of eq. (10) in seconds at ``spindle_rpm`` (default: the nominal speed)."""
        n = self.spindle_rpm if spindle_rpm is None else spindle_rpm
        return 60.0 * self.process_lag_rev / n

    @property
    def max_feed_velocity_mm_s(self) -> float:
        """Steady feed velocity at ``command_max``, mm/s (eq. 5)."""
        return self.servo_gain * self.command_max

    def torque_gain(self, depth_mm) -> np.ndarray:
        """``c(d)`` with steady torque ``T = c(d) f_t^e`` in N·mm (f_t in mm per tooth).

        Power law: ``c = Ks D d^l`` (kgf·mm converted), ``e = m``; average force:
        ``c = N_f K_t a d / (2 pi)``, ``e = 1``.
        """
        d = np.asarray(depth_mm, dtype=np.float64)
        if self.force_model == "power_law":
            return (
                KGF * self.torque_coefficient_kgfmm * self.tool_diameter_mm * d**self.depth_exponent
            )
        return (
            self.n_teeth
            * self.tangential_coefficient_N_mm2
            * self.axial_depth_mm
            * d
            / (2.0 * math.pi)
        )

    @property
    def torque_feed_exponent(self) -> float:
        """Exponent of the feed per tooth in the active torque law (m, or 1)."""
        return self.feed_exponent if self.force_model == "power_law" else 1.0

    def steady_torque_Nmm(self, depth_mm, feed_per_tooth_mm) -> np.ndarray:
        """Torque of the active law at steady feed, N·mm (eq. 8 or seed 002 eq. 1)."""
        f = np.maximum(np.asarray(feed_per_tooth_mm, dtype=np.float64), 0.0)
        return self.torque_gain(depth_mm) * f**self.torque_feed_exponent

    def feed_per_tooth_for_torque(self, torque_Nmm, depth_mm) -> np.ndarray:
        """Feed per tooth (mm) at which the active law gives ``torque_Nmm`` at ``depth_mm``."""
        return (np.asarray(torque_Nmm, dtype=np.float64) / self.torque_gain(depth_mm)) ** (
            1.0 / self.torque_feed_exponent
        )

    def feed_velocity_for_feed(self, feed_per_tooth_mm, spindle_rpm=None) -> np.ndarray:
        """Feed velocity Vf (mm/s) of a feed per tooth: ``Vf = f_t P N / 60`` (eq. 6)."""
        n = self.spindle_rpm if spindle_rpm is None else spindle_rpm
        return np.asarray(feed_per_tooth_mm, dtype=np.float64) * self.n_teeth * n / 60.0

    def command_for_torque(self, torque_Nmm, depth_mm, spindle_rpm=None) -> np.ndarray:
        """Steady command U (counts) at which the nominal plant gives ``torque_Nmm``."""
        ft = self.feed_per_tooth_for_torque(torque_Nmm, depth_mm)
        return self.feed_velocity_for_feed(ft, spindle_rpm) / self.servo_gain

    def process_gain(self, depth_mm, torque_Nmm=None, spindle_rpm=None) -> np.ndarray:
        r"""Steady ratio ``Kp = Tc / U`` at the feed that gives ``torque_Nmm`` (counts/count).

        The gain the variable-gain estimator of eq. (12)-(15) tracks (``Km -> Kp``).
        Through eq. (5)-(9), ``Tc = K_e c(d) (60 K_n U / (N P))^e``, so

        .. math:: K_p = \frac{T_c}{U} = \frac{K_e\,T_r}{U_r}

        with ``U_r`` the command that gives the reference torque ``T_r``. The loop's
        incremental gain ``dTc/dU`` is ``e`` times it (``e = m`` for the power law).
        """
        t = self.torque_limit_Nmm if torque_Nmm is None else torque_Nmm
        return (
            self.sensor_gain
            * np.asarray(t, dtype=np.float64)
            / self.command_for_torque(t, depth_mm, spindle_rpm)
        )

    def open_loop_tf(self, spindle_rpm: float | None = None) -> tuple[list[float], list[float]]:
        r"""Unit-gain linear dynamics from command to torque, ``wn^2 / ((s^2 + 2 xi wn s + wn^2)(tau s + 1))``."""
        wn = self.servo_natural_freq_rad_s
        tau = self.process_lag_s(spindle_rpm)
        den = np.polymul([1.0, 2.0 * self.servo_damping * wn, wn**2], [tau, 1.0])
        return [wn**2], list(den)

    def discrete_open_loop(self, spindle_rpm: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """ZOH discretisation of :meth:`open_loop_tf` at ``sample_time_s``, in powers of z^-1."""
        num, den = self.open_loop_tf(spindle_rpm)
        return zoh_tf(num, den, self.sample_time_s)


# ---- average cutting-force model (seed 002) ----------------------------------------------
def immersion_angles(radial_depth_mm, tool_radius_mm: float, mode: str = "down"):
    """Start and exit angles (rad) of a flat end mill's cut, measured from the +y axis.

    ``"down"``: ``phi_st = arccos(d/R - 1)``, ``phi_ex = pi`` (seed 002 eq. 5);
    ``"up"``: ``phi_st = 0``, ``phi_ex = arccos(1 - d/R)``. Radial depths outside
    ``[0, 2R]`` raise ``ValueError``.
    """
    d = np.asarray(radial_depth_mm, dtype=np.float64)
    if not (tool_radius_mm > 0 and np.all(np.isfinite(d))):
        raise ValueError(
            f"tool_radius_mm must be > 0 and radial depths finite, got {tool_radius_mm!r}"
        )
    if np.any(d < 0) or np.any(d > 2.0 * tool_radius_mm):
        raise ValueError(
            f"radial_depth_mm must lie in [0, {2.0 * tool_radius_mm:g}] (the tool diameter), "
            f"got {radial_depth_mm!r}"
        )
    r = d / tool_radius_mm
    if mode == "down":
        return np.arccos(np.clip(r - 1.0, -1.0, 1.0)), np.full_like(r, math.pi)
    if mode == "up":
        return np.zeros_like(r), np.arccos(np.clip(1.0 - r, -1.0, 1.0))
    raise ValueError(f"mode must be 'up' or 'down', got {mode!r}")


def mean_forces(
    radial_depth_mm,
    axial_depth_mm,
    feed_per_tooth_mm,
    *,
    kt: float,
    kr: float,
    ka: float,
    n_flutes: int,
    tool_radius_mm: float,
    mode: str = "down",
) -> np.ndarray:
    r"""Mean cutting forces ``[Fx, Fy, Fz]`` (N) of a flat end mill (seed 002 eq. 1-4).

    .. math::

        \bar F_x &= \Big\{\frac{N_f a f_t}{8\pi}\big[K_t\cos 2\phi - K_r(2\phi - \sin 2\phi)\big]\Big\}_{\phi_{st}}^{\phi_{ex}} \\
        \bar F_y &= \Big\{\frac{N_f a f_t}{8\pi}\big[K_t(2\phi - \sin 2\phi) + K_r\cos 2\phi\big]\Big\}_{\phi_{st}}^{\phi_{ex}} \\
        \bar F_z &= \Big\{\frac{N_f a f_t}{2\pi}\,K_a\cos\phi\Big\}_{\phi_{st}}^{\phi_{ex}}

    (the OCR of seed 002 swaps Kt and Kr in ``F_x``; this is Altintas' form). The sign of
    ``F_z`` follows seed 002's own eq. (3)-(4), ``F_z = N a f_t C_3 K_a / (8 pi)`` with
    ``C_3 = 4 (cos phi_ex - cos phi_st)``, and its measurements (the fitted [C] gives
    ``F_z < 0`` for every cut): the axial force on the workpiece points along ``-z``. (The
    OCR of eq. 1 carries a minus sign before ``K_a``, which would flip it.) Inputs
    broadcast; the result has a trailing axis of length 3.
    """
    st, ex = immersion_angles(radial_depth_mm, tool_radius_mm, mode)
    a = np.asarray(axial_depth_mm, dtype=np.float64)
    ft = np.asarray(feed_per_tooth_mm, dtype=np.float64)
    k = n_flutes * a * ft / (8.0 * math.pi)
    c1 = np.cos(2 * ex) - np.cos(2 * st)
    c2 = 2 * (ex - st) - (np.sin(2 * ex) - np.sin(2 * st))
    c3 = np.cos(ex) - np.cos(st)
    fx = k * (kt * c1 - kr * c2)
    fy = k * (kt * c2 + kr * c1)
    fz = 4.0 * k * ka * c3
    return np.stack(np.broadcast_arrays(fx, fy, fz), axis=-1)


def mean_torque_average_force(
    radial_depth_mm, axial_depth_mm, feed_per_tooth_mm, *, kt: float, n_flutes: int
) -> np.ndarray:
    """Mean torque (N·mm) of the average-force model: ``N_f K_t a f_t d_r / (2 pi)``."""
    return (
        n_flutes
        * kt
        * np.asarray(axial_depth_mm, dtype=np.float64)
        * np.asarray(feed_per_tooth_mm, dtype=np.float64)
        * np.asarray(radial_depth_mm, dtype=np.float64)
        / (2.0 * math.pi)
    )


# ---- discrete-time machinery -------------------------------------------------------------
class _ServoKey(NamedTuple):
    """The fields the servo's discretisation depends on (not the spindle or torque law)."""

    servo_gain: float
    servo_natural_freq_rad_s: float
    servo_damping: float
    sample_time_s: float
    substeps: int

    of = classmethod(fields_of)


@functools.lru_cache(maxsize=64)
def _servo_matrix(key: _ServoKey) -> np.ndarray:
    """``big @ [Vf, dVf/dt, x, U]``: the feed velocity at the M sub-step points, the position
    at the M sub-step points and the next state (3 rows), all exact (ZOH); read-only."""
    m = key.substeps
    h = key.sample_time_s / m
    wn, z = key.servo_natural_freq_rad_s, key.servo_damping
    a = np.array([[0.0, 1.0, 0.0], [-(wn**2), -2.0 * z * wn, 0.0], [1.0, 0.0, 0.0]])
    b = np.array([[0.0], [key.servo_gain * wn**2], [0.0]])
    phi_h, gam_h = zoh(a, b, h)
    big = np.zeros((2 * m + 3, 4))
    phi, gam = np.eye(3), np.zeros(3)
    for j in range(m):
        phi = phi_h @ phi
        gam = phi_h @ gam + gam_h[:, 0]
        big[j, :3], big[j, 3] = phi[0], gam[0]
        big[m + j, :3], big[m + j, 3] = phi[2], gam[2]
    big[2 * m :, :3], big[2 * m :, 3] = phi, gam
    return read_only(big)


@numba.njit(cache=True)
def lag_rows(m, h, lag_s, out):
    """Fill ``out`` (``(m, m + 2)``) with the lag matrix: ``out @ [T_0, u_0, ..., u_M]`` is
    the lagged torque at the M sub-step points for a static torque ``u`` linear between
    sub-step points (exact first-order hold of eq. 10)."""
    r = h / lag_s
    alpha = math.exp(-r)
    if r < 1e-6:  # series, to avoid cancellation
        b1 = b0 = 0.5 * r
    else:
        b1 = 1.0 - (1.0 - alpha) / r
        b0 = (1.0 - alpha) / r - alpha
    n = m + 2
    row = np.zeros(n)
    row[0] = 1.0  # T_0
    for j in range(m):
        for q in range(n):
            row[q] = alpha * row[q]
        row[1 + j] += b0
        row[2 + j] += b1
        copy_into(out[j], row)


@dataclass(slots=True)
class MillingStep:
    """Signals of one sample period, at its end (the sample instant) unless stated."""

    torque_Nmm: float
    """Cutting torque (after the process lag) at the sample instant, N·mm."""
    peak_torque_Nmm: float
    """Largest cutting torque over the period's sub-steps, N·mm."""
    measured_counts: float
    """Sensor output Tc = Ke T + noise, counts (eq. 9)."""
    feed_velocity_mm_s: float
    """Feed velocity Vf at the sample instant, mm/s."""
    feed_mm_per_rev: float
    """Feed per revolution 60 Vf / N at the sample instant, mm/rev (eq. 6)."""
    mean_feed_mm_per_rev: float
    """Mean feed per revolution over the period, mm/rev: distance fed / revolutions turned."""
    position_mm: float
    """Distance fed along the workpiece since the start, mm."""
    depth_mm: float
    """Radial depth of cut at the sample instant, mm (0 outside the workpiece)."""
    segment: int
    """Index of the workpiece segment the tool is in (``DepthProfile`` segment)."""
    finish_time_s: float | None = None
    """Time at which ``position_mm`` first reached the workpiece length, if in this period
    (linear between sub-step points)."""


# ---- the batched physics: N cuts stepped as arrays, one kernel for one lane or many --------

#: Columns of ``MillingLanes.lane_f`` (per-lane constants, and the lane's clock).
LANE_CONSTANTS = (
    "command_max",  # U_max, counts
    "ft_per_vf",  # 60 / (N P): feed per tooth per feed velocity, mm per (mm/s)
    "feed_exponent",  # exponent of f_t in the torque law (m, or 1)
    "torque_gain",  # c of T = c d^l f_t^e (N·mm)
    "depth_exponent",  # l (power law; 1 for the average-force model)
    "power_law",  # 1.0 for the power law, 0.0 for the average-force model
    "sensor_gain",  # Ke, counts per N·mm
    "length_mm",  # workpiece length
    "t_s",  # time since the cut started
    "substep_s",  # h = Ts / M
    "sample_time_s",  # Ts
    "spindle_rpm",  # N
    "rev_per_s",  # N / 60
    "plateau_scale",  # c d^l of the plateau the tool was last in (d constant)
    "plateau",  # index of that plateau (-1: none yet)
    "wear_per_mm",  # w of the torque coefficient's growth Ks (1 + w x) (0: a sharp tool)
)
#: The columns of ``MillingLanes.lane_f`` by name (``lane_f[k, LC.t_s]``).
LC = enum.IntEnum("LC", LANE_CONSTANTS, start=0, module=__name__)

#: The arrays of :class:`MillingLanes` its kernels read and write (its attributes of
#: these names), as one argument: :func:`step_lanes`' and :func:`start_lane`'s.
MillingArrays = record(
    "MillingArrays",
    __name__,
    """
    big: shared f8_2
    lag z buf lane_f edges d0 slope out work: lanes f8_2
    nseg seg out_segment: lanes i8_1
    finished: lanes b1_1
    m: shared i8
    out_finish: lanes f8_1
    """,
)

#: Fields of ``MillingLanes.out`` (one row per lane after each step).
LANE_SIGNALS = (
    "torque_Nmm",
    "peak_torque_Nmm",
    "measured_counts",
    "feed_velocity_mm_s",
    "feed_mm_per_rev",
    "mean_feed_mm_per_rev",
    "position_mm",
    "depth_mm",
)


@numba.njit(cache=True)
def bisect_right(edges, k, n, x):
    """Index of the first of ``edges[k, :n]`` (sorted) above ``x``; ``n`` for NaN (as
    ``np.searchsorted(..., side="right")``)."""
    lo = 0
    hi = n
    while lo < hi:
        mid = (lo + hi) // 2
        if x < edges[k, mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@numba.njit(cache=True)
def _depth_at(x, edges, d0, slope, k, nseg):
    """Radial depth (mm) at ``x`` of lane ``k``'s profile; zero outside ``[0, length)``
    (``DepthProfile.__call__`` at one position)."""
    if not (x >= 0.0 and x < edges[k, nseg]):
        return 0.0
    i = bisect_right(edges, k, nseg + 1, x) - 1
    i = min(max(i, 0), nseg - 1)
    return d0[k, i] + slope[k, i] * (x - edges[k, i])


@numba.njit(cache=True)
def step_lanes(a, commands, noise):
    """Advance every lane of the arrays ``a`` (:data:`MillingArrays`; see
    :class:`MillingLanes` for the layout) by one sample.

    Lane ``k`` holds ``commands[k]`` (counts, clipped to ``[0, U_max]``): the servo and
    position at the M sub-step points and the next state are one product with ``big[0]``;
    the torque law at the sub-step points drives the process lag (one product with the
    lane's ``lag[k]``); the sensor reads ``Ke T + noise[k]``. ``out[k]`` gets the signals
    of ``LANE_SIGNALS``, ``out_seg[k]`` the workpiece segment and ``out_finish[k]`` the time
    the tool reached the workpiece's end in this sample (NaN if it did not). The
    arithmetic of a lane is that of one cut, whatever the other lanes do. ``work`` is
    scratch space, ``(n, 4 M + 3)``: ``work[k, :2M + 3]`` gets ``big[0] @ z[k]`` (feed
    velocity at the M sub-steps, position at the M sub-steps, next ``[Vf, dVf/dt, x]``),
    ``work[k, 2M + 3 : 3M + 3]`` the M lagged torques (before them, the feeds per tooth and
    the depths' powers on their way to ``buf``), ``work[k, 3M + 3:]`` the depths along a
    taper.
    """
    big, lag, z, buf, lane_f, work, m = a.big, a.lag, a.z, a.buf, a.lane_f, a.work, a.m
    edges, d0, slope, nseg, seg, finished = a.edges, a.d0, a.slope, a.nseg, a.seg, a.finished
    out, out_seg, out_finish = a.out, a.out_segment, a.out_finish
    n_lanes = z.shape[0]
    tq = 2 * m + 3
    for k in range(n_lanes):
        u = commands[k]
        if 0.0 > u:
            u = 0.0
        if lane_f[k, LC.command_max] < u:
            u = lane_f[k, LC.command_max]
        z[k, 3] = u
    matvec(big, tq, 4, z, work)
    for k in range(n_lanes):
        ftpv = lane_f[k, LC.ft_per_vf]
        fexp = lane_f[k, LC.feed_exponent]
        c = lane_f[k, LC.torque_gain]
        dexp = lane_f[k, LC.depth_exponent]
        power = lane_f[k, LC.power_law] != 0.0
        p_end = work[k, 2 * m - 1]
        # buf[k] = [T_0, u_0, u_1 .. u_M]: the static torque at this sample's sub-steps
        if fexp == 1.0:
            for j in range(m):
                v = work[k, j]
                # no reverse feed (NaN passes, caught by the env)
                buf[k, 2 + j] = 0.0 if v <= 0.0 else v * ftpv
        else:  # (f_t)**e, 0 for no or reverse feed; the feeds per tooth wait in the
            # place of the lagged torques, which the lag's product fills below
            wk = work[k]
            for j in range(m):
                wk[tq + j] = wk[j] * ftpv
            powers(wk, tq, buf[k], 2, m, fexp)
        i = seg[k]
        lo = work[k, m]
        hi = lo
        for j in range(m, 2 * m):
            x = work[k, j]
            if x < lo:
                lo = x
            elif x > hi:
                hi = x
            elif x != x:  # NaN: no segment holds it
                lo = hi = np.nan
                break
        if edges[k, i] <= lo and hi < edges[k, i + 1]:  # every sub-step in the segment
            sl = slope[k, i]
            if sl == 0.0:
                depth_end = d0[k, i]
                if lane_f[k, LC.plateau] == i:
                    scale = lane_f[k, LC.plateau_scale]
                else:
                    scale = c * depth_end**dexp if power else c * depth_end
                    lane_f[k, LC.plateau_scale] = scale
                    lane_f[k, LC.plateau] = i
                for j in range(m):
                    buf[k, 2 + j] *= scale
            elif power:  # a taper: the depths' powers in vectors, through the scratch
                wk = work[k]
                for j in range(m):
                    wk[tq + m + j] = (work[k, m + j] - edges[k, i]) * sl + d0[k, i]
                depth_end = wk[tq + 2 * m - 1]
                powers(wk, tq + m, wk, tq, m, dexp)
                for j in range(m):
                    buf[k, 2 + j] *= c * wk[tq + j]
            else:
                depth_end = 0.0
                for j in range(m):
                    depth_end = (work[k, m + j] - edges[k, i]) * sl + d0[k, i]
                    buf[k, 2 + j] *= c * depth_end
        else:
            n_s = nseg[k]
            depth_end = 0.0
            for j in range(m):
                depth_end = _depth_at(work[k, m + j], edges, d0, slope, k, n_s)
                buf[k, 2 + j] *= c * depth_end**dexp if power else c * depth_end
            i = bisect_right(edges, k, n_s + 1, p_end) - 1
            seg[k] = min(max(i, 0), n_s - 1)
        wear = lane_f[k, LC.wear_per_mm]
        if wear != 0.0:  # Ks (1 + w x): the tool dulls along the cut (wear_per_100mm)
            for j in range(m):
                buf[k, 2 + j] *= 1.0 + wear * work[k, m + j]
        out[k, 7] = depth_end
    lagged = work[:, tq:]
    matvec(lag, m, m + 2, buf, lagged)
    for k in range(n_lanes):
        t_end = lagged[k, m - 1]
        peak = lagged[k, 0]
        for j in range(1, m):
            v = lagged[k, j]
            if v > peak or v != v:  # NaN propagates, as in max()
                peak = v
        buf[k, 0] = t_end
        buf[k, 1] = buf[k, m + 1]
        p_start = z[k, 2]
        p_end = work[k, 2 * m - 1]
        vf = work[k, 2 * m]
        z[k, 0] = vf
        z[k, 1] = work[k, 2 * m + 1]
        z[k, 2] = work[k, 2 * m + 2]
        out[k, 0] = t_end
        out[k, 1] = peak
        out[k, 2] = lane_f[k, LC.sensor_gain] * t_end + noise[k]
        out[k, 3] = vf
        out[k, 4] = vf * 60.0 / lane_f[k, LC.spindle_rpm]
        out[k, 5] = (p_end - p_start) / (lane_f[k, LC.rev_per_s] * lane_f[k, LC.sample_time_s])
        out[k, 6] = p_end
        out_seg[k] = seg[k]
        out_finish[k] = np.nan
        t = lane_f[k, LC.t_s]
        length = lane_f[k, LC.length_mm]
        if not finished[k] and p_end >= length:
            j = 0
            while not work[k, m + j] >= length:
                j += 1
            x_prev = work[k, m + j - 1] if j > 0 else p_start
            x_j = work[k, m + j]
            frac = (length - x_prev) / (x_j - x_prev) if x_j > x_prev else 1.0
            if 0.0 > frac:
                frac = 0.0
            if 1.0 < frac:
                frac = 1.0
            out_finish[k] = t + (j + frac) * lane_f[k, LC.substep_s]
            finished[k] = True
        lane_f[k, LC.t_s] = t + lane_f[k, LC.sample_time_s]


def check_depth(profile, params: MillingParams) -> None:
    """``ValueError`` for a workpiece (``DepthProfile``) deeper radially than the tool of
    ``params`` is wide."""
    if profile.max_depth_mm > params.tool_diameter_mm:
        raise ValueError(
            f"radial depth of the workpiece must be at most the tool diameter "
            f"{params.tool_diameter_mm:g} mm, got {profile.max_depth_mm:g} mm"
        )


@numba.njit(cache=True)
def start_lane(k, row, lag_s, segments, a):
    """Lane ``k``'s arrays (``a``, :data:`MillingArrays`) at the start of a cut on the workpiece
    ``segments`` (``DepthProfile.segment_array``; the tables must hold its segments), the
    tool at rest at its start: its constants ``row`` (:meth:`MillingLanes.lane_constants`;
    only its first ``len(LANE_CONSTANTS)`` values are read) and the lag matrix of the
    process lag ``lag_s`` (:func:`lag_rows`)."""
    lag, z, buf, lane_f, nseg, seg = a.lag, a.z, a.buf, a.lane_f, a.nseg, a.seg
    m = buf.shape[1] - 2
    lag_rows(m, row[LC.substep_s], lag_s, lag[k].reshape((m, m + 2)))  # a view: filled in place
    z[k, :] = 0.0
    buf[k, :] = 0.0
    ns = segments.shape[1] - 1
    load_segments(segments, k, a.edges, a.d0, a.slope)
    nseg[k] = ns
    seg[k] = 0
    for i in range(lane_f.shape[1]):
        lane_f[k, i] = row[i]
    lane_f[k, LC.length_mm] = segments[0, ns]
    a.finished[k] = False


class CutModel(NamedTuple):
    """One lane's torque model as a controller reads it (:meth:`MillingLanes.cut_model`):
    the static torque of a feed velocity ``vf`` at depth ``d`` is
    ``torque_gain d^depth_exponent (ft_per_vf vf)^feed_exponent``."""

    command_max: float
    """U_max, the servo's largest command, counts."""
    ft_per_vf: float
    """60 / (N P): feed per tooth per feed velocity, mm per (mm/s)."""
    feed_exponent: float
    """Exponent of the feed per tooth in the torque law (m, or 1)."""
    torque_gain: float
    """c of T = c d^l f_t^e, N·mm."""
    depth_exponent: float
    """l (1 for the average-force model)."""
    t_s: float
    """Time since the cut started, s."""


class MillingLanes(SegmentTables):
    """N independent cuts stepped together: the physics of every end-milling env.

    Each lane has its own true parameters (torque law and its coefficients, sensor gain),
    spindle speed and workpiece (:meth:`start`); :meth:`step` advances every lane by one
    sample with one compiled kernel (:func:`step_lanes`) whose arithmetic per lane is that
    of a single cut, so lane ``i`` of a batch and a batch of one give the same numbers to
    the last bit. All lanes share the servo's discretisation (servo gain, natural
    frequency, damping, sample time, sub-steps): that of the ``params`` given here;
    :meth:`start` refuses a lane whose parameters differ in them. The process lag's matrix
    depends on the spindle speed and is built per lane when the lane starts.

    Parameters
    ----------
    params : MillingParams
        Parameters of the shared servo (and the defaults of every lane).
    n : int
        Number of lanes.

    Attributes
    ----------
    big : ndarray, shape (1, (2 M + 3) * 4)
        The servo's step matrix (``_servo_matrix``), row after row, shared by the lanes.
    lag : ndarray, shape (n, M * (M + 2))
        Each lane's lag matrix (:func:`lag_rows` at its spindle speed), row after row.
    z : ndarray, shape (n, 4)
        ``[Vf, dVf/dt, position, U]`` of every lane.
    buf : ndarray, shape (n, M + 2)
        ``[T, u_0, u_1 .. u_M]``: the lagged torque now and the static torque of the last
        sample's sub-steps (``u_0`` the one before them).
    lane_f : ndarray, shape (n, len(LANE_CONSTANTS))
        Per-lane constants and clock (columns ``LANE_CONSTANTS``).
    out, out_segment, out_finish : ndarray
        Signals of the last step (``LANE_SIGNALS``), segment, finish time (NaN if none).
    """

    STEP_KERNEL = staticmethod(step_lanes)
    T_COLUMN = LC.t_s

    def __init__(self, params: MillingParams, n: int = 1) -> None:
        check_integer("n", n, 1, 1 << 24)
        self.n = int(n)
        self.params = params
        self._key = _ServoKey.of(params)
        m = params.substeps
        self.m = m
        self.big = _servo_matrix(self._key).reshape(1, -1)  # one (2M + 3, 4) matrix
        self.lag = np.zeros((self.n, m * (m + 2)))  # each lane's (M, M + 2) matrix
        self.z = np.zeros((self.n, 4))
        self.buf = np.zeros((self.n, m + 2))
        self.lane_f = np.zeros((self.n, len(LANE_CONSTANTS)))
        self._new_segment_tables(self.n)  # the workpieces' tables (SegmentTables)
        self.nseg = np.ones(self.n, dtype=np.int64)
        self.seg = np.zeros(self.n, dtype=np.int64)
        self.finished = np.zeros(self.n, dtype=np.bool_)
        self.out = np.zeros((self.n, len(LANE_SIGNALS)))
        self.out_segment = np.zeros(self.n, dtype=np.int64)
        self.out_finish = np.full(self.n, np.nan)
        #: Scratch space of the kernel (see :func:`step_lanes`).
        self.work = np.zeros((self.n, 4 * m + 3))

    def cut_model(self, lane: int) -> CutModel:
        """``lane``'s true torque model and clock as it stands (see :class:`CutModel`), for
        model-based controllers and oracles that read the plant."""
        lf = self.lane_f[lane]
        c = {name: float(lf[i]) for i, name in enumerate(LANE_CONSTANTS)}
        return CutModel(
            command_max=c["command_max"],
            ft_per_vf=c["ft_per_vf"],
            feed_exponent=c["feed_exponent"],
            torque_gain=c["torque_gain"],
            depth_exponent=c["depth_exponent"] if c["power_law"] != 0.0 else 1.0,
            t_s=c["t_s"],
        )

    def start(self, lane: int, params: MillingParams, spindle_rpm: float, profile) -> None:
        """Start a new cut in ``lane``: tool at rest at the workpiece's start, no torque.

        ``ValueError`` for a spindle speed outside ``SPINDLE_RPM_RANGE``, a workpiece deeper
        than the tool is wide, or servo parameters other than the batch's.
        """
        check_range("spindle_rpm", spindle_rpm, *SPINDLE_RPM_RANGE)
        check_depth(profile, params)
        if params is not self.params and _ServoKey.of(params) != self._key:
            raise ValueError(
                "a lane's servo gain, natural frequency, damping, sample time and sub-steps "
                f"must be those of the batch ({self._key}), got {_ServoKey.of(params)}"
            )
        rpm = float(spindle_rpm)
        segments = profile.segment_copy()
        self.fit_segments(segments.shape[1] - 1)
        row = self.lane_constants(params, rpm)
        start_lane(lane, row, params.process_lag_s(rpm), segments, self.arrays())

    def arrays(self):
        """The lanes' arrays as the kernels take them (:data:`MillingArrays`; a new record
        after ``fit_segments`` replaced some)."""
        return gather(MillingArrays, self)

    @staticmethod
    def lane_constants(params: MillingParams, spindle_rpm: float) -> np.ndarray:
        """A lane's row of ``lane_f`` (``LANE_CONSTANTS``) at the start of a cut with the
        true ``params`` at ``spindle_rpm``, the workpiece's length 0 (:func:`start_lane`
        writes it)."""
        rpm = spindle_rpm
        if params.force_model == "power_law":
            c = KGF * params.torque_coefficient_kgfmm * params.tool_diameter_mm
            dexp, power = params.depth_exponent, 1.0
        else:
            c = params.torque_gain(1.0).item()
            dexp, power = 1.0, 0.0
        row = {
            "command_max": params.command_max,
            "ft_per_vf": 60.0 / (rpm * params.n_teeth),
            "feed_exponent": params.torque_feed_exponent,
            "torque_gain": c,
            "depth_exponent": dexp,
            "power_law": power,
            "sensor_gain": params.sensor_gain,
            "length_mm": 0.0,
            "t_s": 0.0,
            "substep_s": params.sample_time_s / params.substeps,
            "sample_time_s": params.sample_time_s,
            "spindle_rpm": rpm,
            "rev_per_s": rpm / 60.0,
            "plateau_scale": 0.0,
            "plateau": -1.0,
            "wear_per_mm": params.wear_per_100mm / 100.0,
        }
        return np.array([row[name] for name in LANE_CONSTANTS])


class MillingPlant(SingleCut):
    """Simulates one cut at a constant spindle speed: a :class:`MillingLanes` of one lane
    (:class:`~machining_envs.core.workpieces.SingleCut`, with :class:`MillingParams`; the
    profile is the radial depth of cut, zero outside it)."""

    LANES = MillingLanes
    STEP = MillingStep

    @property
    def z(self) -> np.ndarray:
        """``[Vf, dVf/dt, position, U]``: the servo's state and the command held (a view)."""
        return self._lanes.z[0]

    @property
    def state(self) -> np.ndarray:
        """``[Vf (mm/s), dVf/dt (mm/s^2), position (mm), torque (N·mm)]`` now."""
        lanes = self._lanes
        return np.array([lanes.z[0, 0], lanes.z[0, 1], lanes.z[0, 2], lanes.buf[0, 0]])
