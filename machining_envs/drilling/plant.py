r"""Micro-drilling plant of Cheong & Cho: valve, air-turbine spindle, drilling torque and thrust.

The chain from the valve voltage ``u`` to the torque on the drill (their §3 and §6):

.. math::

    \ddot x_v + 2\zeta\omega_n \dot x_v + \omega_n^2 x_v &= k_1 u
        \quad &\text{(eq. 1, 17: pneumatic proportional valve)} \\
    \dot\omega &= k_2 x_v - k_3 \omega^{0.608} - T / I
        \quad &\text{(eq. 2-4, 19: air-turbine spindle)} \\
    T &= k_4 / \omega \quad &\text{(eq. 20: drilling torque at a fixed feed velocity)}

with ``x_v`` the spool displacement (as a fraction of full opening), ``\omega`` the spindle
speed (rad/s) and ``k_4`` the torque constant of the current cut:

.. math::

    k_4 = 2\pi\, c_T(D)\, v_f\, \epsilon(z)\, \bigl(1 + w z + g(L)\,(1 + \sigma_c \xi_c)\bigr)
          (1 + \sigma_0 \xi_0)

- ``c_T(D)`` (N·mm per mm/rev) comes from the cutting model of §3.2, evaluated once per drill:
  the main lips in oblique cutting (eq. 6-9), the chisel edge as a secondary cutting edge
  (eq. 10-13) and the indentation zone (eq. 14); see :func:`cutting_coefficients`. The
  feed per revolution is ``f = 2\pi v_f / \omega``, so torque is ``k_4 / \omega`` (eq. 20);
- ``\epsilon(z)`` is the share of the lips engaged while the drill point enters the work;
- ``g(L) = g_0 (e^{L / (\ell D)} - 1)`` is the friction of the chips packed in the flutes,
  growing with the length ``L`` drilled since the chips were last cleared (Fig. 12, §5.1);
  leaving the hole (a peck) clears them;
- ``w`` is the drill's wear per mm drilled (``wear_per_mm``, 0 by default: the paper's
  sharp drill); the edge does not recover when the chips are cleared;
- ``\xi_c``, ``\xi_0`` are unit Ornstein-Uhlenbeck processes: the chip packing is irregular.

The paper's eq. (19) leaves out the drilling torque acting back on the spindle; here it is
kept as ``-T / I`` (the spindle slows under load, their Fig. 8(c)). Thrust follows the same
cutting model. The valve is linear and integrated exactly (ZOH, matrices computed once);
the spindle is integrated with fixed RK4 sub-steps in which the valve position comes from
the exact solution.

The physics is batched: :class:`DrillingLanes` holds N holes in arrays and one compiled
kernel (:func:`advance`, numba, cached on disk) advances them; :class:`DrillingPlant` is
one such lane. This module knows nothing of gymnasium.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numba
import numpy as np

from machining_envs.core.checks import (
    CheckedParams,
    check_below,
    check_integer,
    check_range,
    checked_params,
    ranged,
    ranged_int,
)
from machining_envs.core.compiled.kernels import copy_into, powers, py_square, read_only
from machining_envs.core.lti import zoh

__all__ = [
    "DrillingParams",
    "DrillingPlant",
    "DrillingLanes",
    "LANE_SIGNALS",
    "LANE_BLOCK",
    "advance",
    "DrillingStep",
    "CuttingCoefficients",
    "cutting_coefficients",
    "DIAMETER_RANGE_MM",
]

#: Drill diameters the plant accepts, mm: the paper's micro drills (0.5-0.8 mm, Table 1 and
#: Fig. 18-21) with some room either side. Outside it the size-effect shear stress and the
#: breakage law below are no longer plausible.
DIAMETER_RANGE_MM = (0.3, 1.0)

_TWO_PI = 2.0 * math.pi


@checked_params(across=("voltage_max", "feed_velocity_mm_s", "feed_speed_max_mm_s"))
@dataclass(frozen=True)
class DrillingParams(CheckedParams):
    """Parameters of the micro-drilling plant (Cheong & Cho, seed 003).

    The paper identifies the valve-spindle constants and the shear and friction angles by a
    genetic algorithm but prints none of them; every such value here is chosen, with the
    reason beside it. Derived quantities (``k1``, the free spindle speed, the cutting
    coefficients, the breakage torque) are computed from the fields, never stored.
    """

    # ---- valve (eq. 1, 17) -------------------------------------------------------------
    valve_natural_freq_hz: float = ranged(0.0, 1e3, default=8.0, lo_open=True)
    """wn of the pneumatic proportional valve, Hz (eq. 17). Not given: 8 Hz (50 rad/s), a
    response time of about 0.1 s, typical of proportional pressure valves of this size."""

    valve_damping: float = ranged(0.0, 10.0, default=0.7, lo_open=True)
    """zeta of the valve (eq. 17). Not given: 0.7, a well-damped spool."""

    valve_static_gain_per_V: float = ranged(0.0, 10.0, default=0.1, lo_open=True)
    """Steady spool opening per volt, ``k1 / wn^2`` (eq. 17), 1/V. Chosen so that the spool
    is fully open (x_v = 1) at ``voltage_max`` = 10 V; ``k1`` follows as a property."""

    voltage_max: float = ranged(0.0, 1e3, default=10.0, lo_open=True)
    """Largest valve voltage, V (a 0-10 V proportional valve); commands are clipped to
    [0, voltage_max]."""

    nominal_voltage: float = 5.0
    """Voltage of the nominal cut, V, at which the unloaded spindle runs at 545 Hz (Table 1's
    initial spindle frequency). Chosen mid-range so controllers can speed the spindle up
    about threefold (to 1700 Hz at 10 V) and also slow it."""

    # ---- air spindle (eq. 2-4, 19) -----------------------------------------------------
    spindle_friction_exponent: float = ranged(0.1, 1.0, default=0.608)
    """n of the air friction ``theta_dot^n`` (eq. 4, 19), identified in the paper."""

    spindle_drive_gain: float = ranged(0.0, 1e9, default=45057.05, lo_open=True)
    """k2 = Kv A N r_av / I, rad/s^2 per unit spool opening (eq. 19). Not given: chosen with
    ``spindle_friction`` so that the unloaded spindle settles at 545 Hz at the nominal 5 V
    (k2 x_v = k3 w^n at w = 2 pi 545) with a time constant of 0.25 s there
    (1 / (n k3 w^(n-1)) = 0.25 s: an air turbine reaches speed in about a second)."""

    spindle_friction: float = ranged(0.0, 1e9, default=159.849, lo_open=True)
    """k3, air friction coefficient, (rad/s^2) / (rad/s)^n (eq. 19). Chosen with
    ``spindle_drive_gain`` (see there)."""

    spindle_inertia_Nmm_s2: float = ranged(0.0, 1e6, default=1.0e-3, lo_open=True)
    """I, rotor inertia, N·mm·s^2 (1e-6 kg·m^2: a turbine rotor of about 15 g and 12 mm with
    its collet). Not given; it sets how much the drilling torque slows the spindle (the
    paper's eq. 19 leaves that term out). The turbine then gives 22.5 N·mm, about 77 W, at
    545 Hz, and a 1 N·mm load slows it by 7 %."""

    # ---- drill geometry and cutting model (§3.2) ---------------------------------------
    point_angle_deg: float = ranged(60.0, 170.0, default=118.0)
    """Point angle 2 kappa, degrees. Not given: the standard 118 degrees of twist drills."""

    helix_angle_deg: float = ranged(0.0, 50.0, default=30.0)
    """Helix angle at the drill's periphery, degrees. Not given: 30 degrees, usual for micro
    drills for steel."""

    web_ratio: float = ranged(0.0, 0.5, default=0.15, lo_open=True)
    """Web thickness over drill diameter, 2w/D. Not given: 0.15, chosen with
    ``chisel_rake_deg`` so that the chisel edge carries 35 % of the thrust, inside the
    30-40 % the paper cites (§3.2)."""

    friction_angle_deg: float = ranged(0.0, 60.0, default=35.0)
    """Normal friction angle beta_n on the lips (eq. 7-9), degrees. Identified by GA in the
    paper, value not given: 35 degrees, typical of steel on carbide."""

    chisel_rake_deg: float = ranged(-70.0, 0.0, default=-45.0)
    """Static rake angle of the chisel edge, degrees (eq. 10-11). Not given: -45 degrees,
    within the -30 to -60 degrees of twist-drill chisel edges."""

    shear_stress_MPa: float = ranged(0.0, 1e5, default=3000.0, lo_open=True)
    """Effective shear flow stress tau of SS40 (SS400) in eq. (6)-(11), N/mm^2. Identified
    by GA in the paper, value not given. At the paper's 0.32 mm/s and 545 Hz the chip per
    lip is 0.15 um thick, far below the edge radius of a micro drill, where the specific
    cutting energy of steel is several times its macroscopic value (size effect); 3000 MPa,
    about seven times the macroscopic shear flow stress, gives 0.41 N·mm and 1.4 N of
    thrust for the 0.8 mm drill in the nominal cut."""

    indentation_coeff_MPa: float = ranged(0.0, 1e5, default=1200.0)
    """k_c of the indentation thrust k_c f^2 tan(alpha_w) (eq. 14), N/mm^2 (about 3x the
    Brinell hardness of SS400). At micro-drilling feeds its thrust is below 0.1 %."""

    indentation_wedge_deg: float = ranged(0.0, 89.0, default=60.0)
    """Half wedge angle alpha_w of the indenting chisel centre (eq. 14), degrees."""

    # ---- chips packed in the flutes (§5.1, Fig. 12) ------------------------------------
    chip_friction: float = ranged(0.0, 100.0, default=0.235)
    """g0 of the chip friction ratio g(L) = g0 (exp(L / (l D)) - 1). Not given: with
    ``chip_length_diameters`` = 5 the torque of a hole drilled in one pass has grown 2.5x by
    an aspect ratio of 10 (Fig. 12 shows a steady rise with depth; chip evacuation forces
    grow exponentially with hole depth)."""

    chip_length_diameters: float = ranged(0.0, 1e3, default=5.0, lo_open=True)
    """l, the packed length (in drill diameters) over which chip friction grows e-fold."""

    chip_fluctuation: float = ranged(0.0, 2.0, default=0.2)
    """sigma_c, relative standard deviation of the chip friction (chips pack and release
    irregularly). Not given; scaled by a scenario's ``fluctuation_scale``."""

    chip_fluctuation_time_s: float = ranged(0.0, 100.0, default=0.2, lo_open=True)
    """Correlation time of the chip-friction fluctuation, s (an Ornstein-Uhlenbeck process)."""

    # ---- drill wear within the hole (off by default) ----------------------------------------
    wear_per_mm: float = ranged(0.0, 10.0, default=0.0)
    """Drill wear within the hole: the chip-free cutting torque and thrust at hole depth
    ``z`` are ``(1 + w z / mm)`` times the sharp drill's, ``w`` this share per mm drilled.
    Cutting forces grow almost linearly with the flank-wear land (the flank-wear force model
    of Koren & Lenz, 1972), and the land grows linearly with the length cut in the steady
    zone of the wear curve, so the coefficient grows linearly with the depth drilled. Kept
    apart from the chips: the chip friction ``g(L)`` is a share of the sharp drill's
    torque and a peck clears it; a peck does not restore the edge. 0 (default) is the
    paper's sharp drill, bit for bit; the ``wear`` scenarios draw ``w`` (see
    ``machining_envs.drilling.scenarios``)."""

    cutting_fluctuation: float = ranged(0.0, 0.5, default=0.03)
    """sigma_0, relative standard deviation of the chip-free cutting torque and thrust
    (material and edge irregularity); correlation time ``cutting_fluctuation_time_s``."""

    cutting_fluctuation_time_s: float = ranged(0.0, 100.0, default=0.05, lo_open=True)
    """Correlation time of the cutting fluctuation, s."""

    # ---- drill strength ------------------------------------------------------------------
    breakage_coeff_N_per_mm2: float = ranged(0.0, 1e6, default=5.0, lo_open=True)
    """c_b of the breakage torque T_b = c_b D^3 (N·mm, D in mm). The torsional strength of a
    drill's section grows as D^3; the paper gives no strength data. Micro drills rarely fail
    by static torsion (chip clogging, bending from wandering and fatigue break them far
    below it), so the constant is set by the process instead: the paper's holes (aspect
    ratio 10, nominal chips) drilled in one pass without control peak at 55-90 % of it over
    seeds, so none breaks, while deeper or more chip-clogged holes do.
    T_b = 0.625, 1.08, 1.715, 2.56 N·mm for 0.5, 0.6, 0.7, 0.8 mm: 3.9x to 6.2x the
    chip-free nominal torque (small drills are closer to breaking)."""

    # ---- feed (micro-stepping motor) -----------------------------------------------------
    feed_velocity_mm_s: float = ranged(0.0, 100.0, default=0.32, lo_open=True)
    """Feed velocity of the paper's runs, mm/s (Table 1)."""

    feed_speed_max_mm_s: float = ranged(0.0, 100.0, default=3.0, lo_open=True)
    """Largest feed or retract speed of the stage, mm/s (``control="feed"`` maps actions onto
    [-feed_speed_max_mm_s, feed_speed_max_mm_s]). Not given: 3 mm/s, a rapid traverse
    of a micro-stepping stage; the stage follows the command within a sample."""

    retract_limit_mm: float = ranged(0.0, 100.0, default=2.0)
    """Highest the drill point can be above the work surface, mm (the stage's travel)."""

    # ---- sensors -------------------------------------------------------------------------
    sensor_cutoff_hz: float = ranged(0.0, 1e4, default=50.0, lo_open=True)
    """Cut-off of the first-order low-pass of the torque and thrust amplifiers, Hz (anti-alias
    filter below the 50 Hz Nyquist rate of the 100 Hz loop). Not given."""

    torque_noise_Nmm: float = ranged(0.0, 100.0, default=0.01)
    """Standard deviation of the torque sensor noise, N·mm: 2.5 % of the 0.8 mm drill's
    nominal torque but 6 % of the 0.5 mm drill's, the signal-to-noise problem of §7. Not
    given; scaled by a scenario's ``noise_scale``."""

    thrust_noise_N: float = ranged(0.0, 1e3, default=0.02)
    """Standard deviation of the thrust (Kistler 9001 washer) noise, N. Not given."""

    speed_noise_hz: float = ranged(0.0, 1e3, default=0.5)
    """Standard deviation of the fibre-optic spindle-speed measurement, Hz. Not given."""

    # ---- timing --------------------------------------------------------------------------
    sample_time_s: float = ranged(0.0, 1.0, default=0.01, lo_open=True)
    """Controller sample time, s (100 Hz). Not given: ten times faster than the valve's
    response and 25 times faster than the spindle's."""

    substeps: int = ranged_int(1, 1000, default=2)
    """RK4 sub-steps per sample for the spindle (h = 5 ms, 1/50 of the spindle's time
    constant); ``tests/drilling/test_plant.py`` checks the step size against 64 sub-steps."""

    # ---- observation scales ----------------------------------------------------------------
    torque_scale_Nmm: float = ranged(0.0, 1e6, default=1.0, lo_open=True)
    """Normalisation of torques in observations, N·mm."""

    thrust_scale_N: float = ranged(0.0, 1e6, default=2.0, lo_open=True)
    """Normalisation of thrusts in observations, N."""

    def __post_init__(self) -> None:
        super().__post_init__()
        check_range("nominal_voltage", self.nominal_voltage, 0.0, self.voltage_max, lo_open=True)
        check_below(
            "feed_velocity_mm_s",
            self.feed_velocity_mm_s,
            "feed_speed_max_mm_s",
            self.feed_speed_max_mm_s,
            "the stage cannot feed faster than its top speed",
            strict=False,
        )

    @classmethod
    def cheong_cho(cls) -> DrillingParams:
        """The micro-drilling machine of Cheong & Cho, SS40 mild steel (the defaults)."""
        return cls()

    # ---- derived quantities (never stored) -------------------------------------------------
    @property
    def valve_natural_freq_rad_s(self) -> float:
        """wn in rad/s."""
        return _TWO_PI * self.valve_natural_freq_hz

    @property
    def k1(self) -> float:
        """k1 of eq. (17), 1/(V s^2): static gain times wn^2."""
        return self.valve_static_gain_per_V * self.valve_natural_freq_rad_s**2

    def free_speed_rad_s(self, voltage: float, load_torque_Nmm: float = 0.0) -> float:
        r"""Steady spindle speed at a held voltage and a constant load torque, rad/s.

        Solves :math:`k_2 x_v = k_3 \omega^n + T / I` with ``x_v`` the valve's steady opening;
        without load it is :math:`(k_2 x_v / k_3)^{1/n}`.
        """
        drive = self.spindle_drive_gain * self.valve_static_gain_per_V * voltage
        drive -= load_torque_Nmm / self.spindle_inertia_Nmm_s2
        if drive <= 0.0:
            return 0.0
        return (drive / self.spindle_friction) ** (1.0 / self.spindle_friction_exponent)

    def free_speed_hz(self, voltage: float) -> float:
        """Unloaded steady spindle frequency at ``voltage``, Hz."""
        return self.free_speed_rad_s(voltage) / _TWO_PI

    def voltage_for_speed(self, speed_hz: float) -> float:
        """Voltage at which the unloaded spindle settles at ``speed_hz``, V."""
        w = _TWO_PI * speed_hz
        return (
            self.spindle_friction
            * w**self.spindle_friction_exponent
            / (self.spindle_drive_gain * self.valve_static_gain_per_V)
        )

    def spindle_time_constant_s(self, speed_hz: float) -> float:
        """Time constant of the unloaded spindle linearised at ``speed_hz``, s."""
        w = _TWO_PI * speed_hz
        n = self.spindle_friction_exponent
        return 1.0 / (n * self.spindle_friction * w ** (n - 1.0))

    def breakage_torque_Nmm(self, diameter_mm: float) -> float:
        """Torque at which a drill of ``diameter_mm`` breaks, N·mm: ``c_b D^3``."""
        return self.breakage_coeff_N_per_mm2 * diameter_mm**3

    def chip_friction_ratio(self, packed_mm: float, diameter_mm: float) -> float:
        """g(L): chip friction over cutting torque after ``packed_mm`` drilled without clearing."""
        return self.chip_friction * (
            math.exp(packed_mm / (self.chip_length_diameters * diameter_mm)) - 1.0
        )

    def coefficients(self, diameter_mm: float) -> CuttingCoefficients:
        """Torque and thrust per feed of a drill of ``diameter_mm`` (see :func:`cutting_coefficients`)."""
        check_range("diameter_mm", diameter_mm, *DIAMETER_RANGE_MM)
        return cutting_coefficients(_GeometryKey.of(self), float(diameter_mm))

    def chip_free_torque_Nmm(
        self, diameter_mm: float, speed_hz: float, feed_velocity_mm_s: float | None = None
    ) -> float:
        """Torque of the fully engaged drill without packed chips, N·mm (eq. 20)."""
        v = self.feed_velocity_mm_s if feed_velocity_mm_s is None else feed_velocity_mm_s
        return self.coefficients(diameter_mm).torque_per_feed * v / speed_hz

    def nominal_torque_Nmm(self, diameter_mm: float) -> float:
        """Chip-free torque at the nominal voltage's free speed and the nominal feed, N·mm:
        the default torque reference (the spindle then stays near 545 Hz, their Fig. 22)."""
        return self.chip_free_torque_Nmm(diameter_mm, self.free_speed_hz(self.nominal_voltage))


class _GeometryKey(NamedTuple):
    """The fields the cutting coefficients depend on (cached per drill diameter); a named
    tuple, as a key made and hashed twice at every reset of a lane."""

    point_angle_deg: float
    helix_angle_deg: float
    web_ratio: float
    friction_angle_deg: float
    chisel_rake_deg: float
    shear_stress_MPa: float
    indentation_coeff_MPa: float
    indentation_wedge_deg: float
    feed_velocity_mm_s: float
    nominal_speed_hz: float

    @classmethod
    def of(cls, p: DrillingParams) -> _GeometryKey:
        return cls(
            p.point_angle_deg,
            p.helix_angle_deg,
            p.web_ratio,
            p.friction_angle_deg,
            p.chisel_rake_deg,
            p.shear_stress_MPa,
            p.indentation_coeff_MPa,
            p.indentation_wedge_deg,
            p.feed_velocity_mm_s,
            p.free_speed_hz(p.nominal_voltage),
        )

    def shape(self) -> tuple:
        """The fields other than the shear stress (what :func:`_cutting_geometry` needs)."""
        return (
            self.point_angle_deg,
            self.helix_angle_deg,
            self.web_ratio,
            self.friction_angle_deg,
            self.chisel_rake_deg,
            self.indentation_coeff_MPa,
            self.indentation_wedge_deg,
            self.feed_velocity_mm_s,
            self.nominal_speed_hz,
        )


@dataclass(frozen=True)
class CuttingCoefficients:
    """Torque and thrust of one drill per unit feed per revolution ``f`` (mm/rev).

    ``T = torque_per_feed f`` (N·mm), ``H = thrust_per_feed f + indentation_per_feed2 f^2`` (N).
    The arrays give the engaged share of torque and thrust against the drill point's depth.
    """

    torque_per_feed: float
    """c_T, N·mm per mm/rev: main lips (eq. 6-9) plus chisel edge (eq. 10-13)."""
    thrust_per_feed: float
    """N per mm/rev: lips plus chisel edge."""
    indentation_per_feed2: float
    """N per (mm/rev)^2: the indentation thrust of eq. (14)."""
    lip_torque_per_feed: float
    lip_thrust_per_feed: float
    chisel_torque_per_feed: float
    chisel_thrust_per_feed: float
    engage_depth_mm: np.ndarray
    """Depth of the drill point below the surface, mm (ascending, from 0 to full engagement)."""
    engage_torque: np.ndarray
    """Engaged share of the torque at those depths (0 to 1)."""
    engage_thrust: np.ndarray
    """Engaged share of the thrust at those depths (0 to 1)."""

    @property
    def full_engagement_mm(self) -> float:
        """Depth at which the whole lips cut, ``R / tan(kappa)``, mm."""
        return float(self.engage_depth_mm[-1])

    @property
    def chisel_thrust_share(self) -> float:
        """Share of the chip-free thrust carried by the chisel edge (paper: 30-40 %)."""
        return self.chisel_thrust_per_feed / self.thrust_per_feed


_N_LIP = 64  # elements of each lip and of the chisel edge (at most 128: see _sum)
_N_CHISEL = 24
#: Element midpoints and lip element edges, in element widths.
_LIP_MID = np.arange(_N_LIP) + 0.5
_CHISEL_MID = np.arange(_N_CHISEL) + 0.5
_LIP_EDGES = np.arange(1, _N_LIP + 1, dtype=np.float64)


@functools.lru_cache(maxsize=64)
def cutting_coefficients(key: _GeometryKey, diameter_mm: float) -> CuttingCoefficients:
    r"""The cutting model of §3.2 for one drill, per unit feed per revolution.

    **Main lips (eq. 6-9).** Each lip runs from the web (radius ``w``) to the periphery
    ``R = D/2`` and is cut into elements of radial width ``dr``. At radius ``r`` with web angle
    :math:`\omega_w = \arcsin(w/r)` and local helix angle
    :math:`\tan\psi_r = (r/R)\tan\psi`, the element's inclination and normal rake are

    .. math::

        \sin i = \frac{w}{r}\sin\kappa, \qquad
        \tan\alpha_n = \frac{\tan\psi_r\cos\omega_w}{\sin\kappa} - \sin\omega_w\cos\kappa

    (about +30 degrees at the periphery, about -26 degrees next to the web). The chip per lip
    is ``t = (f/2) sin(kappa)`` thick and ``b = dr / sin(kappa)`` wide. The chip flows at
    :math:`\eta_c = i` (Stabler's rule), the shear angle follows
    :math:`\phi_n = \pi/4 - (\beta_n - \alpha_n)/2` (Merchant; the paper identified it by
    GA as a function of rake and inclination), and eq. (7)-(8) give the force along the
    cutting velocity ``F_P`` and the force normal to the edge ``F_Q``:

    .. math::

        F_P &= \frac{\tau b t}{\sin\phi_n}
              \frac{\cos(\beta_n-\alpha_n) + \tan i \tan\eta_c \sin\beta_n}{Q}, \quad
        F_Q = \frac{\tau b t}{\sin\phi_n \cos i} \frac{\sin(\beta_n-\alpha_n)}{Q}, \\
        Q &= \sqrt{\cos^2(\phi_n+\beta_n-\alpha_n) + \tan^2\eta_c\sin^2\beta_n}

    Torque ``2 r F_P`` and thrust ``2 F_Q sin(kappa)`` per element pair. The radial parts of
    ``F_Q`` and the edge-wise force ``F_R`` (eq. 9) cancel between the two symmetric lips;
    the axial part of ``F_R`` (small: ``i`` is near zero over most of the lip) is left out.

    **Chisel edge, secondary cutting (eq. 10-13)** over radii from the indentation zone to
    ``w``: each element of width ``W_c = dr`` cuts at the feed angle
    :math:`\beta_i = \arctan(v_f / (2\pi n r_i))` with dynamic rake
    :math:`\alpha_{dc} = \alpha_{sc} + \beta_i` and shear angle
    :math:`\phi_c = \pi/4 + \alpha_{dc}/2`:

    .. math::

        F'_c = \frac{k_c f W_c \cos\alpha_{dc}\cos\beta_i}{2\sin\phi_c\cos(\phi_c-\alpha_{dc})},
        \quad
        F'_t = \frac{k_c f W_c (-\sin\alpha_{dc})\cos\beta_i}{2\sin\phi_c\cos(\phi_c-\alpha_{dc})}

    (``-sin``: the OCR's ``sin`` with the sign that makes the thrust of the negative rake
    positive), torque :math:`2\sum r_i (F'_c\cos\beta_i + F'_t\sin\beta_i)` and thrust
    :math:`2\sum (F'_c\sin\beta_i + F'_t\cos\beta_i)`. The feed angle is evaluated at the
    nominal speed and feed; it is below 0.2 degrees everywhere, so the coefficients are
    constant and torque is exactly ``k4 / omega`` (eq. 20).

    **Indentation (eq. 14)**: ``k_c f^2 tan(alpha_w)`` inside the radius where the feed
    velocity is 20 % of the cutting velocity (the paper's transition).

    The engagement tables follow the drill point into the work: at a point depth ``z`` the
    lips cut out to radius ``z tan(kappa)``.
    """
    return _cutting_forces(_cutting_geometry(key.shape(), diameter_mm), key.shear_stress_MPa)


class _Geometry(NamedTuple):
    """What the cutting model of one drill computes before the shear stress enters: the
    element radii and widths and the angle terms of eq. (6)-(14) (see
    :func:`cutting_coefficients`)."""

    sk: float
    bt: float
    r: np.ndarray
    sin_phi: np.ndarray
    fp_angle: np.ndarray
    fq_den: np.ndarray
    fq_angle: np.ndarray
    q: np.ndarray
    dc: float
    rc: np.ndarray
    cos_a: np.ndarray
    neg_sin_a: np.ndarray
    cos_b: np.ndarray
    sin_b: np.ndarray
    den: np.ndarray
    indent: float
    depth: np.ndarray


@functools.lru_cache(maxsize=256)
def _cutting_geometry(shape: tuple, diameter_mm: float) -> _Geometry:
    """The shear-stress-free part of :func:`cutting_coefficients` for one drill (``shape``:
    ``_GeometryKey.shape()``); a drill of another shear stress reuses it."""
    point, helix, web_ratio, friction, chisel_rake, indent_c, wedge, v_f, n_rev = shape
    k = math.radians(point / 2.0)
    sk, ck = math.sin(k), math.cos(k)
    radius = diameter_mm / 2.0
    w = web_ratio * radius
    # Main lips.
    dr = (radius - w) / _N_LIP
    beta = math.radians(friction)
    bt = 0.5 * dr  # b t per unit feed: (dr / sin k) (1/2 sin k)
    # Chisel edge: secondary cutting between the indentation zone and the web.
    r_ind = min(v_f / (0.2 * _TWO_PI * n_rev), w)
    dc = (w - r_ind) / _N_CHISEL
    indent = indent_c * math.tan(math.radians(wedge))
    lips = np.empty((6, _N_LIP))
    chisel = np.empty((6, _N_CHISEL))
    depth = np.empty(_N_LIP + 2)
    tan_helix = math.tan(math.radians(helix))
    sin_beta = math.sin(beta)
    x = _Elements(
        w,
        dr,
        sk,
        ck,
        radius,
        tan_helix,
        beta,
        sin_beta,
        sin_beta**2,
        r_ind,
        dc,
        _TWO_PI * n_rev,
        v_f,
        math.radians(chisel_rake),
        math.tan(k),
    )
    _geometry_arrays(x, lips, chisel, depth)
    r, sin_phi, fp_angle, fq_den, fq_angle, q = read_only(*lips)
    rc, cos_a, neg_sin_a, cos_b, sin_b, den = read_only(*chisel)
    read_only(depth)
    return _Geometry(
        sk,
        bt,
        r,
        sin_phi,
        fp_angle,
        fq_den,
        fq_angle,
        q,
        dc,
        rc,
        cos_a,
        neg_sin_a,
        cos_b,
        sin_b,
        den,
        indent,
        depth,
    )


class _Elements(NamedTuple):
    """The scalars of one drill's element arrays (:func:`_geometry_arrays`)."""

    w: float
    dr: float
    sk: float
    ck: float
    radius: float
    tan_helix: float
    beta: float
    sin_beta: float
    sin_beta_sq: float
    r_ind: float
    dc: float
    two_pi_n: float
    v_f: float
    chisel_rake: float
    tan_k: float


@numba.njit(cache=True)
def _geometry_arrays(x, lips, chisel, depth):
    """The element arrays of :func:`_cutting_geometry` from its scalars ``x``
    (:class:`_Elements`), element by element: each value is
    computed by the operations, in the order, that numpy's array expressions of the model
    used, with libm's functions (numpy's own on processors without AVX-512), so that the
    numbers are the same. ``lips`` gets ``r, sin_phi, fp_angle, fq_den, fq_angle, q``,
    ``chisel`` ``rc, cos_a, neg_sin_a, cos_b, sin_b, den``, ``depth`` the point depths
    of the engagement table."""
    w, dr, sk, ck, radius, tan_helix, beta, sin_beta, sin_beta_sq, r_ind, dc = x[:11]
    two_pi_n, v_f, chisel_rake, tan_k = x[11:]
    lip_mid, chisel_mid, lip_edges = _LIP_MID, _CHISEL_MID, _LIP_EDGES
    phi_min = math.radians(5.0)
    for i in range(lip_mid.size):
        r = w + dr * lip_mid[i]
        w_r = w / r
        web = math.asin(w_r)
        incl = math.asin(w_r * sk)
        tan_psi = r / radius * tan_helix
        alpha = math.atan(tan_psi * math.cos(web) / sk - math.sin(web) * ck)
        b_a = beta - alpha
        phi = 0.25 * math.pi - 0.5 * b_a
        if not (phi >= phi_min or phi != phi):  # np.maximum: NaN stays NaN
            phi = phi_min
        tan_eta = math.tan(incl)  # eta: the inclination angle
        c = math.cos(phi + beta - alpha)
        sin_phi = math.sin(phi)
        lips[0, i] = r
        lips[1, i] = sin_phi
        lips[2, i] = math.cos(b_a) + tan_eta * tan_eta * sin_beta
        lips[3, i] = sin_phi * math.cos(incl)
        lips[4, i] = math.sin(b_a)
        lips[5, i] = math.sqrt(c * c + tan_eta * tan_eta * sin_beta_sq)
    for i in range(chisel_mid.size):
        rc = r_ind + dc * chisel_mid[i]
        b_i = math.atan(v_f / (two_pi_n * rc))
        a_dc = chisel_rake + b_i
        phi_c = 0.25 * math.pi + 0.5 * a_dc
        chisel[0, i] = rc
        chisel[1, i] = math.cos(a_dc)
        chisel[2, i] = -math.sin(a_dc)
        chisel[3, i] = math.cos(b_i)
        chisel[4, i] = math.sin(b_i)
        chisel[5, i] = 2.0 * math.sin(phi_c) * math.cos(phi_c - a_dc)
    # Engagement against point depth: the chisel cuts from the first touch (its height is
    # w / tan(kappa), a few microns), the lips out to radius z tan(kappa).
    depth[0] = 0.0 / tan_k
    depth[1] = w / tan_k
    for i in range(lip_edges.size):
        depth[2 + i] = (w + dr * lip_edges[i]) / tan_k


@numba.njit(cache=True)
def _sum(a):
    """``a.sum()`` of numpy for a float64 vector of at most 128 elements, to the last bit:
    numpy's pairwise summation, which below 128 elements keeps eight running sums."""
    n = a.size
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i]
        return 0.0 + res
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    i = 8
    while i < n - n % 8:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[i]
        i += 1
    return 0.0 + res


