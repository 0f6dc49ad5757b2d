r"""Two-axis contouring servo of Choi et al. (seed 004): velocity loop, motor, table.

Each feed axis of the machining centre's XY table is a motor with a proportional velocity
loop (the servo pack), driving the table through a ball screw. With the velocity command
``u`` and the table position ``x`` both expressed at the table (mm/s and mm, through the
screw lead), and the load torque ``T_L`` at the motor shaft entering as a disturbance:

.. math::

    J \dot\omega &= K_{sp} K_t (\omega_{ref} - \omega) - T_L \qquad
        \omega = \tfrac{2\pi}{\ell} \dot x,\ \omega_{ref} = \tfrac{2\pi}{\ell} u \\
    \ddot x &= a (u - \dot x) - \frac{\ell}{2\pi} \frac{T_L}{J}, \qquad a = \frac{K_{sp} K_t}{J}

so that with ``T_L = 0`` the command-to-position transfer function is the paper's

.. math:: G(s) = \frac{K_{sp} K_t}{J s^2 + K_{sp} K_t s} = \frac{a}{s (s + a)}

(paper §2; the OCR'd equation puts ``T_L`` inside the transfer function; here it is an
input). Both inputs are held over each servo period and the axes are discretised exactly
(ZOH) once; a step is then eight multiply-adds per axis.

This module imports numpy, scipy and numba only; it knows nothing of gymnasium.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from machining_envs.contouring._exact import vecmat_rows
from machining_envs.core.checks import CheckedParams, checked_params, ranged
from machining_envs.core.compiled.kernels import read_only

__all__ = ["ContouringParams", "ContouringPlant", "ContouringStep", "AXES", "step_axes"]
__all__ += ["PLANT_COLUMNS", "vecmat_rows"]
# ``vecmat_rows(z, mt, out)``: ``out[i] = z[i] @ mt.T`` row by row, each row exactly as numpy
# computes the 1-D product alone (the order the servo loops sum in), for controllers that
# must give the numbers the env's own loops give (``agents.contouring``).

#: The two feed axes, in the order every array of this package uses.
AXES = ("x", "y")


@checked_params()
@dataclass(frozen=True)
class ContouringParams(CheckedParams):
    """Identified parameters of one XY table (Choi et al., seed 004, Table 1).

    Every field is a physical constant with its unit; derived quantities (the velocity-loop
    pole ``a``, discrete matrices, the command limit in mm/s) are computed from the fields.
    """

    velocity_loop_gain: float = ranged(0.0, 1e4, default=1.3, lo_open=True)
    """Ksp, proportional gain of the servo pack's velocity loop, A per rad/s (Table 1)."""

    torque_constant_Nm_per_A: float = ranged(0.0, 1e3, default=1.2054, lo_open=True)
    """Kt, motor torque constant, N m / A (Table 1)."""

    inertia_x_kgm2: float = ranged(0.0, 10.0, default=2.29 * 0.00376, lo_open=True)
    """Jx, X motor plus table inertia at the motor shaft, kg m^2 (Table 1: 2.29 x 0.00376)."""

    inertia_y_kgm2: float = ranged(0.0, 10.0, default=3.04 * 0.00376, lo_open=True)
    """Jy, Y motor plus table inertia at the motor shaft, kg m^2 (Table 1: 3.04 x 0.00376)."""

    screw_lead_mm: float = ranged(0.0, 1e3, default=10.0, lo_open=True)
    """Ball-screw lead, table mm per motor revolution. Not given in the paper: 10 mm is the
    usual lead of a 40-taper vertical machining centre's directly coupled X/Y screws. It only
    scales the load torque's effect (1 N m is 628 N of feed force at 10 mm) and the command
    limit; the command-to-position dynamics G(s) do not depend on it."""

    motor_max_rpm: float = ranged(0.0, 1e5, default=2000.0, lo_open=True)
    """Top motor speed, rpm: the limit of the velocity command. Not given in the paper:
    2000 rpm is the top speed of the 0.85 kW-class AC servo motors of the period (the paper's
    Yaskawa USAMED-09); with the 10 mm lead it is 333 mm/s (20 m/min) at the table."""

    sample_time_s: float = ranged(0.0, 0.01, default=2e-4, lo_open=True)
    """Servo period (position-loop sample time), s: 5 kHz. Chosen so that the H-infinity
    design of the paper, whose loop crosses over near 560 rad/s, keeps its continuous-time
    behaviour once discretised: at 5 kHz (Tustin) its step response overshoots 0.5 % and
    settles (2 %) in 8.4 ms like the continuous loop's 9.0 ms; at 1 kHz the same design
    overshoots 10 % and rings for 40 ms, at 2 kHz it overshoots 2 % (see docs/contouring.md)."""

    @classmethod
    def choi_et_al(cls) -> ContouringParams:
        """The TNV-40 machining centre's X/Y axes of the paper's Table 1 (the defaults)."""
        return cls()

    # ---- derived quantities (never stored) -------------------------------------------------
    def inertia_kgm2(self, axis: str) -> float:
        """J of ``axis`` ('x' or 'y'), kg m^2."""
        if axis == "x":
            return self.inertia_x_kgm2
        if axis == "y":
            return self.inertia_y_kgm2
        raise ValueError(f"axis must be 'x' or 'y', got {axis!r}")

    @property
    def loop_gain_Nms(self) -> float:
        """Ksp Kt, N m per rad/s of velocity error."""
        return self.velocity_loop_gain * self.torque_constant_Nm_per_A

    def velocity_pole(self, axis: str) -> float:
        """a = Ksp Kt / J, 1/s: the closed velocity loop's bandwidth (pole of G at -a)."""
        return self.loop_gain_Nms / self.inertia_kgm2(axis)

    def time_constant_s(self, axis: str) -> float:
        """1/a, s: the velocity loop's time constant (5.5 ms on X, 7.3 ms on Y)."""
        return 1.0 / self.velocity_pole(axis)

    @property
    def mm_per_rad(self) -> float:
        """Table travel per radian of motor rotation, mm."""
        return self.screw_lead_mm / (2.0 * math.pi)

    @property
    def command_max_mm_s(self) -> float:
        """Largest velocity command, mm/s at the table: top motor speed through the lead."""
        return self.motor_max_rpm / 60.0 * self.screw_lead_mm

    def transfer_function(self, axis: str) -> tuple[list[float], list[float]]:
        """``(num, den)`` of G(s) = Ksp Kt / (J s^2 + Ksp Kt s), command mm/s to position mm."""
        j = self.inertia_kgm2(axis)
        kk = self.loop_gain_Nms
        return [kk], [j, kk, 0.0]

    def continuous_axis(self, axis: str) -> tuple[np.ndarray, np.ndarray]:
        """``(A, B)`` of one axis, state ``[x mm, v mm/s]``, inputs ``[u mm/s, T_L N m]``."""
        a = self.velocity_pole(axis)
        load = -self.mm_per_rad / self.inertia_kgm2(axis)
        return np.array([[0.0, 1.0], [0.0, -a]]), np.array([[0.0, 0.0], [a, load]])

    def discrete_axis(self, axis: str) -> tuple[np.ndarray, np.ndarray]:
        """Exact ZOH ``(Phi, Gamma)`` of one axis over ``sample_time_s`` (cached)."""
        return _axis_zoh(
            self.velocity_pole(axis), -self.mm_per_rad / self.inertia_kgm2(axis), self.sample_time_s
        )


