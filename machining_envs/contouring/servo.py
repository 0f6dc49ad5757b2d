r"""Position-loop controllers of the CNC: design once from a nominal axis, run as difference
equations.

Two designs for one axis of :mod:`machining_envs.contouring.plant`, both returned as a
discrete state-space controller at the servo period (:class:`ServoDesign`)

.. math::

    \xi_{k+1} = A \xi_k + B \begin{bmatrix} r_k \\ y_k \end{bmatrix}, \qquad
    u_k = C \xi_k + D \begin{bmatrix} r_k \\ y_k \end{bmatrix}

from the position set point ``r`` and the measured position ``y`` (mm) to the velocity
command ``u`` (mm/s). Positions enter relative to where the table stood at the start
(the controller state starts at zero, the equilibrium of a table at rest on its set point),
which keeps the numbers small and makes the loop indifferent to where on the table it runs.

- :func:`pi_design`: PI with set-point weighting, ``u = Kp (b r - y) + Ki int(r - y)``,
  by pole placement (see its docstring);
- :func:`hinf_2dof_design`: the Hoyle-Hyde-Limebeer two-degree-of-freedom H-infinity
  loop-shaping design of the paper (§4), synthesised with python-control's ``hinfsyn``.

Both are synthesised once per axis model and cached; nothing here runs per step except
:class:`ServoLoop`, which precomputes the closed loop of a design and a (true) plant and
advances it a block of servo periods at a time with a few matrix products.

python-control and slycot are imported only inside the H-infinity design.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import schur, solve_continuous_are
from scipy.signal import cont2discrete

from machining_envs.contouring.plant import AXES, ContouringParams
from machining_envs.core.checks import PY_NUMBER_TYPES, check_integer, check_range

__all__ = [
    "ServoDesign",
    "pi_design",
    "hinf_2dof_design",
    "closed_loop",
    "ServoLoop",
    "SERVO_KINDS",
    "servo_design",
    "HINF_MODEL_POLE",
    "HINF_WEIGHT_GAIN",
    "HINF_WEIGHT_POLE",
    "HINF_RHO",
]

#: Reference model M0 = 500 / (s + 500) (paper §4.2 step 1): first order, so no overshoot.
HINF_MODEL_POLE = 500.0
#: Loop-shaping weight W = 1e6 / (s + 1e-3) (paper §4.2 step 2).
HINF_WEIGHT_GAIN = 1e6
HINF_WEIGHT_POLE = 1e-3
#: rho, the weight of model matching against robust stabilisation in the 2-DOF problem
#: (Skogestad & Postlethwaite §9.4.3). Not given in the paper: 1, their example's choice
#: and the smallest gamma in their recommended range 1-3.
HINF_RHO = 1.0
#: Controller modes faster than this (rad/s) are residualised: the optimal H-infinity
#: controller carries one mode near 1e12 rad/s (the solution degenerates at the optimal
#: gamma), which a 5 kHz loop cannot represent; replacing it by its static gain changes
#: nothing below 1e8 rad/s.
FAST_MODE_RAD_S = 1e6


@dataclass(frozen=True, eq=False)
class ServoDesign:
    """A discrete position controller for one axis (inputs ``[r, y]`` mm, output mm/s)."""

    kind: str
    """``"pi"`` or ``"hinf"``."""
    axis: str
    sample_time_s: float
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    continuous: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    """The continuous controller ``(A, B, C, D)`` it was discretised from (Tustin)."""
    gamma: float | None = None
    """Achieved H-infinity norm of the 2-DOF problem (None for PI)."""
    details: dict = field(default_factory=dict)
    """Design numbers: gains, pole, prefilter, rho, ... (see the design functions)."""

    @property
    def n_states(self) -> int:
        return self.a.shape[0]


def _frozen(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    out = []
    for a in arrays:
        a = np.array(a, dtype=np.float64)
        a.setflags(write=False)
        out.append(a)
    return tuple(out)


def _tustin(a, b, c, d, ts):
    ad, bd, cd, dd, _ = cont2discrete((a, b, c, d), ts, method="bilinear")
    return ad, bd, cd, dd


def closed_loop(params: ContouringParams, design: ServoDesign, axis: str | None = None):
    """Discrete closed loop of ``design`` on ``params``'s axis (ZOH plant at the same period).

    State ``[x, v, xi]``; inputs ``[r, T_L]``. Returns ``(A, B, Cy, Cu, Du)`` with position
    ``y = Cy z`` and command ``u = Cu z + Du [r, T_L]``.
    """
    axis = axis or design.axis
    if abs(params.sample_time_s - design.sample_time_s) > 1e-15:
        raise ValueError(
            f"sample_time_s of the plant ({params.sample_time_s}) and the design "
            f"({design.sample_time_s}) differ"
        )
    phi, gam = params.discrete_axis(axis)
    gu, gl = gam[:, :1], gam[:, 1:]
    n = design.n_states
    e1 = np.array([[1.0, 0.0]])
    dr, dy = design.d[:, :1], design.d[:, 1:]
    br, by = design.b[:, :1], design.b[:, 1:]
    a = np.block([[phi + gu @ dy @ e1, gu @ design.c], [by @ e1, design.a]])
    b = np.block([[gu @ dr, gl], [br, np.zeros((n, 1))]])
    cy = np.hstack([e1, np.zeros((1, n))])
    cu = np.hstack([dy @ e1, design.c])
    du = np.hstack([dr, np.zeros((1, 1))])
    return a, b, cy, cu, du


# ---- PI ------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=32)
def _pi(a_pole: float, ts: float, axis: str) -> ServoDesign:
    kp = a_pole / 3.0
    ki = a_pole**2 / 27.0
    b_w = 1.0 / 3.0
    ca = np.zeros((1, 1))
    cb = np.array([[1.0, -1.0]])
    cc = np.array([[ki]])
    cd = np.array([[kp * b_w, -kp]])
    ad, bd, cdd, dd = _tustin(ca, cb, cc, cd, ts)
    return ServoDesign(
        "pi",
        axis,
        ts,
        *_frozen(ad, bd, cdd, dd),
        continuous=_frozen(ca, cb, cc, cd),
        details={
            "kp_per_s": kp,
            "ki_per_s2": ki,
            "setpoint_weight": b_w,
            "closed_loop_pole_rad_s": a_pole / 3.0,
        },
    )


def pi_design(params: ContouringParams, axis: str) -> ServoDesign:
    r"""PI position controller for one axis, tuned by pole placement, without overshoot.

    With the axis ``G(s) = a / (s (s + a))`` and ``u = Kp (b r - y) + Ki \int (r - y)``, the
    closed loop's characteristic polynomial is ``s^3 + a s^2 + a Kp s + a Ki``. Placing all
    three poles at one real value ``-p`` is possible only for ``p = a / 3`` (the fastest
    critically damped placement), which gives ``Kp = a / 3`` and ``Ki = a^2 / 27`` (1/s,
    1/s^2). With the set-point weight ``b = 1/3`` the controller's reference zero cancels one
    of the three poles and the step response is ``p^2 / (s + p)^2``: critically damped, so no
    overshoot, and the fastest set-point response a PI on this axis has without overshoot
    (a larger ``b`` moves the zero right of ``-p`` and the response overshoots; with a pure
    integrator in the loop, ``b = 1`` always overshoots). Discretised by Tustin.

    X: ``p = 60.7 rad/s`` (``Kp = 60.7 /s``, ``Ki = 1227 /s^2``); Y: ``p = 45.7 rad/s``.
    """
    return _pi(params.velocity_pole(axis), params.sample_time_s, axis)


# ---- H-infinity 2-DOF ----------------------------------------------------------------------
def _residualise(a, b, c, d, limit: float):
    """Singular-perturbation reduction: modes with ``|lambda| > limit`` replaced by their
    static gain (DC gain and all behaviour well below ``limit`` kept)."""
    t, z, sdim = schur(a, output="real", sort=lambda x, y: math.hypot(x, y) <= limit)
    if sdim == a.shape[0]:
        return a, b, c, d
    k = sdim
    bz, cz = z.T @ b, c @ z
    a11, a12, a21, a22 = t[:k, :k], t[:k, k:], t[k:, :k], t[k:, k:]
    x = np.linalg.solve(a22, np.hstack([a21, bz[k:]]))
    x21, xb = x[:, :k], x[:, k:]
    return a11 - a12 @ x21, bz[:k] - a12 @ xb, cz[:, :k] - cz[:, k:] @ x21, d - cz[:, k:] @ xb


def _generalized_plant(a_pole: float, rho: float, m0: float, wg: float, wp: float):
    """Skogestad & Postlethwaite (2005) §9.4.3, eq. (9.87): the 2-DOF loop-shaping plant.

    Shaped plant ``Gs = G W`` with ``G = a / (s (s + a))`` and ``W = wg / (s + wp)``,
    state ``[x, v, w]`` (W realised with its gain split evenly between input and output, so
    that 1e6 does not sit in one entry); reference model ``Tref = m0 / (s + m0)``.
    Inputs ``[r, phi, us]``, outputs ``[us, ys, e, rho r, y]`` where ``phi`` is the
    normalised coprime-factor perturbation and ``e = rho (ys - rho Tref r)``.
    """
    g = math.sqrt(wg)
    a_s = np.array([[0.0, 1.0, 0.0], [0.0, -a_pole, a_pole * g], [0.0, 0.0, -wp]])
    b_s = np.array([[0.0], [0.0], [g]])
    c_s = np.array([[1.0, 0.0, 0.0]])
    # Ds = 0, so Rs = Ss = I: the normalised coprime factorisation's filter Riccati equation
    # A Z + Z A' - Z C'C Z + B B' = 0.
    z_s = solve_continuous_are(a_s.T, c_s.T, b_s @ b_s.T, np.eye(1))
    a_r, b_r, c_r, d_r = (np.array([[v]]) for v in (-m0, m0, 1.0, 0.0))
    ns = 3
    a = np.block([[a_s, np.zeros((ns, 1))], [np.zeros((1, ns)), a_r]])
    b1 = np.block([[np.zeros((ns, 1)), z_s @ c_s.T], [b_r, np.zeros((1, 1))]])
    b2 = np.vstack([b_s, np.zeros((1, 1))])
    c1 = np.vstack(
        [
            np.zeros((1, ns + 1)),
            np.hstack([c_s, np.zeros((1, 1))]),
            np.hstack([rho * c_s, -rho * rho * c_r]),
        ]
    )
    c2 = np.vstack([np.zeros((1, ns + 1)), np.hstack([c_s, np.zeros((1, 1))])])
    d11 = np.array([[0.0, 0.0], [0.0, 1.0], [-rho * rho * d_r[0, 0], rho]])
    d12 = np.array([[1.0], [0.0], [0.0]])
    d21 = np.array([[rho, 0.0], [0.0, 1.0]])
    d22 = np.zeros((2, 1))
    return (
        a,
        np.hstack([b1, b2]),
        np.vstack([c1, c2]),
        np.block([[d11, d12], [d21, d22]]),
        (a_s, b_s, c_s),
    )


@functools.lru_cache(maxsize=32)
def _hinf(
    a_pole: float, ts: float, axis: str, rho: float, m0: float, wg: float, wp: float
) -> ServoDesign:
    try:
        import control
    except ImportError as exc:  # pragma: no cover - control is a dependency
        raise ImportError(
            "the H-infinity design needs python-control: pip install control"
        ) from exc
    a, b, c, d, _ = _generalized_plant(a_pole, rho, m0, wg, wp)
    plant = control.ss(a, b, c, d)
    try:
        k, _, gamma, _ = control.hinfsyn(plant, 2, 1)
    except control.ControlSlycot as exc:  # pragma: no cover - slycot is a dependency
        raise ImportError("the H-infinity design needs slycot: pip install slycot") from exc
    gamma = float(gamma)
    if not math.isfinite(gamma):
        raise RuntimeError(f"hinfsyn found no stabilising controller for axis {axis!r}")
    ka, kb, kc, kd = _residualise(
        np.asarray(k.A), np.asarray(k.B), np.asarray(k.C), np.asarray(k.D), FAST_MODE_RAD_S
    )
    n_k = ka.shape[0]
    # The implemented controller u = W (K1 rho r + K2 y): K's output through W's state w.
    g = math.sqrt(wg)
    ca = np.block([[ka, np.zeros((n_k, 1))], [g * kc, np.array([[-wp]])]])
    cb = np.vstack([kb @ np.diag([rho, 1.0]), g * kd @ np.diag([rho, 1.0])])
    cc = np.hstack([np.zeros((1, n_k)), np.array([[g]])])
    cd = np.zeros((1, 2))
    ad, bd, cdd, dd = _tustin(ca, cb, cc, cd, ts)
    design = ServoDesign("hinf", axis, ts, *_frozen(ad, bd, cdd, dd), continuous=(ca, cb, cc, cd))
    # Constant prefilter (S&P eq. 9.90): scale the reference input so that the discrete
    # closed loop's steady-state gain from r to y is exactly 1.
    params = ContouringParams(sample_time_s=ts)
    nominal = params.replace(inertia_x_kgm2=params.loop_gain_Nms / a_pole)
    acl, bcl, cy, _, _ = closed_loop(nominal, design, "x")
    radius = float(np.max(np.abs(np.linalg.eigvals(acl))))
    if not radius < 1.0:
        raise RuntimeError(
            f"the discretised H-infinity loop of axis {axis!r} is unstable at "
            f"{1 / ts:.0f} Hz (spectral radius {radius:.6f}); use a shorter sample_time_s"
        )
    dc = float((cy @ np.linalg.solve(np.eye(acl.shape[0]) - acl, bcl[:, :1]))[0, 0])
    pre = 1.0 / dc
    bd = bd.copy()
    dd = dd.copy()
    bd[:, 0] *= pre
    dd[:, 0] *= pre
    cb = cb.copy()
    cb[:, 0] *= pre
    cd = cd.copy()
    cd[:, 0] *= pre
    return ServoDesign(
        "hinf",
        axis,
        ts,
        *_frozen(ad, bd, cdd, dd),
        continuous=_frozen(ca, cb, cc, cd),
        gamma=gamma,
        details={
            "gamma": gamma,
            "epsilon": 1.0 / gamma,
            "rho": rho,
            "prefilter": pre,
            "model_pole_rad_s": m0,
            "weight_gain": wg,
            "weight_pole_rad_s": wp,
            "controller_states": int(ca.shape[0]),
            "discrete_spectral_radius": radius,
        },
    )


def hinf_2dof_design(
    params: ContouringParams,
    axis: str,
    rho: float = HINF_RHO,
    model_pole: float = HINF_MODEL_POLE,
    weight_gain: float = HINF_WEIGHT_GAIN,
    weight_pole: float = HINF_WEIGHT_POLE,
) -> ServoDesign:
    r"""Hoyle-Hyde-Limebeer 2-DOF H-infinity loop-shaping position controller (paper §4).

    1. Shape the axis with the paper's weight ``W = 1e6 / (s + 1e-3)``: ``Gs = G W``.
    2. Build the generalised plant of Skogestad & Postlethwaite §9.4.3 (eq. 9.87) from the
       normalised coprime factors of ``Gs`` and the reference model
       ``M0 = 500 / (s + 500)``; its exogenous inputs are the reference and the coprime-factor
       perturbation, its errors the control, the output and ``rho`` times the model-matching
       error; the controller ``K = [K1 K2]`` reads ``rho r`` and ``y``.
    3. Synthesise the H-infinity optimal ``K`` with python-control's ``hinfsyn`` (slycot's
       SB10AD, Glover-Doyle formulas); residualise its one degenerate fast mode.
    4. Implement ``u = W (K1 rho r + K2 y)`` (positive feedback convention), discretise by
       Tustin at ``sample_time_s`` and scale the reference input by the constant prefilter
       that makes the closed loop's steady-state gain exactly 1 (S&P eq. 9.90).

    The achieved ``gamma`` is in ``.gamma`` (about 5.8 on X, 6.0 on Y). A design is
    computed once per distinct axis model and cached; raises ``RuntimeError`` if the
    discretised loop is unstable.
    """
    for name, v, lo, hi in (
        ("rho", rho, 1e-3, 1e3),
        ("model_pole", model_pole, 1e-3, 1e6),
        ("weight_gain", weight_gain, 1e-6, 1e12),
        ("weight_pole", weight_pole, 0.0, 1e6),
    ):
        check_range(name, v, lo, hi, types=PY_NUMBER_TYPES, allow_bool=True)
    return _hinf(
        params.velocity_pole(axis),
        params.sample_time_s,
        axis,
        float(rho),
        float(model_pole),
        float(weight_gain),
        float(weight_pole),
    )


#: Servo kinds the contouring envs and agents know, by name.
SERVO_KINDS = ("pi", "hinf")


def servo_design(kind: str, params: ContouringParams, axis: str) -> ServoDesign:
    """The cached ``"pi"`` or ``"hinf"`` design of ``params``'s ``axis``."""
    if kind == "pi":
        return pi_design(params, axis)
    if kind == "hinf":
        return hinf_2dof_design(params, axis)
    raise ValueError(f"servo must be one of {SERVO_KINDS}, got {kind!r}")