@numba.njit(cache=True)
def _forces(tau, g, sums, cum_t, cum_h):
    """The shear-stress part of the cutting model (eq. 6-13) of one drill (its
    :class:`_Geometry` ``g``): the torque and thrust of every lip and chisel element per
    unit feed, summed as numpy sums.

    ``sums`` gets ``[lip torque, lip thrust, chisel torque, chisel thrust]``; ``cum_t`` and
    ``cum_h`` (``2 + r.size``) the torque and thrust cut out to each engagement radius.
    """
    r, sin_phi, fp_angle, fq_den, fq_angle, q = (
        g.r,
        g.sin_phi,
        g.fp_angle,
        g.fq_den,
        g.fq_angle,
        g.q,
    )
    rc, cos_a, neg_sin_a, cos_b, sin_b, den = g.rc, g.cos_a, g.neg_sin_a, g.cos_b, g.sin_b, g.den
    bt, sk, dc = g.bt, g.sk, g.dc
    n_lip, n_ch = r.size, rc.size
    lip_t = np.empty(n_lip)
    lip_h = np.empty(n_lip)
    a = tau * bt
    for i in range(n_lip):
        fp = a / sin_phi[i] * fp_angle[i] / q[i]
        fq = a / fq_den[i] * fq_angle[i] / q[i]
        lip_t[i] = 2.0 * r[i] * fp
        lip_h[i] = 2.0 * fq * sk
    ch_t = np.empty(n_ch)
    ch_h = np.empty(n_ch)
    b = tau * dc
    for i in range(n_ch):
        fc = b * cos_a[i] * cos_b[i] / den[i]
        ft = b * neg_sin_a[i] * cos_b[i] / den[i]
        ch_t[i] = 2.0 * rc[i] * (fc * cos_b[i] + ft * sin_b[i])
        ch_h[i] = 2.0 * (fc * sin_b[i] + ft * cos_b[i])
    ch_t_sum = _sum(ch_t)
    ch_h_sum = _sum(ch_h)
    sums[0] = _sum(lip_t)
    sums[1] = _sum(lip_h)
    sums[2] = ch_t_sum
    sums[3] = ch_h_sum
    cum_t[0] = 0.0
    cum_h[0] = 0.0
    cum_t[1] = ch_t_sum
    cum_h[1] = ch_h_sum
    st = 0.0
    sh = 0.0
    for i in range(n_lip):  # np.cumsum: running sums in order
        st = lip_t[i] if i == 0 else st + lip_t[i]
        sh = lip_h[i] if i == 0 else sh + lip_h[i]
        cum_t[2 + i] = ch_t_sum + st
        cum_h[2 + i] = ch_h_sum + sh