@functools.lru_cache(maxsize=64)
def _axis_zoh(a: float, load_gain: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The exact ZOH ``(Phi, Gamma)`` of one axis (``A = [[0, 1], [0, -a]]``,
    ``B = [[0, 0], [a, g]]``), read-only: :func:`axes_zoh` of the one axis, the one source
    of the axes' discretisation (the plant, the servo's designs and the vector env's
    lanes)."""
    e = axes_zoh(np.array([a]), np.array([load_gain]), np.array([dt]))[0]
    return read_only(e[:2, :2], e[:2, 2:])


def axes_zoh(a: np.ndarray, load_gain: np.ndarray, dt: np.ndarray) -> np.ndarray:
    r"""The exact ZOH discretisations ``(n, 4, 4)`` of ``n`` axes (arrays of their ``a``,
    ``g`` and ``dt``): the exponential of :func:`_axis_zoh`'s block matrix
    ``[[A, B], [0, 0]] dt``, ``Phi`` in ``[:, :2, :2]``, ``Gamma`` in ``[:, :2, 2:]``. A
    vector env's lanes discretise their tables, whose inertias are random, at every reset:
    here all of them in one compiled call (:func:`axes_zoh_into`).

    The axis is a velocity loop of pole ``a`` behind an integrator, so its exponential has a
    closed form in ``q = a dt``: with ``E = exp(-q)``, ``phi1 = (1 - E) / q`` and
    ``phi2 = (q - 1 + E) / q^2``,

    .. math::

        \Phi = \begin{bmatrix} 1 & dt\,\phi_1 \\ 0 & E \end{bmatrix}, \qquad
        \Gamma = \begin{bmatrix} dt\,q\,\phi_2 & g\,dt^2 \phi_2 \\
                                  q\,\phi_1 & g\,dt\,\phi_1 \end{bmatrix}

    (the step responses of ``v' = -a v + b w``, ``x' = v`` to a held input ``w``, ``b = a``
    for the command and ``g`` for the load torque). ``phi1`` comes from ``expm1``, ``phi2``
    from its Taylor series below ``q = 1`` (where ``q - 1 + E`` would cancel), so each entry
    is the exact value to ``16 + q`` units in the last place (against 40-digit arithmetic),
    and scipy's ``expm`` (``core.lti.zoh``) to 1e-13 over the scenarios' tables (``expm``
    is itself up to 64 units from the exact values there; ``tests/contouring/test_plant.py``).
    ``expm``, a Pade approximant through BLAS and LAPACK, cost about 5 µs an axis and woke
    OpenBLAS's threads at every reset."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    g = np.ascontiguousarray(load_gain, dtype=np.float64)
    h = np.ascontiguousarray(dt, dtype=np.float64)
    out = np.zeros((a.shape[0], 4, 4))
    axes_zoh_into(a, g, h, out)
    return out


