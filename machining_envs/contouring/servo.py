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
:class:`ServoLanes` (and :class:`ServoLoop`, one loop of it), which precomputes the closed
loop of a design and a (true) plant and advances it a block of servo periods at a time,
compiled (:func:`run_block`; a vector env's lanes eight at a time, :func:`run_lanes`).

python-control and slycot are imported only inside the H-infinity design.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numba
import numpy as np
from scipy.linalg import schur, solve_continuous_are

from machining_envs.contouring.plant import AXES, ContouringParams, axes_zoh_into
from machining_envs.core.checks import PY_NUMBER_TYPES, check_integer, check_range
from machining_envs.core.compiled.kernels import (
    add8,
    add_scaled8,
    clip8,
    fma,
    fma8,
    get8,
    load8,
    mul8,
    read_only,
    shift8,
    store8,
    sub8,
    zero8,
)

__all__ = [
    "ServoDesign",
    "pi_design",
    "hinf_2dof_design",
    "stored_hinf_design",
    "synthesize_stored_designs",
    "HINF_DESIGNS_FILE",
    "closed_loop",
    "ServoLoop",
    "ServoLanes",
    "lane_loops",
    "lifted_matrix",
    "run_block",
    "ServoBlock",
    "run_lanes",
    "gather_loops",
    "gather_states",
    "scatter_lanes",
    "LANES",
    "GROUP_SIZE",
    "LANES_STATE_SIZE",
    "ROW_SIZE",
    "SCRATCH_SIZE",
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
    """Read-only float64 copies of ``arrays`` (a design's matrices: designs are cached)."""
    return tuple(read_only(np.array(a, dtype=np.float64)) for a in arrays)


def _tustin(a, b, c, d, ts):
    from scipy.signal import cont2discrete  # here: scipy.signal takes seconds to import

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
def _pi(
    a_pole: float,
    ts: float,
    axis: str,
    kp_scale: float = 1.0,
    ki_scale: float = 1.0,
    setpoint_weight: float = 1.0 / 3.0,
) -> ServoDesign:
    kp = a_pole / 3.0
    ki = a_pole**2 / 27.0
    if kp_scale != 1.0:
        kp = kp * kp_scale
    if ki_scale != 1.0:
        ki = ki * ki_scale
    b_w = setpoint_weight
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


def pi_design(
    params: ContouringParams,
    axis: str,
    kp_scale: float = 1.0,
    ki_scale: float = 1.0,
    setpoint_weight: float = 1.0 / 3.0,
) -> ServoDesign:
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

    ``kp_scale``, ``ki_scale`` and ``setpoint_weight`` move the design away from that
    placement (for tuning; the defaults are the design above).
    """
    return _pi(
        params.velocity_pole(axis), params.sample_time_s, axis, kp_scale, ki_scale, setpoint_weight
    )


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

    The achieved ``gamma`` is in ``.gamma`` (about 5.8 on X, 6.0 on Y). The envs' default
    designs (and the benchmark's tuned rho) are read from the stored file
    (:data:`HINF_DESIGNS_FILE`), so that every machine runs the same servo whatever its
    BLAS; another design is synthesised once per distinct axis model and cached. Raises
    ``RuntimeError`` if the discretised loop is unstable.
    """
    args = _hinf_args(params, axis, rho, model_pole, weight_gain, weight_pole)
    stored = _stored_design(args)
    return stored if stored is not None else _hinf(*args)


def _hinf_args(params, axis, rho, model_pole, weight_gain, weight_pole) -> tuple:
    """The arguments of :func:`_hinf` for ``params``'s ``axis`` (the settings checked)."""
    for name, v, lo, hi in (
        ("rho", rho, 1e-3, 1e3),
        ("model_pole", model_pole, 1e-3, 1e6),
        ("weight_gain", weight_gain, 1e-6, 1e12),
        ("weight_pole", weight_pole, 0.0, 1e6),
    ):
        check_range(name, v, lo, hi, types=PY_NUMBER_TYPES)
    return (
        params.velocity_pole(axis),
        params.sample_time_s,
        axis,
        float(rho),
        float(model_pole),
        float(weight_gain),
        float(weight_pole),
    )


# ---- stored H-infinity designs -------------------------------------------------------------
#
# hinfsyn's result depends on the BLAS and LAPACK kernels the machine picks (the matrices'
# last digits, and from them every trajectory). The designs the envs and the agents use by
# default are synthesised once and stored as package data, every float exact, so that every
# machine runs the same servo; a design of other numbers (another machine's identified axes,
# another rho) is synthesised on the spot. ``machining-bench synthesize`` writes the file
# again and says where.

#: The stored designs (package data).
HINF_DESIGNS_FILE = Path(__file__).resolve().with_name("hinf_designs.json")


def _design_key(args: tuple) -> str:
    """What a stored design was made from, exactly: ``axis|`` and the ``repr`` of the
    velocity pole, sample time, rho, model pole, weight gain and weight pole."""
    a_pole, ts, axis, *rest = args
    return f"{axis}|" + "|".join(repr(float(v)) for v in (a_pole, ts, *rest))


@functools.lru_cache(maxsize=1)
def _stored_designs() -> dict:
    path = HINF_DESIGNS_FILE
    return json.loads(path.read_text())["designs"] if path.is_file() else {}


def _stored_design(args: tuple) -> ServoDesign | None:
    entry = _stored_designs().get(_design_key(args))
    if entry is None:
        return None
    arr = _frozen(*(np.reshape(entry[k], entry[k + "_shape"]) for k in "abcd"))
    cont = _frozen(
        *(
            np.reshape(m, s)
            for m, s in zip(entry["continuous"], entry["continuous_shapes"], strict=True)
        )
    )
    return ServoDesign(
        "hinf",
        args[2],
        float(entry["sample_time_s"]),
        *arr,
        continuous=cont,
        gamma=float(entry["gamma"]),
        details=dict(entry["details"]),
    )


def stored_hinf_design(params: ContouringParams, axis: str, rho: float = HINF_RHO):
    """The stored design of ``params``'s ``axis`` at ``rho`` (exactly those numbers, the
    paper's model pole and weight), or None where none is stored."""
    return _stored_design(
        _hinf_args(params, axis, rho, HINF_MODEL_POLE, HINF_WEIGHT_GAIN, HINF_WEIGHT_POLE)
    )


def _design_entry(d: ServoDesign) -> dict:
    def plain(v):
        return v.item() if isinstance(v, np.generic) else v

    out = {"sample_time_s": float(d.sample_time_s), "gamma": float(d.gamma)}
    for k in "abcd":
        m = np.asarray(getattr(d, k), dtype=np.float64)
        out[k], out[k + "_shape"] = m.ravel().tolist(), list(m.shape)
    out["continuous"] = [np.asarray(m, dtype=np.float64).ravel().tolist() for m in d.continuous]
    out["continuous_shapes"] = [list(np.shape(m)) for m in d.continuous]
    out["details"] = {k: plain(v) for k, v in d.details.items()}
    return out


def synthesize_stored_designs(rhos, path=None, params: ContouringParams | None = None) -> Path:
    """Synthesise the H-infinity design of both axes at each of ``rhos`` on ``params`` (the
    envs' defaults) on this machine and write them to ``path`` (default: the package's
    :data:`HINF_DESIGNS_FILE`); returns the path written."""
    params = params or ContouringParams()
    designs = {}
    for rho in sorted({float(r) for r in rhos}):
        for ax in AXES:
            args = _hinf_args(params, ax, rho, HINF_MODEL_POLE, HINF_WEIGHT_GAIN, HINF_WEIGHT_POLE)
            designs[_design_key(args)] = _design_entry(_hinf.__wrapped__(*args))
    path = Path(path) if path is not None else HINF_DESIGNS_FILE
    doc = {
        "about": "H-infinity 2-DOF designs (machining_envs.contouring.servo.hinf_2dof_design), "
        "synthesised once (python-control hinfsyn) and stored so that every machine runs the "
        "same servo and the same agents; key: axis|velocity pole|sample time|rho|model "
        "pole|weight gain|weight pole. Written by `machining-bench synthesize`.",
        "designs": designs,
    }
    path.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    _stored_designs.cache_clear()
    return path


#: Servo kinds the contouring envs and agents know, by name.
SERVO_KINDS = ("pi", "hinf")


def servo_design(kind: str, params: ContouringParams, axis: str) -> ServoDesign:
    """The cached ``"pi"`` or ``"hinf"`` design of ``params``'s ``axis``."""
    if kind == "pi":
        return pi_design(params, axis)
    if kind == "hinf":
        return hinf_2dof_design(params, axis)
    raise ValueError(f"servo must be one of {SERVO_KINDS}, got {kind!r}")


# ---- the block update -------------------------------------------------------------------
#
# A block of ``nb`` servo periods of one axis's closed loop ``z+ = A z + B w`` (w = [r, T_L],
# ``u = Cu z + Du r``) runs as its recursion, compiled: period by period, the next state is
# the sum of A's columns scaled by the state's values and of B's by the inputs, all eight
# values of a column at once (``core.compiled.kernels``: one fused multiply-add per value, so the
# numbers do not depend on the processor's vector width and a lane equals the single env to
# the last bit). A lane keeps per axis the columns of ``A`` (``ac``, eight of eight values,
# zero past the state), of ``B`` (``bc``), ``Cu`` (``cu``, eight values), ``Du``, the
# plant's input column (``gu``: where a clipped command's difference enters), the torque
# factor and the command limit: 1.5 kB a lane.
#
# The block is also one linear map (``lifted_matrix``, the numpy reference of the tests):
# the recursion agrees with it to rounding (a few units in the last place of the terms'
# magnitudes; ``tests/contouring/test_exact.py``). Evaluated as that map, a block reads
# some 5 000 coefficients a lane (40 kB, out of the cache at N = 1024); the recursion's
# 2 x 50 updates of ten columns are about 3x faster for one lane and 5x at N = 1024.


def lifted_matrix(truth: ContouringParams, designs, block: int) -> np.ndarray:
    """The block update of both axes as one matrix, unclipped (numpy; the reference of
    :func:`run_block`, for tests and inspection).

    Rows per axis (X, then Y): the positions after each of the ``block`` periods, the
    velocities at the ``block + 1`` instants, the ``block`` commands, the closed-loop state
    at the block's end; columns: ``[z_x, z_y, r_x, TL_x, r_y, TL_y]``.
    """
    nb = block
    blocks = []
    slices = []
    offset = 0
    for axis, design in zip(AXES, designs, strict=True):
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
        cu_row = cu[0]
        u_free = np.einsum("k,jkl->jl", cu_row, free[:-1])
        u_forced = np.einsum("k,jkim->jim", cu_row, forced[:-1])
        u_forced[np.arange(nb), np.arange(nb), :] += du[0]
        rows_free = np.concatenate([free[1:, 0, :], free[:, 1, :], u_free, free[-1]])
        rows_forced = np.concatenate([forced[1:, 0], forced[:, 1], u_forced, forced[-1]])
        blocks.append((rows_free, rows_forced[:, :, 0], rows_forced[:, :, 1]))
        slices.append(slice(offset, offset + n))
        offset += n
    n_rows = [rf.shape[0] for rf, *_ in blocks]
    big = np.zeros((sum(n_rows), offset + 4 * nb))
    r0 = 0
    for k, (rf, rr, rl) in enumerate(blocks):
        big[r0 : r0 + rf.shape[0], slices[k]] = rf
        c0 = offset + 2 * nb * k
        big[r0 : r0 + rf.shape[0], c0 : c0 + nb] = rr
        big[r0 : r0 + rf.shape[0], c0 + nb : c0 + 2 * nb] = rl
        r0 += rf.shape[0]
    return big


@numba.njit(cache=True)
def _close_axis(phi, gam, da, db, dc, dd, ac, bc, cu):
    """Closed loop of one axis (``closed_loop``'s arithmetic) into ``ac`` (column ``q`` of
    ``A`` in ``ac[q]``), ``bc`` (the set point's and the load's columns of ``B``) and ``cu``
    (``Cu``), zero past the state; returns ``Du``'s set-point entry."""
    nk = da.shape[0]
    dr = dd[0, 0]
    dy = dd[0, 1]
    ac[:, :] = 0.0
    bc[:, :] = 0.0
    cu[:] = 0.0
    for i in range(2):
        gy = gam[i, 0] * dy
        ac[0, i] = phi[i, 0] + gy * 1.0
        ac[1, i] = phi[i, 1] + gy * 0.0
        for j in range(nk):
            ac[2 + j, i] = gam[i, 0] * dc[0, j]
        bc[0, i] = gam[i, 0] * dr
        bc[1, i] = gam[i, 1]
    for i in range(nk):
        ac[0, 2 + i] = db[i, 1] * 1.0
        ac[1, 2 + i] = db[i, 1] * 0.0
        for j in range(nk):
            ac[2 + j, 2 + i] = da[i, j]
        bc[0, 2 + i] = db[i, 0]
    cu[0] = dy * 1.0
    cu[1] = dy * 0.0
    for j in range(nk):
        cu[2 + j] = dc[0, j]
    return dr


@numba.njit(cache=True, inline="always")
def _next_state(a, b, z, r, load):
    """``A z + B [r, load]`` (``a``: A's columns, ``b``: B's, ``z``: eight values), in four
    chains of fused multiply-adds (columns 0-1 and the inputs, 2-3, 4-5, 6-7), summed as
    ``(c0 + c1) + (c2 + c3)``."""
    c0 = add_scaled8(zero8(), a[0], a[1], 0, get8(z, 0), get8(z, 1))
    c1 = add_scaled8(zero8(), a[2], a[3], 0, get8(z, 2), get8(z, 3))
    c2 = add_scaled8(zero8(), a[4], a[5], 0, get8(z, 4), get8(z, 5))
    c3 = add_scaled8(zero8(), a[6], a[7], 0, get8(z, 6), get8(z, 7))
    c0 = add_scaled8(c0, b[0], b[1], 0, r, load)
    return add8(add8(c0, c1), add8(c2, c3))


@numba.njit(cache=True, inline="always")
def _command(c, du, z, r):
    """``Cu z + Du r`` (``c``: Cu's eight values)."""
    s0 = fma(c[0], get8(z, 0), c[4] * get8(z, 4))
    s1 = fma(c[1], get8(z, 1), c[5] * get8(z, 5))
    s2 = fma(c[2], get8(z, 2), c[6] * get8(z, 6))
    s3 = fma(c[3], get8(z, 3), c[7] * get8(z, 7))
    return ((s0 + s1) + (s2 + s3)) + du * r


@numba.njit(cache=True, inline="always")
def _axis_period(a, b, c, du, gu, umax, z, r, load, zb, o):
    """One servo period of one axis from the state ``z``: ``(next state, command applied,
    whether it was clipped)``. A command past ``umax`` is clipped; the controller, which
    does not know of the clip, carries on unchanged, and the plant's states (the first
    two) get the difference through its input column ``gu`` (``zb[o : o + 8]``: scratch)."""
    u = _command(c, du, z, r)
    zn = _next_state(a, b, z, r, load)
    if not (u > umax or u < -umax):  # within the limit, or NaN (the state is NaN then too)
        return zn, u, False
    uc = umax if u > umax else -umax
    store8(zb, o, zn)
    zb[o] += gu[0] * (uc - u)
    zb[o + 1] += gu[1] * (uc - u)
    return load8(zb, o), uc, True


class ServoBlock(NamedTuple):
    """The arrays of one block of servo periods of both axes (:func:`run_block`): what it
    reads, the set points ``ref`` and load torques ``load`` (``(nb, 2)``), and what it
    writes, the positions ``pos``, velocities ``vel`` (``nb + 1`` rows: the start, then
    after each period), commands ``cmd`` and motor torques ``torque``."""

    ref: np.ndarray
    load: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    cmd: np.ndarray
    torque: np.ndarray


@numba.njit(cache=True, _nrt=False)
def run_block(loop, state, block, zb):
    """Advance both axes of one loop by one block (``ServoLoop.run``; see there).

    ``loop`` = ``(ac, bc, cu, du, gu, tq, umax)``: the lane's per-axis arrays (leading
    dimension 2; see :func:`lane_loops`) and its command limit (a number); ``state`` holds
    both axes' closed-loop states (``n`` values each, ``n <= 8``); ``block`` is a
    :class:`ServoBlock`; ``zb`` is scratch of 16 values. Writes the block's positions,
    velocities, commands and torques; updates ``state``; returns whether a command clipped.
    """
    ac, bc, cu, du, gu, tq, umax = loop
    ref, load, pos, vel, cmd, torque = block
    nb = ref.shape[0]
    n = state.shape[0] // 2
    zb[:] = 0.0
    for k in range(2):
        for q in range(n):
            zb[8 * k + q] = state[k * n + q]
        vel[0, k] = zb[8 * k + 1]
    zx = load8(zb, 0)
    zy = load8(zb, 8)
    ax, ay, bx, by, cx, cy, gx, gy = ac[0], ac[1], bc[0], bc[1], cu[0], cu[1], gu[0], gu[1]
    clipped = False
    for j in range(nb):
        # The two axes side by side: their chains overlap in the processor.
        zx, ux, kx = _axis_period(ax, bx, cx, du[0], gx, umax, zx, ref[j, 0], load[j, 0], zb, 0)
        zy, uy, ky = _axis_period(ay, by, cy, du[1], gy, umax, zy, ref[j, 1], load[j, 1], zb, 8)
        clipped = clipped or kx or ky
        cmd[j, 0] = ux
        cmd[j, 1] = uy
        pos[j, 0] = get8(zx, 0)
        pos[j, 1] = get8(zy, 0)
        vel[j + 1, 0] = get8(zx, 1)
        vel[j + 1, 1] = get8(zy, 1)
    store8(zb, 0, zx)
    store8(zb, 8, zy)
    for k in range(2):
        for q in range(n):
            state[k * n + q] = zb[8 * k + q]
        for j in range(nb):
            torque[j, k] = (vel[j + 1, k] - vel[j, k]) * tq[k] + load[j, k]
    return clipped


# ---- eight lanes at once ----------------------------------------------------------------
#
# run_block advances one lane: each period waits on the last one's state, and the eight
# values of a state vector have to be taken apart to scale the columns (the processor's
# shuffle unit, not its arithmetic, sets the pace). A batch of lanes runs faster side by
# side: ``run_lanes`` holds value q of the state of eight lanes in one vector (``LANES``),
# and so scales, for every row i, the eight lanes' own coefficients A[i, q] at once, with
# no shuffle and eight independent chains. Each lane gets run_block's operations in
# run_block's order (the same four chains of fused multiply-adds per row, summed as
# ``(c0 + c1) + (c2 + c3)``; the command; the clip), so the same numbers to the last bit.
#
# It skips what run_block computes past an axis's ``ns`` states, which is exact zeros
# there: the rows past the state have zero coefficients and stay +0, and every sum in a
# row starts from a fused multiply-add onto +0, so it is never -0, and adding a +0 to it
# changes nothing. (Only a state already infinite or NaN, which the env takes for a
# divergence, could spread its NaN differently: run_block's zero rows turn NaN too.)
#
# Lanes 8 g .. 8 g + 7 form group g. When a lane starts, its coefficients are copied from
# its row of ``ServoLanes.buf`` into its group's table (``ServoLanes.groups``, by
# ``gather_loops``), with the eight lanes side by side, per axis: A's entries, column q
# row i at ``(8 q + i) * 8``; B's (set point, then load) at ``_L_B + (8 m + i) * 8``;
# Cu's at ``_L_C + 8 q``; Du, the plant's input column (two), the torque factor and the
# command limit after them, each eight values, one per lane. A step copies only the
# states (``gather_states``, ``scatter_lanes``): the coefficients stay put for the
# episode. A group of fewer than eight lanes has zeros in the others' places, a zero
# state and zero inputs: they stay zero.

#: Lanes side by side in :func:`run_lanes`.
LANES = 8
_L_B = 512
_L_C = _L_B + 128
_L_DU = _L_C + 64
_L_GU = _L_DU + 8
_L_TQ = _L_GU + 16
_L_UMAX = _L_TQ + 8
_L_AXIS = _L_UMAX + 8
#: Values of the table of coefficients of eight lanes (both axes) that :func:`run_lanes`
#: reads (a row of ``ServoLanes.groups``).
GROUP_SIZE = 2 * _L_AXIS
#: Values of the states of eight lanes (both axes, eight values each) that
#: :func:`run_lanes` reads and updates.
LANES_STATE_SIZE = 2 * 64


@numba.njit(cache=True, _nrt=False)
def gather_loops(loops, lanes, groups):
    """The coefficients of each lane ``lanes[i]`` (its row of ``ServoLanes.buf``, laid
    out as :func:`lane_loops` reads them) into its place ``lanes[i] % LANES`` of its group's
    table ``groups[lanes[i] // LANES]``, laid out as :func:`run_lanes` reads them
    (``ServoLanes.groups``). A place without a lane keeps the zeros it was made with: a
    zero loop, which stays at rest."""
    for i in range(lanes.size):
        lane = lanes[i]
        row = loops[lane]
        table = groups[lane // LANES]
        p = lane % LANES
        for ax in range(2):
            o = ax * _L_AXIS
            for q in range(8):
                for r in range(8):
                    table[o + (8 * q + r) * 8 + p] = row[_O_AC + (8 * ax + q) * 8 + r]
            for m in range(2):
                for r in range(8):
                    table[o + _L_B + (8 * m + r) * 8 + p] = row[_O_BC + (2 * ax + m) * 8 + r]
                table[o + _L_GU + 8 * m + p] = row[_O_GU + 2 * ax + m]
            for q in range(8):
                table[o + _L_C + 8 * q + p] = row[_O_CU + 8 * ax + q]
            table[o + _L_DU + p] = row[_O_DU + ax]
            table[o + _L_TQ + p] = row[_O_TQ + ax]
            table[o + _L_UMAX + p] = row[_O_UMAX]


@numba.njit(cache=True, _nrt=False)
def gather_states(state, k0, w, z):
    """The states of ``w <= LANES`` lanes (``state[k0 : k0 + w]``, both axes) into ``z``
    for :func:`run_lanes`: lane ``k0 + p`` in place ``p``; the places from ``w`` on get
    zeros (at rest, whatever the scratch held)."""
    ns = state.shape[1] // 2
    for ax in range(2):
        for q in range(8):
            for p in range(LANES):
                lane = p < w and q < ns
                z[ax * 64 + 8 * q + p] = state[k0 + p, ax * ns + q] if lane else 0.0


@numba.njit(cache=True, _nrt=False)
def scatter_lanes(state, k0, w, z):
    """The states :func:`run_lanes` left in ``z`` back into ``state[k0 : k0 + w]``."""
    ns = state.shape[1] // 2
    for p in range(w):
        for ax in range(2):
            for q in range(ns):
                state[k0 + p, ax * ns + q] = z[ax * 64 + 8 * q + p]


@numba.njit(cache=True, inline="always")
def _lanes_row(table, o, i, ns, z0, z1, z2, z3, z4, z5, z6, z7, r, ld):
    """Row ``i`` of the next states of eight lanes: :func:`_next_state`'s four chains,
    without the columns past the ``ns`` states (which add exact zeros there)."""
    a = o + i * 8
    b = o + _L_B + i * 8
    c0 = fma8(load8(table, a + 64), z1, fma8(load8(table, a), z0, zero8()))
    c0 = fma8(load8(table, b + 64), ld, fma8(load8(table, b), r, c0))
    # The other three pairs of columns written out: a helper inlined for each (numba's
    # inlining, 24 a version) made the three versions take about five times as long to
    # compile.
    if ns > 3:
        c1 = fma8(load8(table, a + 192), z3, fma8(load8(table, a + 128), z2, zero8()))
    elif ns > 2:
        c1 = fma8(load8(table, a + 128), z2, zero8())
    else:
        c1 = zero8()
    if ns > 5:
        c2 = fma8(load8(table, a + 320), z5, fma8(load8(table, a + 256), z4, zero8()))
    elif ns > 4:
        c2 = fma8(load8(table, a + 256), z4, zero8())
    else:
        c2 = zero8()
    if ns > 7:
        c3 = fma8(load8(table, a + 448), z7, fma8(load8(table, a + 384), z6, zero8()))
    elif ns > 6:
        c3 = fma8(load8(table, a + 384), z6, zero8())
    else:
        c3 = zero8()
    return add8(add8(c0, c1), add8(c2, c3))


def _lanes_kernel(ns: int):
    """:func:`run_lanes` for ``ns`` states per axis, compiled with ``ns`` a constant (its
    rows unrolled, the columns past the state left out; about twice as fast as one
    compiled for any ``ns``)."""

    @numba.njit(cache=True, _nrt=False)
    def run(table, nb, z, ref, load, pos, vel, cmd, torque):
        for ax in range(2):
            o = ax * _L_AXIS
            zo = ax * 64
            z0, z1, z2, z3 = load8(z, zo), load8(z, zo + 8), load8(z, zo + 16), load8(z, zo + 24)
            z4, z5 = load8(z, zo + 32), load8(z, zo + 40)
            z6, z7 = load8(z, zo + 48), load8(z, zo + 56)
            store8(vel, ax * 8, z1)
            c = o + _L_C
            for j in range(nb):
                io = j * 16 + ax * 8
                r = load8(ref, io)
                ld = load8(load, io)
                s0 = fma8(load8(table, c), z0, mul8(load8(table, c + 32), z4))
                s1 = fma8(load8(table, c + 8), z1, mul8(load8(table, c + 40), z5))
                s2 = fma8(load8(table, c + 16), z2, mul8(load8(table, c + 48), z6))
                s3 = fma8(load8(table, c + 24), z3, mul8(load8(table, c + 56), z7))
                u = add8(add8(add8(s0, s1), add8(s2, s3)), mul8(load8(table, o + _L_DU), r))
                n0 = _lanes_row(table, o, 0, ns, z0, z1, z2, z3, z4, z5, z6, z7, r, ld)
                n1 = _lanes_row(table, o, 1, ns, z0, z1, z2, z3, z4, z5, z6, z7, r, ld)
                n2 = z2
                n3 = z3
                n4 = z4
                n5 = z5
                n6 = z6
                n7 = z7
                if ns > 2:
                    n2 = _lanes_row(table, o, 2, ns, z0, z1, z2, z3, z4, z5, z6, z7, r, ld)
                if ns > 3:
                    n3 = _lanes_row(table, o, 3, ns, z0, z1, z2, z3, z4, z5, z6, z7, r, ld)
                if ns > 4:
                    n4 = _lanes_row(table, o, 4, ns, z0, z1, z2, z3, z4, z5, z6, z7, r, ld)
                if ns > 5:
                    n5 = _lanes_row(table, o, 5, ns, z0, z1, z2, z3, z4, z5, z6, z7, r, ld)
                if ns > 6:
                    n6 = _lanes_row(table, o, 6, ns, z0, z1, z2, z3, z4, z5, z6, z7, r, ld)
                if ns > 7:
                    n7 = _lanes_row(table, o, 7, ns, z0, z1, z2, z3, z4, z5, z6, z7, r, ld)
                ua = clip8(u, load8(table, o + _L_UMAX))
                n0 = shift8(n0, load8(table, o + _L_GU), u, ua)
                n1 = shift8(n1, load8(table, o + _L_GU + 8), u, ua)
                store8(cmd, io, ua)
                store8(pos, io, n0)
                store8(vel, io + 16, n1)
                store8(torque, io, add8(mul8(sub8(n1, z1), load8(table, o + _L_TQ)), ld))
                z0, z1, z2, z3, z4, z5, z6, z7 = n0, n1, n2, n3, n4, n5, n6, n7
            store8(z, zo, z0)
            store8(z, zo + 8, z1)
            store8(z, zo + 16, z2)
            store8(z, zo + 24, z3)
            store8(z, zo + 32, z4)
            store8(z, zo + 40, z5)
            store8(z, zo + 48, z6)
            store8(z, zo + 56, z7)

    return run


_lanes_3 = _lanes_kernel(3)  # the PI design's states
_lanes_6 = _lanes_kernel(6)  # the H-infinity design's
_lanes_8 = _lanes_kernel(8)  # any other (the rows past the state are zero)


@numba.njit(cache=True, _nrt=False)
def run_lanes(table, ns, nb, z, ref, load, pos, vel, cmd, torque):
    """:func:`run_block` for eight lanes at once (see above): their coefficients and
    states in ``table`` (a row of ``ServoLanes.groups``) and ``z`` (from
    :func:`gather_states`; updated), ``ns`` states per
    axis; ``ref``, ``load``, ``pos``, ``cmd``, ``torque`` hold ``nb`` rows and ``vel``
    ``nb + 1``, each row both axes' eight lanes (``[row, axis, lane]``, 16 values a row)."""
    if ns == 6:
        _lanes_6(table, nb, z, ref, load, pos, vel, cmd, torque)
    elif ns == 3:
        _lanes_3(table, nb, z, ref, load, pos, vel, cmd, torque)
    else:
        _lanes_8(table, nb, z, ref, load, pos, vel, cmd, torque)


#: The arrays of a lane's loops (:class:`ServoLanes`), in their order in its row, and
#: their shapes.
_LANE_ARRAYS = (
    ("ac", (2, 8, 8)),
    ("bc", (2, 2, 8)),
    ("cu", (2, 8)),
    ("du", (2,)),
    ("gu", (2, 2)),
    ("tq", (2,)),
    ("umax", (1,)),
)
#: Where each array starts in a lane's row, and where the last ends.
_OFFSETS = tuple(
    sum(math.prod(shape) for _, shape in _LANE_ARRAYS[:i]) for i in range(len(_LANE_ARRAYS) + 1)
)
#: Values in a lane's row of ``ServoLanes.buf``: its arrays, then up to seven unused, so
#: that every row starts 64 bytes after the last (192).
ROW_SIZE = _OFFSETS[-1] + (-_OFFSETS[-1]) % 8
#: Scratch values :func:`run_block` needs.
SCRATCH_SIZE = 16
# The table as the compiled code's constants (numba freezes module globals).
_O_AC, _O_BC, _O_CU, _O_DU, _O_GU, _O_TQ, _O_UMAX, _O_END = _OFFSETS
_S_AC, _S_BC, _S_CU, _S_GU = (dict(_LANE_ARRAYS)[k] for k in ("ac", "bc", "cu", "gu"))


@numba.njit(cache=True)
def _close_lanes(lanes, e, designs, buf):
    """:func:`_close_axis` of both axes of each lane ``lanes[i]`` on the exponentials
    ``e[i, axis]`` (``plant.axes_zoh``: ``Phi`` then ``Gamma``) with the axis's design
    ``designs[axis]`` (``ServoLanes._design_arrays``), into its row of ``buf``
    (``ServoLanes.buf``: ``Du``'s entry and ``Gamma``'s first column too)."""
    for i in range(lanes.size):
        ac, bc, cu, du, gu, _, _ = lane_loops(buf[lanes[i]])
        for k in range(2):
            phi = e[i, k, :2, :2]
            gam = e[i, k, :2, 2:]
            da, db, dc, dd = designs[k]
            du[k] = _close_axis(phi, gam, da, db, dc, dd, ac[k], bc[k], cu[k])
            gu[k, 0] = gam[0, 0]
            gu[k, 1] = gam[1, 0]


@numba.njit(cache=True, inline="always")
def _one_or_each(x, i):
    """``x[i]``, or ``x[0]`` where ``x`` holds one value for all."""
    return x[i] if x.size > 1 else x[0]


@numba.njit(cache=True)
def _start_loops(lanes, gain, mm_per_rad, dt, inertia, umax, designs, buf, groups):
    """:meth:`ServoLanes._start_arrays`: the plants' poles ``gain / J`` and load gains
    ``-mm_per_rad / J`` (``ContouringParams.velocity_pole``, ``discrete_axis``'s load), both
    axes of every lane discretised (``plant.axes_zoh_into``), their loops closed
    (:func:`_close_lanes`), the torque factors ``J / (mm_per_rad dt)`` and command limits
    set, and the lanes' places in their groups written (:func:`gather_loops`). ``gain``,
    ``mm_per_rad``, ``dt`` and ``umax`` hold one value per lane or one for all."""
    n = lanes.size
    a = np.empty(2 * n)
    g = np.empty(2 * n)
    h = np.empty(2 * n)
    for i in range(n):
        for j in range(2):
            a[2 * i + j] = _one_or_each(gain, i) / inertia[i, j]
            g[2 * i + j] = -_one_or_each(mm_per_rad, i) / inertia[i, j]
            h[2 * i + j] = _one_or_each(dt, i)
    e = np.zeros((2 * n, 4, 4))
    axes_zoh_into(a, g, h, e)
    _close_lanes(lanes, e.reshape((n, 2, 4, 4)), designs, buf)
    for i in range(n):
        _, _, _, _, _, tq, um = lane_loops(buf[lanes[i]])
        scale = _one_or_each(mm_per_rad, i) * _one_or_each(dt, i)
        tq[0] = inertia[i, 0] / scale
        tq[1] = inertia[i, 1] / scale
        um[0] = _one_or_each(umax, i)
    gather_loops(buf, lanes, groups)


#: The nominal plant's numbers :func:`start_scaled_loops` reads, in this order: its loop
#: gain, screw lead (mm/rad), sample time, X and Y inertias and command limit.
NOMINAL_LOOP_NUMBERS = (
    "loop_gain_Nms",
    "mm_per_rad",
    "sample_time_s",
    "inertia_x_kgm2",
    "inertia_y_kgm2",
    "command_max_mm_s",
)


@numba.njit(cache=True)
def start_scaled_loops(lanes, nominal, scale, designs, buf, groups):
    """:meth:`ServoLanes.start_scaled`'s compiled part: the loops of each lane
    ``lanes[i]`` on the nominal plant (``nominal``: ``NOMINAL_LOOP_NUMBERS``) with its
    inertias (X, Y) scaled by ``scale[i]``, by :func:`_start_loops`."""
    m = lanes.size
    inertia = np.empty((m, 2))
    for i in range(m):
        inertia[i, 0] = nominal[3] * scale[i, 0]
        inertia[i, 1] = nominal[4] * scale[i, 1]
    _start_loops(
        lanes, nominal[0:1], nominal[1:2], nominal[2:3], inertia, nominal[5:6], designs, buf, groups
    )


@numba.njit(cache=True, inline="always")
def lane_loops(row):
    """A lane's loops as views of its row of ``ServoLanes.buf`` (``_LANE_ARRAYS``):
    ``(ac, bc, cu, du, gu, tq, umax)`` as :func:`run_block` takes them, except ``umax``, an
    array of one value."""
    return (
        row[_O_AC:_O_BC].reshape(_S_AC),
        row[_O_BC:_O_CU].reshape(_S_BC),
        row[_O_CU:_O_DU].reshape(_S_CU),
        row[_O_DU:_O_GU],
        row[_O_GU:_O_TQ].reshape(_S_GU),
        row[_O_TQ:_O_UMAX],
        row[_O_UMAX:_O_END],
    )


def _aligned_zeros(shape: tuple[int, int]) -> np.ndarray:
    """A float array of zeros whose first value lies on a 64-byte boundary: with rows of a
    multiple of eight values, every row's vectors of eight lie within one cache line each
    (a vector across two costs about twice as much to load). A copy (a pickled env's) may
    lie anywhere: the same numbers, a little slower."""
    size = shape[0] * shape[1]
    raw = np.zeros(size + 7)
    skip = (-(raw.ctypes.data // 8)) % 8
    return raw[skip : skip + size].reshape(shape)


class ServoLanes:
    """The closed loops of N lanes (each a pair of designs on its own true plant), in the
    arrays :func:`run_block` reads.

    Parameters
    ----------
    designs : (ServoDesign, ServoDesign)
        The X and Y controllers (designed from the nominal plant; the same in every lane).
    block : int
        Servo periods per block.
    n : int
        Number of lanes.
    """

    def __init__(self, designs, block: int, n: int = 1) -> None:
        check_integer("block", block, 1, 10000, types=(int,))
        self.designs = tuple(designs)
        self.block = block
        self.n = n
        nk = self.designs[0].n_states
        if any(d.n_states != nk for d in self.designs):
            raise ValueError("the X and Y designs must have as many states")
        ns = nk + 2
        self.n_states_axis = ns
        if ns > 8:
            raise ValueError(
                f"the block update holds an axis's closed-loop state in eight values; "
                f"the designs have {nk} states (at most 6)"
            )
        #: Every lane's arrays in one row each (one argument for a compiled step); the
        #: named arrays below are views of it over all lanes, laid out by lane_loops.
        self.buf = _aligned_zeros((n, ROW_SIZE))
        #: The same coefficients, eight lanes side by side in each row (group ``g``: lanes
        #: ``8 g .. 8 g + 7``), as :func:`run_lanes` reads them (:func:`gather_loops`).
        self.groups = _aligned_zeros((-(-n // LANES), GROUP_SIZE))
        self._bind_views()
        self._design_arrays = tuple(
            tuple(np.ascontiguousarray(m) for m in (d.a, d.b, d.c, d.d)) for d in self.designs
        )

    def _bind_views(self) -> None:
        """Name the runs of :attr:`buf` over all lanes (``_LANE_ARRAYS``)."""
        for (name, shape), o, end in zip(_LANE_ARRAYS, _OFFSETS[:-1], _OFFSETS[1:], strict=True):
            view = self.buf[:, o:end].reshape((self.n, *shape))
            assert np.shares_memory(view, self.buf)
            setattr(self, name, view)
        self.umax = self.umax[:, 0]

    def __getstate__(self) -> dict:
        # A pickled view is a copy: the views are made anew from buf on loading.
        views = {name for name, _ in _LANE_ARRAYS}
        return {k: v for k, v in self.__dict__.items() if k not in views}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._bind_views()

    def start(self, lane: int, truth: ContouringParams) -> None:
        """Set ``lane``'s loops to the designs on the plant ``truth``."""
        self.start_lanes(np.array([lane]), [truth])

    def start_lanes(self, lanes: np.ndarray, truths) -> None:
        """Set each lane ``lanes[i]``'s loops to the designs on the plant ``truths[i]``:
        both axes of every lane discretised and their loops closed in one compiled call
        (:func:`_start_loops`)."""
        # ContouringParams' derived quantities, in their order of operations.
        self._start_arrays(
            lanes,
            np.array([t.loop_gain_Nms for t in truths]),
            np.array([t.mm_per_rad for t in truths]),
            np.array([t.sample_time_s for t in truths]),
            np.array([[t.inertia_kgm2(axis) for axis in AXES] for t in truths]),
            [t.command_max_mm_s for t in truths],
        )

    def start_scaled(self, lanes: np.ndarray, nominal: ContouringParams, scales) -> None:
        """:meth:`start_lanes` on the plants ``nominal`` with its inertias scaled by
        ``scales[i]`` (X, Y) in lane ``lanes[i]`` (``scenarios.true_params_of``'s plants,
        their inertias the same products), without making them (:func:`start_scaled_loops`,
        which a compiled batch start calls itself)."""
        numbers = np.array([getattr(nominal, name) for name in NOMINAL_LOOP_NUMBERS])
        start_scaled_loops(
            lanes,
            numbers,
            np.asarray(scales, dtype=np.float64),
            self._design_arrays,
            self.buf,
            self.groups,
        )

    def _start_arrays(self, lanes, gain, mm_per_rad, dt, inertia, umax) -> None:
        """The loops of ``lanes`` on plants of the loop gains ``gain``, screw leads
        ``mm_per_rad``, sample times ``dt``, inertias ``inertia`` (X, Y) and command limits
        ``umax`` (one of each per lane, or one for all but the inertias), in one compiled
        call (:func:`_start_loops`)."""
        umax = np.asarray(umax, dtype=np.float64).reshape(-1)
        _start_loops(
            lanes, gain, mm_per_rad, dt, inertia, umax, self._design_arrays, self.buf, self.groups
        )


class ServoLoop:
    """Both axes' closed loops (a design on a true plant), advanced a block at a time.

    A block of ``n`` servo periods runs as the closed loop's recursion, compiled
    (:func:`run_block`): state, positions, commands and velocities over the block follow
    from the state at its start and the block's reference and load-torque samples, linearly
    (:func:`lifted_matrix`) until a command reaches the drive's limit. There the command is
    clipped (the controller, which does not know of the clip, carries on unchanged).
    Positions are relative to the table's start.

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
        self.truth = truth
        self.lanes = ServoLanes(designs, block, 1)
        self.lanes.start(0, truth)
        self.designs = self.lanes.designs
        self.block = block
        self.n_states = 2 * self.lanes.n_states_axis
        self._zb = np.zeros(SCRATCH_SIZE)

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
        ln = self.lanes
        pos = np.empty((nb, 2))
        vel = np.empty((nb + 1, 2))
        cmd = np.empty((nb, 2))
        torque = np.empty((nb, 2))
        ref = np.ascontiguousarray(ref, dtype=np.float64)
        load = np.ascontiguousarray(load, dtype=np.float64)
        loop = (ln.ac[0], ln.bc[0], ln.cu[0], ln.du[0], ln.gu[0], ln.tq[0], float(ln.umax[0]))
        block = ServoBlock(ref, load, pos, vel, cmd, torque)
        clipped = run_block(loop, state, block, self._zb)
        return pos, vel[1:], cmd, torque, bool(clipped)