def _cutting_forces(g: _Geometry, tau: float) -> CuttingCoefficients:
    """The cutting model of one drill (its :class:`_Geometry`) at the shear stress ``tau``."""
    sums = np.empty(4)
    cum_t = np.empty(2 + g.r.size)
    cum_h = np.empty(2 + g.r.size)
    _forces(float(tau), g, sums, cum_t, cum_h)
    lip_t, lip_h, ch_t, ch_h = sums.tolist()
    return CuttingCoefficients(
        torque_per_feed=float(cum_t[-1]),
        thrust_per_feed=float(cum_h[-1]),
        indentation_per_feed2=float(g.indent),
        lip_torque_per_feed=lip_t,
        lip_thrust_per_feed=lip_h,
        chisel_torque_per_feed=ch_t,
        chisel_thrust_per_feed=ch_h,
        engage_depth_mm=g.depth,
        engage_torque=read_only(cum_t / cum_t[-1]),
        engage_thrust=read_only(cum_h / cum_h[-1]),
    )


@functools.lru_cache(maxsize=32)
def _valve_matrices(wn: float, zeta: float, k1: float, ts: float, m: int):
    """Exact valve transitions: spool positions at every half sub-step, and the next state.

    Returns ``(half, step)``: ``half`` (2m+1, 3) maps ``[x1, x2, u]`` to ``x_v`` at
    ``t + j h / 2``; ``step`` (2, 3) maps it to the state at ``t + Ts``.
    """
    a = np.array([[0.0, 1.0], [-(wn**2), -2.0 * zeta * wn]])
    b = np.array([[0.0], [k1]])
    phi_half, gam_half = zoh(a, b, ts / (2 * m))
    half = np.empty((2 * m + 1, 3))
    p, g = np.eye(2), np.zeros(2)
    for j in range(2 * m + 1):
        half[j, :2] = p[0]
        half[j, 2] = g[0]
        g = phi_half @ g + gam_half[:, 0]
        p = phi_half @ p
    phi, gam = zoh(a, b, ts)
    step = np.hstack([phi, gam])
    return read_only(half, step)