#: Taylor coefficients of ``phi2(q) = (q - 1 + exp(-q)) / q^2 = sum_k (-q)^k / (k + 2)!``,
#: ``k = 0 .. 21`` (below ``q = 1`` the first term left out is under 1e-22 of the sum).
_PHI2_SERIES = np.array([(-1.0) ** k / math.factorial(k + 2) for k in range(22)])


@numba.njit(cache=True)
def axes_zoh_into(a, g, dt, out):
    """:func:`axes_zoh`'s closed form for each axis ``i`` into ``out[i]`` (zeros on
    entry)."""
    c = _PHI2_SERIES
    for i in range(a.shape[0]):
        h = dt[i]
        q = a[i] * h
        em1 = math.expm1(-q)  # E - 1
        phi1 = -em1 / q if q != 0.0 else 1.0  # (no velocity loop: a double integrator)
        if q < 1.0:
            phi2 = c[c.size - 1]
            for k in range(c.size - 2, -1, -1):
                phi2 = phi2 * q + c[k]
        else:
            phi2 = (q + em1) / (q * q)
        e = out[i]
        e[0, 0] = 1.0
        e[0, 1] = h * phi1
        e[0, 2] = h * q * phi2
        e[0, 3] = g[i] * h * h * phi2
        e[1, 1] = math.exp(-q)
        e[1, 2] = q * phi1
        e[1, 3] = g[i] * h * phi1
        e[2, 2] = 1.0
        e[3, 3] = 1.0


class ContouringStep(NamedTuple):
    """Signals of one servo period, at its end unless stated."""

    x_mm: float
    y_mm: float
    vx_mm_s: float
    vy_mm_s: float
    torque_x_Nm: float
    """Mean motor torque of X over the period, N m: J dw/dt + T_L (exact for the ZOH step)."""
    torque_y_Nm: float


#: Numbers of one table in :func:`step_axes`'s ``c``: the X axis's ``Phi`` and ``Gamma``
#: (row by row), the Y axis's, the command limit, the two torque factors.
PLANT_COLUMNS = 19


@numba.njit(cache=True)
def step_axes(c, z, ux, uy, lx, ly):
    """Both axes over one servo period (:meth:`ContouringPlant.step`'s arithmetic): the
    commands ``ux``, ``uy`` (mm/s, clipped to the limit ``c[16]``) and load torques ``lx``,
    ``ly`` (N m) held; ``z = [x, vx, y, vy]`` is updated in place. Returns the mean motor
    torques of the period."""
    m = c[16]
    ux = m if ux > m else (-m if ux < -m else ux)
    uy = m if uy > m else (-m if uy < -m else uy)
    x = z[0]
    vx = z[1]
    y = z[2]
    vy = z[3]
    xn = c[0] * x + c[1] * vx + c[4] * ux + c[5] * lx
    vxn = c[2] * x + c[3] * vx + c[6] * ux + c[7] * lx
    yn = c[8] * y + c[9] * vy + c[12] * uy + c[13] * ly
    vyn = c[10] * y + c[11] * vy + c[14] * uy + c[15] * ly
    z[0] = xn
    z[1] = vxn
    z[2] = yn
    z[3] = vyn
    return c[17] * (vxn - vx) + lx, c[18] * (vyn - vy) + ly