class ServoLoop:
    """Both axes' closed loops (a design on a true plant), advanced a block at a time.

    The loop is linear until a command reaches the drive's limit, so a block of ``n``
    servo periods is one product of precomputed matrices: state, positions, commands and
    velocities over the block follow from the state at its start and the block's reference
    and load-torque samples. Where a command would pass the limit, the block is run again
    period by period with the command clipped (the controller, which does not know of the
    clip, carries on unchanged). Positions are relative to the table's start.

    Parameters
    ----------
    truth : ContouringParams
        The plant the loop runs on.
    designs : (ServoDesign, ServoDesign)
        The X and Y controllers (designed from the nominal plant).
    block : int
        Servo periods per block.
    """

    def __init__(self, truth: ContouringParams, designs, block: int) -> None:
        check_integer("block", block, 1, 10000, types=(int,), allow_bool=True)
        self.truth = truth
        self.designs = tuple(designs)
        self.block = block
        self._umax = truth.command_max_mm_s
        nb = block
        self._axes = []
        blocks = []
        offset = 0
        for axis, design in zip(AXES, self.designs, strict=True):
            a, b, _, cu, du = closed_loop(truth, design, axis)
            n = a.shape[0]
            # z_j = A^j z_0 + sum_{i<j} A^(j-1-i) B w_i (j = 0..block), w_i = [r_i, TL_i].
            powers = [np.eye(n)]
            for _ in range(nb):
                powers.append(a @ powers[-1])
            free = np.stack(powers)  # (nb+1, n, n)
            pb = np.stack([powers[m] @ b for m in range(nb)])  # A^m B, (nb, n, 2)
            forced = np.zeros((nb + 1, n, nb, 2))
            for j in range(1, nb + 1):
                forced[j, :, :j, :] = pb[j - 1 :: -1].transpose(1, 0, 2)
            # Output rows: positions after each period (nb), velocities at every instant
            # (nb + 1), commands (nb), the state at the block's end (n).
            cu_row = cu[0]
            u_free = np.einsum("k,jkl->jl", cu_row, free[:-1])
            u_forced = np.einsum("k,jkim->jim", cu_row, forced[:-1])
            u_forced[np.arange(nb), np.arange(nb), :] += du[0]
            rows_free = np.concatenate([free[1:, 0, :], free[:, 1, :], u_free, free[-1]])
            rows_forced = np.concatenate(
                [forced[1:, 0], forced[:, 1], u_forced, forced[-1]]
            )  # (R, nb, 2)
            blocks.append((rows_free, rows_forced[:, :, 0], rows_forced[:, :, 1], n))
            self._axes.append(
                {
                    "a": a,
                    "b": b,
                    "cu": cu_row,
                    "du": du[0],
                    "n": n,
                    "gu": truth.discrete_axis(axis)[1][:, 0].copy(),
                    "slice": slice(offset, offset + n),
                }
            )
            offset += n
        self.n_states = offset
        # One matrix for both axes: columns [z_x, z_y, r_x, TL_x, r_y, TL_y].
        n_rows = [rf.shape[0] for rf, *_ in blocks]
        big = np.zeros((sum(n_rows), offset + 4 * nb))
        r0 = 0
        for k, (rf, rr, rl, _) in enumerate(blocks):
            sl = self._axes[k]["slice"]
            big[r0 : r0 + rf.shape[0], sl] = rf
            c0 = offset + 2 * nb * k
            big[r0 : r0 + rf.shape[0], c0 : c0 + nb] = rr
            big[r0 : r0 + rf.shape[0], c0 + nb : c0 + 2 * nb] = rl
            self._axes[k]["rows"] = r0
            r0 += rf.shape[0]
        self._big = big
        self._vec = np.zeros(big.shape[1])
        self._tq = [
            truth.inertia_kgm2(ax) / (truth.mm_per_rad * truth.sample_time_s) for ax in AXES
        ]

    def initial_state(self) -> np.ndarray:
        """Table at rest at its start, controllers at rest: ``[z_x, z_y]``."""
        return np.zeros(self.n_states)

    def run(self, state: np.ndarray, ref: np.ndarray, load: np.ndarray):
        """Advance one block.

        Parameters
        ----------
        state : array
            Closed-loop states of X then Y at the block's start (updated in place).
        ref : (block, 2) array
            Set points (relative to the start) at the block's periods.
        load : (block, 2) array
            Load torques (N m) over the block's periods.

        Returns
        -------
        pos : (block, 2) positions at the end of each period; vel : (block, 2) velocities
        there; cmd : (block, 2) commands applied; torque : (block, 2) mean motor torques;
        clipped : bool, whether a command reached the limit.
        """
        nb = self.block
        ns = self.n_states
        vec = self._vec
        vec[:ns] = state
        vec[ns : ns + nb] = ref[:, 0]
        vec[ns + nb : ns + 2 * nb] = load[:, 0]
        vec[ns + 2 * nb : ns + 3 * nb] = ref[:, 1]
        vec[ns + 3 * nb :] = load[:, 1]
        out = self._big @ vec
        pos = np.empty((nb, 2))
        vel = np.empty((nb + 1, 2))
        cmd = np.empty((nb, 2))
        clipped = False
        for k, ax in enumerate(self._axes):
            r0 = ax["rows"]
            u = out[r0 + 2 * nb + 1 : r0 + 3 * nb + 1]
            if max(u.max(), -u.min()) > self._umax:
                clipped = True
                z, u = self._clipped(ax, state[ax["slice"]], ref[:, k], load[:, k])
                pos[:, k] = z[1:, 0]
                vel[:, k] = z[:, 1]
                state[ax["slice"]] = z[-1]
            else:
                pos[:, k] = out[r0 : r0 + nb]
                vel[:, k] = out[r0 + nb : r0 + 2 * nb + 1]
                state[ax["slice"]] = out[r0 + 3 * nb + 1 : r0 + 3 * nb + 1 + ax["n"]]
            cmd[:, k] = u
        torque = np.diff(vel, axis=0)
        torque *= self._tq
        torque += load
        return pos, vel[1:], cmd, torque, clipped

    def _clipped(self, ax, z0, ref, load):
        a, b, cu, du = ax["a"], ax["b"], ax["cu"], ax["du"]
        n_b = self.block
        z = np.empty((n_b + 1, ax["n"]))
        z[0] = z0
        u = np.empty(n_b)
        # The plant sees the clipped command: the unclipped loop's update plus the clip's
        # correction through the plant's command column.
        gu = ax["gu"]
        for j in range(n_b):
            uj = float(cu @ z[j] + du[0] * ref[j])
            uc = min(max(uj, -self._umax), self._umax)
            u[j] = uc
            z[j + 1] = a @ z[j] + b[:, 0] * ref[j] + b[:, 1] * load[j]
            if uc != uj:
                z[j + 1, :2] += gu * (uc - uj)
        return z, u