@functools.lru_cache(maxsize=32)
def _filter_weights(cutoff_hz: float, ts: float, m: int) -> tuple[float, tuple[float, ...]]:
    """First-order sensor filter over one sample: ``y+ = a y + sum_j w_j T_j`` (j = 0..m).

    Exact for an input that is linear between the sub-step values ``T_j``: over a sub-step
    of length ``h`` with ``a_h = exp(-h / tau)``, a ramp from ``x0`` to ``x1`` moves the
    output to ``a_h y + (1 - a_h - c) x0 + c x1`` with ``c = 1 - (tau / h)(1 - a_h)``.
    """
    tau = 1.0 / (_TWO_PI * cutoff_hz)
    h = ts / m
    a_h = math.exp(-h / tau)
    c = 1.0 - (tau / h) * (1.0 - a_h)
    w = [0.0] * (m + 1)
    for j in range(1, m + 1):
        decay = a_h ** (m - j)  # from the end of sub-step j to the end of the sample
        w[j - 1] += (1.0 - a_h - c) * decay
        w[j] += c * decay
    return a_h**m, tuple(w)


@dataclass(slots=True)
class DrillingStep:
    """Signals of one control period, at its end (the sample instant) unless stated."""

    torque_Nmm: float
    """Torque on the drill at the sample instant, N·mm."""
    peak_torque_Nmm: float
    """Largest torque over the period's sub-steps, N·mm."""
    thrust_N: float
    measured_torque_Nmm: float
    """Filtered, noisy torque sensor output, N·mm."""
    measured_thrust_N: float
    measured_speed_hz: float
    speed_hz: float
    """True spindle frequency, Hz."""
    valve_opening: float
    """Spool opening x_v (1 = fully open)."""
    feed_velocity_mm_s: float
    """Commanded feed velocity of the stage, mm/s (negative: retracting)."""
    cutting_feed_mm_s: float
    """Rate at which the hole deepened over the period, mm/s."""
    feed_mm_per_rev: float
    position_mm: float
    """Drill point position below the work surface, mm (negative: above it)."""
    depth_mm: float
    """Hole depth, mm."""
    packed_mm: float
    """Length drilled since the chips were last cleared, mm."""
    chip_ratio: float
    """Chip friction over cutting torque, g(L) with its fluctuation."""
    cutting: bool
    engagement: float
    """Engaged share of the drill's full torque (1 once the point is fully in the work)."""
    finish_time_s: float | None = None