class ContouringPlant:
    """Both axes of the XY table: eight multiply-adds per axis and period (:func:`step_axes`).

    Parameters
    ----------
    params : ContouringParams
        The table's true parameters.

    The state is ``[x, vx, y, vy]`` (mm, mm/s). :meth:`step` holds the velocity commands
    (clipped to ``+-command_max_mm_s``) and load torques over one servo period.
    :meth:`step_batch` is the same update on arrays of states, for vectorised use.
    """

    def __init__(self, params: ContouringParams) -> None:
        if not isinstance(params, ContouringParams):
            raise ValueError(f"params must be a ContouringParams, got {type(params).__name__}")
        self.params = params
        phx, gax = params.discrete_axis("x")
        phy, gay = params.discrete_axis("y")
        self._umax = params.command_max_mm_s
        # Torque from the velocity change: J (2 pi / lead) dv / Ts.
        k = 1.0 / (params.mm_per_rad * params.sample_time_s)
        #: The numbers :func:`step_axes` reads (``PLANT_COLUMNS`` of them).
        self.coefficients = np.concatenate(
            (
                phx.ravel(),
                gax.ravel(),
                phy.ravel(),
                gay.ravel(),
                (self._umax, params.inertia_x_kgm2 * k, params.inertia_y_kgm2 * k),
            )
        )
        self.z = np.zeros(4)
        self.reset()

    # The block forms, for step_batch, made on first use: a vector env's lane makes a
    # plant at every reset and never reads them.
    @functools.cached_property
    def phi(self) -> np.ndarray:
        """Both axes' ``Phi`` in block form on ``z = [x, vx, y, vy]``, (4, 4)."""
        return self._block_form(0)

    @functools.cached_property
    def gamma(self) -> np.ndarray:
        """Both axes' ``Gamma`` in block form on the inputs ``w = [ux, TLx, uy, TLy]``."""
        return self._block_form(4)

    def _block_form(self, first: int) -> np.ndarray:
        """The X axis's 2x2 matrix at ``coefficients[first:first + 4]`` and the Y axis's
        eight further on, as one block-diagonal (4, 4) matrix."""
        c = self.coefficients
        out = np.zeros((4, 4))
        out[:2, :2] = c[first : first + 4].reshape(2, 2)
        out[2:, 2:] = c[first + 8 : first + 12].reshape(2, 2)
        return out

    def reset(self, x0_mm: float = 0.0, y0_mm: float = 0.0) -> None:
        """Table at rest at ``(x0, y0)``."""
        self.z[:] = (float(x0_mm), 0.0, float(y0_mm), 0.0)
        self.t_s = 0.0

    @property
    def state(self) -> np.ndarray:
        """``[x mm, vx mm/s, y mm, vy mm/s]`` now."""
        return self.z.copy()

    def step(
        self, ux: float, uy: float, load_x_Nm: float = 0.0, load_y_Nm: float = 0.0
    ) -> ContouringStep:
        """Hold the commands (mm/s, clipped) and load torques (N m) for one servo period."""
        z = self.z
        tx, ty = step_axes(
            self.coefficients, z, float(ux), float(uy), float(load_x_Nm), float(load_y_Nm)
        )
        self.t_s += self.params.sample_time_s
        return ContouringStep(float(z[0]), float(z[2]), float(z[1]), float(z[3]), tx, ty)

    def step_batch(self, z: np.ndarray, w: np.ndarray) -> np.ndarray:
        """States ``z`` (n, 4) after one period under inputs ``w`` (n, 4) = [ux, TLx, uy, TLy].

        Commands are clipped like :meth:`step`; returns the new states (n, 4).
        """
        w = np.array(w, dtype=np.float64, copy=True)
        np.clip(w[:, 0], -self._umax, self._umax, out=w[:, 0])
        np.clip(w[:, 2], -self._umax, self._umax, out=w[:, 2])
        return z @ self.phi.T + w @ self.gamma.T