# ---- the batched physics: N holes stepped as arrays, one kernel for one lane or many --------

#: Entries of ``DrillingLanes.shared`` (the batch's constants). The valve's transition rows
#: (``_G.HALF``: 2m+1 rows of 3, then 2 rows of 3) and the filter weights (m+1) follow the
#: scalars.
_G = IntEnum(
    "_G",
    "TS UMAX VMAX RETRACT K2 K3 N INERTIA OU_C OU_C_IN OU_0 OU_0_IN FA CHIP_LEN SQUARE H H2 H6"
    " HALF",
    start=0,
)
#: Columns of ``DrillingLanes.par`` (one row of parameters per lane).
_P = IntEnum(
    "_P",
    "G0 SIG_C SIG_0 KT KH KH2 FULL D TARGET NOISE_T NOISE_H NOISE_S BREAK WEAR",
    start=0,
)
#: Columns of ``DrillingLanes.state``.
_S = IntEnum(
    "_S",
    "X1 X2 OMEGA T POS DEPTH PACKED XI_CHIP XI_CUT TQ_F TH_F TQ TH VOLT FINISHED",
    start=0,
)
#: Fields of ``DrillingLanes.out`` (one row per lane after each step), in the order of
#: :class:`DrillingStep`; ``cutting`` is 0 or 1 and ``finish_time_s`` NaN until the hole ends.
LANE_SIGNALS = tuple(f.name for f in dataclasses.fields(DrillingStep))
_N_OUT = len(LANE_SIGNALS)
#: The same fields as columns of ``DrillingLanes.out``.
_Out = IntEnum("_Out", LANE_SIGNALS, start=0)
#: Entries of each engagement table (``DrillingLanes.eng[k]``: point depth, torque share,
#: thrust share).
_N_ENG = _N_LIP + 2
#: Inputs per lane of :func:`advance`: voltage, feed velocity and the five standard normals.
_N_IN = 7
#: 1 Hz, rad/s: below it the torque law is not evaluated (the drill stalls).
_W_FLOOR = 2.0 * math.pi


#: The fields of ``DrillingParams`` every lane of a batch shares (``DrillingLanes.shared``).
_SHARED_FIELDS = (
    "valve_natural_freq_hz",
    "valve_damping",
    "valve_static_gain_per_V",
    "voltage_max",
    "spindle_friction_exponent",
    "spindle_drive_gain",
    "spindle_friction",
    "spindle_inertia_Nmm_s2",
    "chip_length_diameters",
    "chip_fluctuation_time_s",
    "cutting_fluctuation_time_s",
    "feed_speed_max_mm_s",
    "retract_limit_mm",
    "sensor_cutoff_hz",
    "sample_time_s",
    "substeps",
)


def _shared_key(p: DrillingParams) -> tuple:
    return tuple(getattr(p, f) for f in _SHARED_FIELDS)


def _shared_constants(p: DrillingParams) -> np.ndarray:
    """``DrillingLanes.shared`` of a batch with the parameters ``p``."""
    m = p.substeps
    ts = p.sample_time_s
    half, vstep = _valve_matrices(p.valve_natural_freq_rad_s, p.valve_damping, p.k1, ts, m)
    fa, fw = _filter_weights(p.sensor_cutoff_hz, ts, m)
    ou_c = math.exp(-ts / p.chip_fluctuation_time_s)
    ou_0 = math.exp(-ts / p.cutting_fluctuation_time_s)
    scalars = (
        ts,
        p.voltage_max,
        p.feed_speed_max_mm_s,
        p.retract_limit_mm,
        p.spindle_drive_gain,
        p.spindle_friction,
        p.spindle_friction_exponent,
        p.spindle_inertia_Nmm_s2,
        ou_c,
        math.sqrt(1.0 - ou_c**2),
        ou_0,
        math.sqrt(1.0 - ou_0**2),
        fa,
        p.chip_length_diameters,
        2.0,  # Python's x ** 2 is pow(): data, so that the kernel's py_square gives it too
        ts / m,  # the RK4 step, and the factors of its stages
        0.5 * (ts / m),
        (ts / m) / 6.0,
    )
    return np.concatenate([scalars, half.ravel(), vstep.ravel(), fw])


@numba.njit(cache=True, inline="always")
def _pymax(a, b):
    """``max(a, b)`` of Python for floats (``a`` unless ``b > a``)."""
    return b if b > a else a


@numba.njit(cache=True, inline="always")
def _pymin(a, b):
    """``min(a, b)`` of Python for floats (``a`` unless ``b < a``)."""
    return b if b < a else a


@numba.njit(cache=True, inline="always")
def _interval(x, eng, k):
    """The ``j`` with ``xp[j] <= x < xp[j + 1]`` in the depths ``xp = eng[k, 0]`` of lane
    ``k``'s engagement tables, for ``x`` inside ``[xp[0], xp[-1])``. The search starts where
    an evenly spaced table past ``xp[1]`` (the lips' part) would have ``x``; the comparisons
    make it exact."""
    last = eng.shape[2] - 2
    x1 = eng[k, 0, 1]
    j = 0
    if x >= x1:
        j = 1 + int(min((x - x1) / (eng[k, 0, 2] - x1), last))
    j = min(j, last)
    while j > 0 and eng[k, 0, j] > x:
        j -= 1
    while j < last and eng[k, 0, j + 1] <= x:
        j += 1
    return j


@numba.njit(cache=True, inline="always")
def _interp(x, eng, k, row, j):
    """``np.interp(x, xp, fp)`` with numpy's arithmetic, ``xp = eng[k, 0]`` and
    ``fp = eng[k, row]``, for ``x`` in the interval ``j`` (:func:`_interval`)."""
    if np.isnan(x):
        return x
    x0 = eng[k, 0, j]
    y0 = eng[k, row, j]
    if x0 == x:
        return y0
    x1 = eng[k, 0, j + 1]
    y1 = eng[k, row, j + 1]
    slope = (y1 - y0) / (x1 - x0)
    y = slope * (x - x0) + y0
    if np.isnan(y):
        y = slope * (x - x1) + y1
        if np.isnan(y) and y0 == y1:
            y = y0
    return y


@numba.njit(cache=True, inline="always")
def _engagement(eng, k, full, depth_mm):
    """Engaged shares of torque and thrust of lane ``k`` (tables ``eng[k]``) with the point
    ``depth_mm`` below the surface (``full``: depth of full engagement)."""
    if depth_mm >= full:
        return 1.0, 1.0
    if depth_mm <= 0.0:
        return 0.0, 0.0
    if np.isnan(depth_mm):
        return depth_mm, depth_mm
    j = _interval(depth_mm, eng, k)
    return _interp(depth_mm, eng, k, 1, j), _interp(depth_mm, eng, k, 2, j)


#: Columns of the step kernel's scratch: what a lane carries between the stages of its step.
_T = IntEnum(
    "_T",
    "U BOTTOM CUT K4 KH KH2 LOAD W WB F1 F2 F3 XB XC TQ_F TH_F PEAK TQ TH",
    start=0,
)
_N_TMP = len(_T)


@numba.njit(cache=True, inline="always")
def _accel(g, xv, friction, load, w):
    """The spindle's acceleration (RK4's stage) at the valve position ``xv``, with the
    friction term ``friction`` and the load ``load`` (k4 over the inertia) at the speed
    ``w`` (held above the floor where the torque law is not evaluated)."""
    return g[_G.K2] * xv - g[_G.K3] * friction - load / (w if w > _W_FLOOR else _W_FLOOR)


@numba.njit(cache=True, inline="always")
def _mid_stage(k0, k1, g, tmp, friction, speeds, col, h):
    """RK4's second or third stage of lanes ``k0 .. k1 - 1`` (:func:`advance`): the
    acceleration at the speed ``tmp[:, _T.WB]`` into column ``col``, and the speed a step
    ``h`` on (into ``_T.WB`` and ``speeds``)."""
    for k in range(k0, k1):
        wb = tmp[k - k0, _T.WB]
        f = _accel(g, tmp[k - k0, _T.XB], friction[k - k0], tmp[k - k0, _T.LOAD], wb)
        tmp[k - k0, col] = f
        wb = tmp[k - k0, _T.W] + h * f
        tmp[k - k0, _T.WB] = wb if wb > 0.0 else 0.0
        speeds[k - k0] = tmp[k - k0, _T.WB]


#: Lanes whose step advances together, stage by stage (see :func:`advance`).
LANE_BLOCK = 16


@numba.njit(cache=True)
def advance(k0, k1, m, g, par, eng, state, inputs, out, tmp, rows):
    """Advance lanes ``k0 .. k1 - 1`` by one sample; ``inputs[k - k0]`` = voltage (V), feed
    velocity (mm/s) and five standard normals (chip and cutting fluctuation innovations,
    torque, thrust and speed sensor noise) of lane ``k``; ``out[k]`` gets the signals of
    :class:`DrillingStep`; ``tmp`` (at least ``k1 - k0`` rows of ``_N_TMP``) and ``rows``
    (2 rows of at least ``k1 - k0``) are scratch.

    The lanes go through each stage of the step together (the commands, fluctuations, hole
    and load; the four stages of every RK4 sub-step of the spindle; the new state and the
    sensors), so that the slow operations of different lanes (divisions, ``exp``) overlap
    in the processor; each lane's arithmetic is that of one hole, whatever the number of
    lanes. The friction law's powers ``w**n`` of each RK4 stage are taken for the lanes
    together, in the processor's vectors (:func:`~machining_envs.core.compiled.kernels.powers`).
    (One function: the arrays are not passed on per lane.)
    """
    nb = k1 - k0
    speeds = rows[0]  # each lane's spindle speed at the RK4 stage (>= 0) ...
    friction = rows[1]  # ... and its power n of the friction law
    for k in range(k0, k1):
        voltage = inputs[k - k0, 0]
        feed = inputs[k - k0, 1]
        ts = g[_G.TS]
        u = _pymin(_pymax(voltage, 0.0), g[_G.UMAX])
        vmax = g[_G.VMAX]
        v = _pymin(_pymax(feed, -vmax), vmax)
        state[k, _S.VOLT] = u

        # Fluctuations (Ornstein-Uhlenbeck, unit variance), then the hole over this period.
        xi_chip = g[_G.OU_C] * state[k, _S.XI_CHIP] + g[_G.OU_C_IN] * inputs[k - k0, 2]
        xi_cut = g[_G.OU_0] * state[k, _S.XI_CUT] + g[_G.OU_0_IN] * inputs[k - k0, 3]
        state[k, _S.XI_CHIP] = xi_chip
        state[k, _S.XI_CUT] = xi_cut
        z0 = state[k, _S.POS]
        z1 = z0 + v * ts
        if z1 < -g[_G.RETRACT]:
            z1 = -g[_G.RETRACT]
        bottom = state[k, _S.DEPTH]
        cut_len = z1 - bottom if (v > 0.0 and z1 > bottom) else 0.0
        cutting = cut_len > 0.0
        d = par[k, _P.D]
        if cutting:
            v_cut = cut_len / ts
            mid = bottom + 0.5 * cut_len
            eng_t, eng_h = _engagement(eng, k, par[k, _P.FULL], mid)
            packed = state[k, _S.PACKED] + 0.5 * cut_len
            ratio = par[k, _P.G0] * (math.exp(packed / (g[_G.CHIP_LEN] * d)) - 1.0)
            ratio *= _pymax(0.0, 1.0 + par[k, _P.SIG_C] * xi_chip)
            wear = 1.0 + par[k, _P.WEAR] * mid  # the edge dulls with the depth drilled
            load = (wear + ratio) * _pymax(0.0, 1.0 + par[k, _P.SIG_0] * xi_cut)
            k4 = par[k, _P.KT] * v_cut * eng_t * load
            kh = par[k, _P.KH] * v_cut * eng_h * load
            kh2 = par[k, _P.KH2] * py_square(v_cut * eng_h, g[_G.SQUARE])
        else:
            v_cut = 0.0
            ratio = 0.0
            eng_t = 0.0
            k4 = 0.0
            kh = 0.0
            kh2 = 0.0
        out[k, _Out.feed_velocity_mm_s] = v
        out[k, _Out.cutting_feed_mm_s] = v_cut
        out[k, _Out.position_mm] = z1
        out[k, _Out.chip_ratio] = ratio
        out[k, _Out.cutting] = 1.0 if cutting else 0.0
        out[k, _Out.engagement] = eng_t
        tmp[k - k0, _T.U] = u
        tmp[k - k0, _T.BOTTOM] = bottom
        tmp[k - k0, _T.CUT] = cut_len
        tmp[k - k0, _T.K4] = k4
        tmp[k - k0, _T.KH] = kh
        tmp[k - k0, _T.KH2] = kh2
        tmp[k - k0, _T.LOAD] = k4 / g[_G.INERTIA]

        # Torque and thrust at the sub-step instants (j = 0..m); the sensors filter them.
        w = state[k, _S.OMEGA]
        fw = _G.HALF + 3 * (2 * m + 1) + 6
        fa = g[_G.FA]
        wj = w if w > _W_FLOOR else _W_FLOOR
        tq = k4 / wj
        th = kh / wj + kh2 / (wj * wj)
        tmp[k - k0, _T.TQ_F] = state[k, _S.TQ_F] * fa + g[fw] * tq
        tmp[k - k0, _T.TH_F] = state[k, _S.TH_F] * fa + g[fw] * th
        tmp[k - k0, _T.PEAK] = tq if tq > 0.0 else 0.0
        tmp[k - k0, _T.TQ] = tq
        tmp[k - k0, _T.TH] = th
        tmp[k - k0, _T.W] = w
        # The valve's exact position at the start of the period.
        tmp[k - k0, _T.XC] = (
            g[_G.HALF] * state[k, _S.X1] + g[_G.HALF + 1] * state[k, _S.X2] + g[_G.HALF + 2] * u
        )
    # The spindle by RK4 with the valve exactly at every half sub-step and the load
    # k4 / omega; the torque and thrust at the end of every sub-step.
    fw = _G.HALF + 3 * (2 * m + 1) + 6
    for j in range(m):
        r = _G.HALF + 6 * j
        for k in range(k0, k1):
            w = tmp[k - k0, _T.W]
            speeds[k - k0] = w if w > 0.0 else 0.0
        powers(speeds, 0, friction, 0, nb, g[_G.N])
        for k in range(k0, k1):
            u = tmp[k - k0, _T.U]
            x1 = state[k, _S.X1]
            x2 = state[k, _S.X2]
            xa = tmp[k - k0, _T.XC]
            tmp[k - k0, _T.XB] = g[r + 3] * x1 + g[r + 4] * x2 + g[r + 5] * u
            tmp[k - k0, _T.XC] = g[r + 6] * x1 + g[r + 7] * x2 + g[r + 8] * u
            w = tmp[k - k0, _T.W]
            wa = w if w > 0.0 else 0.0
            f = _accel(g, xa, friction[k - k0], tmp[k - k0, _T.LOAD], wa)
            tmp[k - k0, _T.F1] = f
            wb = w + g[_G.H2] * f
            tmp[k - k0, _T.WB] = wb if wb > 0.0 else 0.0
            speeds[k - k0] = tmp[k - k0, _T.WB]
        powers(speeds, 0, friction, 0, nb, g[_G.N])
        # the second and third stages: the speed at the midpoint from f2, at the end from f3
        _mid_stage(k0, k1, g, tmp, friction, speeds, _T.F2, g[_G.H2])
        powers(speeds, 0, friction, 0, nb, g[_G.N])
        _mid_stage(k0, k1, g, tmp, friction, speeds, _T.F3, g[_G.H])
        powers(speeds, 0, friction, 0, nb, g[_G.N])
        for k in range(k0, k1):
            wc = tmp[k - k0, _T.WB]
            f4 = _accel(g, tmp[k - k0, _T.XC], friction[k - k0], tmp[k - k0, _T.LOAD], wc)
            w = tmp[k - k0, _T.W] + g[_G.H6] * (
                tmp[k - k0, _T.F1] + 2.0 * tmp[k - k0, _T.F2] + 2.0 * tmp[k - k0, _T.F3] + f4
            )
            if w < 0.0:
                w = 0.0
            tmp[k - k0, _T.W] = w
            wj = w if w > _W_FLOOR else _W_FLOOR
            tq = tmp[k - k0, _T.K4] / wj
            th = tmp[k - k0, _T.KH] / wj + tmp[k - k0, _T.KH2] / (wj * wj)
            if tq > tmp[k - k0, _T.PEAK]:
                tmp[k - k0, _T.PEAK] = tq
            tmp[k - k0, _T.TQ_F] += g[fw + j + 1] * tq
            tmp[k - k0, _T.TH_F] += g[fw + j + 1] * th
            tmp[k - k0, _T.TQ] = tq
            tmp[k - k0, _T.TH] = th
    for k in range(k0, k1):
        ts = g[_G.TS]
        u = tmp[k - k0, _T.U]
        x1 = state[k, _S.X1]
        x2 = state[k, _S.X2]
        r = _G.HALF + 3 * (2 * m + 1)
        state[k, _S.X1] = g[r] * x1 + g[r + 1] * x2 + g[r + 2] * u
        state[k, _S.X2] = g[r + 3] * x1 + g[r + 4] * x2 + g[r + 5] * u
        w = tmp[k - k0, _T.W]
        state[k, _S.OMEGA] = w
        tq_f = tmp[k - k0, _T.TQ_F]
        th_f = tmp[k - k0, _T.TH_F]
        state[k, _S.TQ_F] = tq_f
        state[k, _S.TH_F] = th_f
        state[k, _S.TQ] = tmp[k - k0, _T.TQ]
        state[k, _S.TH] = tmp[k - k0, _T.TH]

        # The drill point and the chips.
        z1 = out[k, _Out.position_mm]
        cut_len = tmp[k - k0, _T.CUT]
        bottom = tmp[k - k0, _T.BOTTOM]
        state[k, _S.POS] = z1
        if cut_len > 0.0:
            state[k, _S.DEPTH] = z1
            state[k, _S.PACKED] += cut_len
        if z1 < 0.0:
            state[k, _S.PACKED] = 0.0  # the point left the hole: the flutes are cleared
        time = state[k, _S.T]
        finish = np.nan
        if state[k, _S.FINISHED] == 0.0 and state[k, _S.DEPTH] >= par[k, _P.TARGET]:
            frac = (par[k, _P.TARGET] - bottom) / cut_len if cut_len > 0 else 1.0
            finish = time + _pymin(_pymax(frac, 0.0), 1.0) * ts
            state[k, _S.FINISHED] = 1.0
        state[k, _S.T] = time + ts
        speed_hz = w / (2.0 * math.pi)
        v_cut = out[k, _Out.cutting_feed_mm_s]
        out[k, _Out.torque_Nmm] = tmp[k - k0, _T.TQ]
        out[k, _Out.peak_torque_Nmm] = tmp[k - k0, _T.PEAK]
        out[k, _Out.thrust_N] = tmp[k - k0, _T.TH]
        out[k, _Out.measured_torque_Nmm] = tq_f + par[k, _P.NOISE_T] * inputs[k - k0, 4]
        out[k, _Out.measured_thrust_N] = th_f + par[k, _P.NOISE_H] * inputs[k - k0, 5]
        out[k, _Out.measured_speed_hz] = speed_hz + par[k, _P.NOISE_S] * inputs[k - k0, 6]
        out[k, _Out.speed_hz] = speed_hz
        out[k, _Out.valve_opening] = state[k, _S.X1]
        out[k, _Out.feed_mm_per_rev] = (v_cut / speed_hz) if speed_hz > 1.0 else 0.0
        out[k, _Out.depth_mm] = state[k, _S.DEPTH]
        out[k, _Out.packed_mm] = state[k, _S.PACKED]
        out[k, _Out.finish_time_s] = finish


@numba.njit(cache=True)
def _step_lanes(m, g, par, eng, state, inputs, out):
    """Advance every lane by one sample (:func:`advance`, ``LANE_BLOCK`` lanes at a time;
    ``inputs[k]`` is lane ``k``'s)."""
    n = state.shape[0]
    tmp = np.empty((LANE_BLOCK, _N_TMP))
    rows = np.empty((2, LANE_BLOCK))
    for k0 in range(0, n, LANE_BLOCK):
        k1 = min(k0 + LANE_BLOCK, n)
        advance(k0, k1, m, g, par, eng, state, inputs[k0:k1], out, tmp, rows)


@numba.njit(cache=True)
def start_lane(k, row, eng_depth, eng_torque, eng_thrust, par, eng):
    """Lane ``k``'s parameters and drill (:class:`DrillingLanes`): its ``par`` row
    (:meth:`DrillingLanes.lane_row`) and its engagement tables."""
    for i in range(par.shape[1]):
        par[k, i] = row[i]
    copy_into(eng[k, 0], eng_depth)
    copy_into(eng[k, 1], eng_torque)
    copy_into(eng[k, 2], eng_thrust)


@numba.njit(cache=True)
def restart_lane(k, voltage, x1, omega, position_mm, state):
    """Lane ``k``'s state at the start of a hole (:meth:`DrillingLanes.restart`): the valve
    settled at ``x1`` for ``voltage``, the spindle at ``omega``, the drill point at
    ``position_mm``, every other state zero."""
    s = state[k]
    s[:] = 0.0
    s[_S.VOLT] = voltage
    s[_S.X1] = x1
    s[_S.OMEGA] = omega
    s[_S.POS] = position_mm


class DrillingLanes:
    """N independent holes drilled together: the physics of every drilling env.

    Each lane has its own parameters, drill and hole (:meth:`start`); :meth:`step`
    advances every lane by one sample with one compiled kernel whose arithmetic per lane is
    exactly that of a single hole, so lane ``i`` of a batch and a batch of one give the same
    numbers to the last bit. The lanes share the valve, the spindle, the sensor filter, the
    fluctuations' correlation times, the stage's limits, the sample time and the RK4
    sub-steps (those of the ``params`` given here; :meth:`start` refuses a lane whose
    parameters differ in them); the drill, the hole, the cutting and chip constants, the
    fluctuations' sizes and the sensor noise are the lane's own.

    Layout: ``shared`` the batch's constants (with the valve's exact transitions and the
    sensor filter's weights); one row per lane of ``par`` the lane's parameters and its
    drill's cutting constants, ``eng`` the engagement tables of the drill (point depth,
    torque share, thrust share), ``state`` the valve, spindle, drill point, chips,
    fluctuations and sensor filters, ``out`` the signals of the last step
    (``LANE_SIGNALS``).

    Parameters
    ----------
    params : DrillingParams
        Parameters of every lane until :meth:`start` gives it its own; sets the sub-steps.
    n : int
        Number of lanes.
    """

    def __init__(self, params: DrillingParams, n: int = 1) -> None:
        check_integer("n", n, 1, 1 << 24)
        self.n = int(n)
        self.params = params
        self.m = params.substeps
        self._key = _shared_key(params)
        #: The batch's constants: valve, spindle, filter, fluctuation times, sample time.
        self.shared = _shared_constants(params)
        self.par = np.zeros((self.n, len(_P)))
        self.eng = np.zeros((self.n, 3, _N_ENG))
        self.state = np.zeros((self.n, len(_S)))
        #: Signals of the last step, one row per lane (columns: ``LANE_SIGNALS``).
        self.out = np.zeros((self.n, _N_OUT))
        self.out[:, -1] = np.nan

    def start(
        self,
        lane: int,
        params: DrillingParams,
        diameter_mm: float,
        target_depth_mm: float,
        start_position_mm: float = 0.0,
        coefficients: CuttingCoefficients | None = None,
    ) -> None:
        """Set ``lane``'s parameters, drill and hole, and start it (:meth:`restart`).

        ``coefficients``: the drill's cutting model if the caller has it
        (``params.coefficients(diameter_mm)``).
        """
        p = params
        check_range("target_depth_mm", target_depth_mm, 0.0, 100.0, lo_open=True)
        check_range("start_position_mm", start_position_mm, -p.retract_limit_mm, 0.0)
        if p is not self.params and _shared_key(p) != self._key:
            own = dict(zip(_SHARED_FIELDS, _shared_key(p), strict=True))
            batch = dict(zip(_SHARED_FIELDS, self._key, strict=True))
            diff = {f: v for f, v in own.items() if v != batch[f]}
            raise ValueError(
                f"a lane's {', '.join(diff)} must be the batch's "
                f"({', '.join(f'{f}={batch[f]!r}' for f in diff)}), got {diff}"
            )
        c = p.coefficients(diameter_mm) if coefficients is None else coefficients
        start_lane(
            lane,
            self.lane_row(p, c, diameter_mm, target_depth_mm),
            c.engage_depth_mm,
            c.engage_torque,
            c.engage_thrust,
            self.par,
            self.eng,
        )
        self.restart(lane, p, start_position_mm)

    @staticmethod
    def lane_row(
        params: DrillingParams,
        coefficients: CuttingCoefficients,
        diameter_mm: float,
        target_depth_mm: float,
    ) -> np.ndarray:
        """A lane's row of ``par`` (``_P_*``): its parameters and its drill's cutting
        constants (``coefficients``, of ``params`` at ``diameter_mm``)."""
        p, c = params, coefficients
        return np.array(
            (
                p.chip_friction,
                p.chip_fluctuation,
                p.cutting_fluctuation,
                _TWO_PI * c.torque_per_feed,
                _TWO_PI * c.thrust_per_feed,
                _TWO_PI**2 * c.indentation_per_feed2,
                c.full_engagement_mm,
                float(diameter_mm),
                float(target_depth_mm),
                p.torque_noise_Nmm,
                p.thrust_noise_N,
                p.speed_noise_hz,
                p.breakage_torque_Nmm(diameter_mm),
                p.wear_per_mm,
            )
        )

    def restart(
        self,
        lane: int,
        params: DrillingParams,
        position_mm: float = 0.0,
        speed_hz: float | None = None,
        voltage: float | None = None,
    ) -> None:
        """Start ``lane``'s hole again: the spindle running free at ``voltage`` (default
        nominal; or at ``speed_hz``), the valve settled, the drill point at ``position_mm``,
        no hole, no chips, fluctuations and sensor filters at zero."""
        u = params.nominal_voltage if voltage is None else float(voltage)
        omega = params.free_speed_rad_s(u) if speed_hz is None else _TWO_PI * speed_hz
        restart_lane(lane, u, params.valve_static_gain_per_V * u, omega, position_mm, self.state)

    def step(self, inputs: np.ndarray) -> None:
        """Advance every lane by one sample; ``inputs[k]`` = voltage (V), feed velocity
        (mm/s) and five standard normals of lane ``k``; results in ``out``."""
        inputs = np.asarray(inputs, dtype=np.float64)
        if inputs.shape != (self.n, _N_IN):
            raise ValueError(f"inputs must have shape ({self.n}, {_N_IN}), got {inputs.shape}")
        _step_lanes(self.m, self.shared, self.par, self.eng, self.state, inputs, self.out)


def _state_property(col: int, doc: str) -> property:
    def get(self) -> float:
        return float(self._lanes.state[0, col])

    return property(get, doc=doc)


class DrillingPlant:
    """Simulates one hole: valve, spindle, drill point and chips (a :class:`DrillingLanes`
    of one lane).

    Parameters
    ----------
    params : DrillingParams
        The plant's true parameters for this hole.
    diameter_mm : float
        Drill diameter (``DIAMETER_RANGE_MM``).
    target_depth_mm : float
        Hole depth at which the hole is finished, mm.
    start_position_mm : float
        Drill point position at the start, mm (negative: above the surface; default 0,
        touching it).
    """

    def __init__(
        self,
        params: DrillingParams,
        diameter_mm: float,
        target_depth_mm: float,
        start_position_mm: float = 0.0,
    ) -> None:
        check_range("diameter_mm", diameter_mm, *DIAMETER_RANGE_MM)
        check_range("target_depth_mm", target_depth_mm, 0.0, 100.0, lo_open=True)
        check_range("start_position_mm", start_position_mm, -params.retract_limit_mm, 0.0)
        self.params = params
        self.diameter_mm = float(diameter_mm)
        self.target_depth_mm = float(target_depth_mm)
        self.start_position_mm = float(start_position_mm)
        self.coeffs = params.coefficients(diameter_mm)
        self.breakage_torque_Nmm = params.breakage_torque_Nmm(diameter_mm)
        self._lanes = DrillingLanes(params, 1)
        self._lanes.start(
            0, params, self.diameter_mm, self.target_depth_mm, self.start_position_mm, self.coeffs
        )
        self._inputs = np.zeros((1, _N_IN))

    def reset(self, speed_hz: float | None = None, voltage: float | None = None) -> None:
        """Spindle running free at ``voltage`` (default nominal), valve settled, drill at start."""
        self._lanes.restart(0, self.params, self.start_position_mm, speed_hz, voltage)

    x1 = _state_property(_S.X1, "Spool opening x_v.")
    x2 = _state_property(_S.X2, "Spool velocity dx_v/dt, 1/s.")
    omega = _state_property(_S.OMEGA, "Spindle speed, rad/s.")
    t_s = _state_property(_S.T, "Time since the hole started, s.")
    position_mm = _state_property(_S.POS, "Drill point below the surface, mm.")
    depth_mm = _state_property(_S.DEPTH, "Hole depth, mm.")
    packed_mm = _state_property(_S.PACKED, "Length drilled since the chips were cleared, mm.")
    xi_chip = _state_property(_S.XI_CHIP, "Chip-friction fluctuation (unit OU process).")
    xi_cut = _state_property(_S.XI_CUT, "Cutting fluctuation (unit OU process).")
    torque_filt = _state_property(_S.TQ_F, "Torque sensor filter output, N·mm.")
    thrust_filt = _state_property(_S.TH_F, "Thrust sensor filter output, N.")
    torque_Nmm = _state_property(_S.TQ, "Torque at the last sample instant, N·mm.")
    thrust_N = _state_property(_S.TH, "Thrust at the last sample instant, N.")
    voltage = _state_property(_S.VOLT, "Valve voltage now applied, V.")

    @property
    def finished(self) -> bool:
        """Whether the hole has reached its target depth."""
        return bool(self._lanes.state[0, _S.FINISHED])

    @property
    def state(self) -> np.ndarray:
        """``[x_v, dx_v/dt, omega (rad/s)]``: the paper's x1, x2, x3 (eq. 18-19)."""
        return self._lanes.state[0, [_S.X1, _S.X2, _S.OMEGA]].copy()

    def engagement(self, depth_mm: float) -> tuple[float, float]:
        """Engaged share of torque and thrust with the point ``depth_mm`` below the surface."""
        return _engagement(self._lanes.eng, 0, self._lanes.par[0, _P.FULL], float(depth_mm))

    def step(
        self,
        voltage: float,
        feed_velocity_mm_s: float,
        noise: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0),
    ) -> DrillingStep:
        """Hold ``voltage`` (V) and ``feed_velocity_mm_s`` for one sample and advance.

        ``noise`` holds five standard normal draws: the chip and cutting fluctuation
        innovations and the torque, thrust and speed sensor noises.
        """
        inp = self._inputs
        inp[0, 0] = voltage
        inp[0, 1] = feed_velocity_mm_s
        inp[0, 2:] = noise
        self._lanes.step(inp)
        o = self._lanes.out[0].tolist()
        finish = o[17]
        return DrillingStep(
            *o[:15],
            cutting=o[15] != 0.0,
            engagement=o[16],
            finish_time_s=None if math.isnan(finish) else finish,
        )
