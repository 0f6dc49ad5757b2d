"""The engine of ``ContouringFeed-v0``: the reward weights, the lane tables and the
compiled step and start of N CNC feed overrides over their position loops, which
:class:`ContouringFeedEnv` (one lane) and :class:`ContouringFeedVectorEnv` (N lanes) drive."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numba
import numpy as np
from gymnasium import spaces

from machining_envs.contouring._exact import np_mean, py_hypot
from machining_envs.contouring.lanes import (
    ERROR_SCALE_MM,
    VELOCITY_SCALE_MM_S,
    circle_info,
    positive_setting,
    run_limits,
)
from machining_envs.contouring.paths import (
    SEGMENT_COLUMNS,
    path_distances,
    path_heading,
    path_point,
    path_points,
    path_segment_index,
    row_largest,
)
from machining_envs.contouring.plant import AXES, ContouringParams
from machining_envs.contouring.scenarios import (
    _D_A,
    _D_B,
    _D_LENGTH,
    _D_T,
    _D_X0,
    _D_XE,
    _D_Y0,
    _D_YE,
    CONTOURING_SCENARIOS,
    ContouringScenario,
    _RandomPaths,
    check_feed,
    contouring_scenario,
    load_time,
)
from machining_envs.contouring.servo import (
    LANES,
    LANES_STATE_SIZE,
    NOMINAL_LOOP_NUMBERS,
    SCRATCH_SIZE,
    SERVO_KINDS,
    ServoBlock,
    ServoLanes,
    gather_states,
    lane_loops,
    run_block,
    run_lanes,
    scatter_lanes,
    servo_design,
    start_scaled_loops,
)
from machining_envs.core.actions import ActionMap
from machining_envs.core.actuation import (
    ActuationLanes,
    configure_lane,
    resolve_actuation,
)
from machining_envs.core.compiled.blocks import (
    ALIGN,
    SCRATCH,
    LaneBlocks,
    serve_one_table,
)
from machining_envs.core.compiled.kernels import clip_unit, data_address
from machining_envs.core.compiled.normals import LaneGenerators
from machining_envs.core.compiled.packed import (
    PackedArgs,
    b1_1,
    b1_2,
    f4_2,
    f8_1,
    f8_2,
    f8_3,
    i8_1,
    i8_2,
    spaced_rows,
)
from machining_envs.core.env import (
    check_scenario_spec,
    resolve_params,
)
from machining_envs.core.lanes import LaneCore, LaneNames, LaneObjects, settle_batch, split_batch
from machining_envs.core.reward import check_reward_weights, resolve_reward

#: The observation previews the path's turn over these distances ahead of the set point, mm.
LOOKAHEAD_MM = (0.5, 1.0, 2.0, 5.0, 10.0)
#: Contour-error tolerance of each servo by default, mm: a finishing tolerance each loop
#: can hold at the programmed feed on straight and gently curved parts but not everywhere
#: at twice it (see docs/contouring.md).
DEFAULT_TOLERANCE_MM = {"pi": 0.05, "hinf": 0.005}

# Upper bounds of the observation (index 4, the path speed, is set to ``override_max``).
_LIMS = [100.0, 100.0, 100.0, 100.0, 2.0, 1.0, 10.0, *[10.0] * len(LOOKAHEAD_MM)]
_LIMS += [10.0, 10.0, 10.0, 1.0]


@dataclass(frozen=True)
class FeedReward:
    r"""Weights of the ContouringFeed-v0 reward (see :class:`ContouringFeedEnv`, Rewards).

    .. math::

        r = w_p \frac{\Delta s}{L} - w_t \frac{\Delta t}{L / F}
            - w_e \frac{1}{N} \sum_{j=1}^{N} \max\!\left(0, \frac{\varepsilon_j}{\varepsilon_{tol}} - 1\right)
            - w_d [\text{diverged}]

    over the step's ``N`` servo periods: progress along the path of length ``L``, the time
    spent as a share of the programmed cycle time ``L / F``, and the contour error beyond the
    tolerance. At the programmed feed without error the first two cancel over a run; a
    faster run without error earns the time it saves.
    """

    progress: float = 1.0
    """w_p, weight of the share of the path covered in the step."""
    time: float = 1.0
    """w_t, weight of the time spent, per programmed cycle time."""
    tolerance: float = 1.0
    """w_e, weight of the relative excess of the contour error over the tolerance."""
    divergence: float = 10.0
    """w_d, one-off penalty when the run diverges."""

    def __post_init__(self) -> None:
        check_reward_weights(self)


# ---- the compiled step of every lane ------------------------------------------------------
# Each lane table's columns are declared once by name (an IntEnum: its members are
# constants to the compiler, ``lf[k, _LF.s]``); the kernels take the tables as one record
# (:class:`_Feed`).

#: Columns of ``FeedCore.lf``: per-lane floats, then the path's and run's constants (from
#: ``length`` on, also named ``FeedCore.pf``).
_LF = IntEnum(
    "_LF",
    "in_action applied s override prev_action reward"
    " length x0 y0 x_end y_end feed programmed_time time_limit",
    start=0,
)
#: Columns of ``FeedCore.li`` (per-lane integers; ``lane``: each lane's index, which a
#: block of lanes reads for its first).
_LI = IntEnum("_LI", "in_clipped nseg n_load k n_clipped segment lane", start=0)
#: Columns of ``FeedCore.out`` (the step's signals, read into ``info``).
_Out = IntEnum(
    "_Out",
    "t_s command_x_mm_s command_y_mm_s x_mm y_mm x_ref_mm y_ref_mm contour_error_mm"
    " peak_contour_error_mm tracking_error_mm vx_mm_s vy_mm_s torque_x_Nm torque_y_Nm"
    " torque_sq_Nm2 load_x_Nm load_y_Nm feed_override path_speed_mm_s path_s_mm"
    " machining_time_s",
    start=0,
)
#: Columns of ``FeedCore.flags``.
_Flag = IntEnum("_Flag", "diverged finished terminated truncated", start=0)
_N_OBS = len(_LIMS)
_N_LOOK = len(LOOKAHEAD_MM)


class _C(IntEnum):
    """Entries of ``FeedCore.consts``: the servo periods of a step, their period, the
    contour tolerance, the in-position and divergence distances, the override's middle and
    half range, whether the CNC's actuation makes the override (``applied``); then where
    the reward weights, the lookahead distances and the observation's lower and upper
    bounds start."""

    N_SUB = 0
    TS = 1
    TOL = 2
    IN_POSITION = 3
    DIVERGENCE = 4
    MID = 5
    HALF = 6
    ACTUATED = 7
    W = 8
    LOOK = W + 4
    LO = LOOK + _N_LOOK
    HI = LO + _N_OBS


class _Feed(NamedTuple):
    """The lane tables of the step (views of the kernel's table; a block's rows)."""

    lf: np.ndarray
    li: np.ndarray
    tabs: np.ndarray
    load_t: np.ndarray
    load_v: np.ndarray
    state: np.ndarray
    consts: np.ndarray
    obs: np.ndarray
    flags: np.ndarray
    out: np.ndarray


@numba.njit(cache=True, _nrt=False, error_model="numpy")
def _feed_obs(k, tab, f, sig):
    """Observation of lane ``k`` (``ContouringFeedEnv``'s table) into ``f.obs[k]``, from
    its path's table ``tab`` and the signals ``sig`` = ``(contour error, peak contour
    error, x and y errors at the set point, vx, vy)``. It allocates nothing, so it keeps no
    reference counts (``_nrt=False``: its views of the lane's rows cost none), and divides
    as numpy does (``error_model="numpy"``: no test of each divisor, a path's length, the
    tolerance, pi, all positive)."""
    eps, peak, ex, ey, vx, vy = sig
    lf = f.lf
    c = f.consts
    tol = c[_C.TOL]
    length = lf[k, _LF.length]
    sk = lf[k, _LF.s]
    o = f.obs[k]
    _bound(o, 0, eps / tol, c)
    _bound(o, 1, peak / tol, c)
    _bound(o, 2, ex / ERROR_SCALE_MM, c)
    _bound(o, 3, ey / ERROR_SCALE_MM, c)
    _bound(o, 4, lf[k, _LF.override] if sk < length else 0.0, c)
    _bound(o, 5, sk / length, c)
    _bound(o, 6, (length - sk) / 100.0, c)
    h0 = path_heading(tab, length, sk)
    for i in range(_N_LOOK):
        turn = (path_heading(tab, length, sk + c[_C.LOOK + i]) - h0) / math.pi
        _bound(o, 7 + i, turn, c)
    _bound(o, 12, lf[k, _LF.feed] / 100.0, c)
    _bound(o, 13, vx / VELOCITY_SCALE_MM_S, c)
    _bound(o, 14, vy / VELOCITY_SCALE_MM_S, c)
    _bound(o, 15, lf[k, _LF.prev_action], c)


@numba.njit(cache=True, inline="always")
def _bound(o, i, x, c):
    """``o[i]`` = ``x`` held within the observation's bounds ``i`` (``c``: the consts)."""
    lo = c[_C.LO + i]
    hi = c[_C.HI + i]
    o[i] = lo if x < lo else (hi if x > hi else x)


def _scratch_size(nb: int, n_seg: int, lanes: bool) -> int:
    """Values of ``_feed_step``'s float scratch (see :func:`_carve`), with room for
    :func:`_carve_lanes`'s where ``lanes`` (a core of more than one lane)."""
    return _carve_size(nb, n_seg) + (_lanes_size(nb) if lanes else 0)


@numba.njit(cache=True, inline="always")
def _carve_size(nb, n_seg):
    """Values of :func:`_carve`'s views, where :func:`_carve_lanes`'s start."""
    return (nb + 1) + 6 * nb + 4 * nb + (8 * nb + 2) + SCRATCH_SIZE + n_seg + 3 * nb


def _lanes_size(nb: int) -> int:
    """Values of :func:`_carve_lanes`'s scratch (and seven to align it)."""
    return LANES * (3 * nb + 1) + LANES_STATE_SIZE + LANES + 2 * LANES * (6 * nb + 1) + 7


@numba.njit(cache=True, inline="always")
def _carve(sc, nb, n_seg):
    """The scratch arrays of ``_feed_step`` as views of one float array (one argument to
    pass instead of sixteen): the set point's path positions (nb + 1), reference and table
    x, y, contour errors, a spare run (nb each), references and loads (nb, 2), positions
    (nb, 2), velocities (nb + 1, 2), commands and torques (nb, 2), ``run_block``'s scratch,
    the distances' lower bounds per segment, ``path_points``' scratch (3 nb)."""
    o = nb + 1
    st = sc[:o]
    rx = sc[o : o + nb]
    ry = sc[o + nb : o + 2 * nb]
    px = sc[o + 2 * nb : o + 3 * nb]
    py = sc[o + 3 * nb : o + 4 * nb]
    eps = sc[o + 4 * nb : o + 5 * nb]
    tmp = sc[o + 5 * nb : o + 6 * nb]
    o += 6 * nb
    ref = sc[o : o + 2 * nb].reshape((nb, 2))
    load = sc[o + 2 * nb : o + 4 * nb].reshape((nb, 2))
    o += 4 * nb
    pos = sc[o : o + 2 * nb].reshape((nb, 2))
    vel = sc[o + 2 * nb : o + 4 * nb + 2].reshape((nb + 1, 2))
    cmd = sc[o + 4 * nb + 2 : o + 6 * nb + 2].reshape((nb, 2))
    torque = sc[o + 6 * nb + 2 : o + 8 * nb + 2].reshape((nb, 2))
    o += 8 * nb + 2
    zb = sc[o : o + SCRATCH_SIZE]
    lower = sc[o + SCRATCH_SIZE : o + SCRATCH_SIZE + n_seg]
    o += SCRATCH_SIZE + n_seg
    pts = sc[o : o + 3 * nb]
    assert pts.size == 3 * nb  # the buffer has room for every view
    return st, rx, ry, px, py, eps, tmp, ref, load, pos, vel, cmd, torque, zb, lower, pts


@numba.njit(cache=True, inline="always")
def _carve_lanes(sc, nb, n_seg):
    """The scratch of ``_feed_step``'s lanes taken ``LANES`` at a time, after
    :func:`_carve`'s: each place's set-point path positions ``(LANES, nb + 1)`` and
    reference x and y ``(LANES, nb)``; ``run_lanes``' states; a value per place; the
    references, loads, positions, commands, torques (``nb`` rows) and velocities (``nb +
    1``), each row both axes' places (``[row, axis, place]``). Each starts on a 64-byte
    boundary: ``run_lanes`` reads them eight values at a time, and a vector across two
    cache lines made it half as fast again."""
    o = _carve_size(nb, n_seg)
    o += (-(data_address(sc) // 8 + o)) % 8  # every run from a 64-byte boundary (a vector)
    m = LANES * (nb + 1)
    st = sc[o : o + m].reshape((LANES, nb + 1))
    rx = sc[o + m : o + m + LANES * nb].reshape((LANES, nb))
    ry = sc[o + m + LANES * nb : o + m + 2 * LANES * nb].reshape((LANES, nb))
    o += m + 2 * LANES * nb
    z = sc[o : o + LANES_STATE_SIZE]
    nan = sc[o + LANES_STATE_SIZE : o + LANES_STATE_SIZE + LANES]
    o += LANES_STATE_SIZE + LANES
    row = 2 * LANES
    ref = sc[o : o + row * nb]
    load = sc[o + row * nb : o + 2 * row * nb]
    pos = sc[o + 2 * row * nb : o + 3 * row * nb]
    cmd = sc[o + 3 * row * nb : o + 4 * row * nb]
    torque = sc[o + 4 * row * nb : o + 5 * row * nb]
    vel = sc[o + 5 * row * nb : o + 6 * row * nb + row]
    assert vel.size == row * (nb + 1)  # the buffer has room for every view
    return st, rx, ry, z, nan, ref, load, pos, cmd, torque, vel


@numba.njit(cache=True, inline="always")
def _override(k, f):
    """Lane ``k``'s feed override this step: what the CNC's actuation made of its action
    where ``ACTUATED`` is set, else the action's own."""
    c = f.consts
    if c[_C.ACTUATED] != 0.0:
        return f.lf[k, _LF.applied]
    return c[_C.MID] + c[_C.HALF] * f.lf[k, _LF.in_action]


@numba.njit(cache=True, inline="always")
def _lane_inputs(k, f, path, ref, load, pts):
    """The first part of lane ``k``'s step (:func:`_feed_step`): the set point's path
    positions ``st`` over the block and its points ``rx``, ``ry`` (``path`` = ``(st, rx,
    ry)``), the references ``ref`` and load torques ``load`` of the servo periods."""
    st, rx, ry = path
    lf, li, load_t, load_v = f.lf, f.li, f.load_t, f.load_v
    n = int(f.consts[_C.N_SUB])
    ts = f.consts[_C.TS]
    tab = f.tabs[k, : li[k, _LI.nseg]]
    length = lf[k, _LF.length]
    x0 = lf[k, _LF.x0]
    y0 = lf[k, _LF.y0]
    li[k, _LI.n_clipped] += li[k, _LI.in_clipped]
    ov = _override(k, f)
    v = lf[k, _LF.feed] * ov
    vts = v * ts
    s0 = lf[k, _LF.s]
    for j in range(n + 1):
        st[j] = min(s0 + vts * float(j), length)
    path_points(tab, length, st, n, rx, ry, pts)
    for j in range(n):
        ref[j, 0] = rx[j] - x0
        ref[j, 1] = ry[j] - y0
    # The load torque of each period: the last step of the lane's load at or before its
    # instant. The instants rise, so each search goes on from the last one's step, and a
    # block whose last instant comes before the next step holds the first period's load.
    nl = li[k, _LI.n_load]
    k0 = li[k, _LI.k]
    i = 0
    t = float(k0) * ts + 1e-12
    while i < nl and load_t[k, i] <= t:
        i += 1
    if i == nl or float(k0 + n - 1) * ts + 1e-12 < load_t[k, i]:
        v0 = load_v[k, i, 0]
        v1 = load_v[k, i, 1]
        for j in range(n):
            load[j, 0] = v0
            load[j, 1] = v1
    else:
        for j in range(n):
            t = float(k0 + j) * ts + 1e-12
            while i < nl and load_t[k, i] <= t:
                i += 1
            load[j, 0] = load_v[k, i, 0]
            load[j, 1] = load_v[k, i, 1]


@numba.njit(cache=True, inline="always")
def _lane_outputs(k, f, path, work, block, unfinite):
    """The last part of lane ``k``'s step (:func:`_feed_step`), once its loops have run the
    block (``block`` = ``(pos, vel, cmd, torque, load)``, and its state at the block's end;
    ``unfinite``: whether a position or velocity of the block is not finite, which
    diverges the lane): contour errors, progress, the episode's flags, reward, outputs and
    observation.
    ``path`` = ``(st, rx, ry)`` from :func:`_lane_inputs`, ``work`` = ``(px, py, eps,
    tmp, lower, order)`` scratch."""
    st, rx, ry = path
    px, py, eps, tmp, lower, order = work
    pos, vel, cmd, torque, load = block
    lf, li, c, state = f.lf, f.li, f.consts, f.state
    n = int(c[_C.N_SUB])
    ts = c[_C.TS]
    tol = c[_C.TOL]
    tab = f.tabs[k, : li[k, _LI.nseg]]
    length = lf[k, _LF.length]
    x0 = lf[k, _LF.x0]
    y0 = lf[k, _LF.y0]
    a = lf[k, _LF.in_action]
    ov = _override(k, f)
    s0 = lf[k, _LF.s]
    diverged = unfinite
    for j in range(n):
        px[j] = pos[j, 0] + x0
        py[j] = pos[j, 1] + y0
    if diverged:  # kept so that no NaN can reach an observation or a reward
        for j in range(n):
            px[j] = rx[j]
            py[j] = ry[j]
            for q in range(2):
                torque[j, q] = 0.0
                cmd[j, q] = 0.0
        for j in range(n + 1):
            vel[j, 0] = 0.0
            vel[j, 1] = 0.0
        for q in range(state.shape[1]):
            state[k, q] = 0.0
    path_distances(tab, px, py, n, eps, tmp, lower, order)
    ds = st[n] - s0
    lf[k, _LF.s] = st[n]
    li[k, _LI.k] += n
    t = li[k, _LI.k] * ts
    s1 = lf[k, _LF.s]
    rxe, rye = path_point(tab, length, s1)
    xe = px[n - 1]
    ye = py[n - 1]
    etrack = py_hypot(rxe - xe, rye - ye)
    diverged = diverged or etrack > c[_C.DIVERGENCE]
    hit = -1
    # The set point's positions rise along the block (a feed and override never negative),
    # so none reaches the end unless the last does: the search is skipped (its second
    # condition keeps it for positions that do not rise).
    if st[n] >= length or not st[n] >= st[0]:
        for j in range(n):
            if st[j + 1] >= length:
                end = math.hypot(px[j] - lf[k, _LF.x_end], py[j] - lf[k, _LF.y_end])
                if end <= c[_C.IN_POSITION]:
                    hit = j
                    break
    finished = hit >= 0 and not diverged
    terminated = diverged or finished
    truncated = (not terminated) and t >= lf[k, _LF.time_limit] - 1e-12
    for j in range(n):
        e = eps[j] / tol - 1.0
        tmp[j] = e if (e > 0.0 or e != e) else 0.0
    excess = np_mean(tmp[:n])
    prog = lf[k, _LF.programmed_time]
    r = c[_C.W] * ds / length - c[_C.W + 1] * (n * ts) / prog - c[_C.W + 2] * excess
    if diverged:
        r -= c[_C.W + 3]
    lf[k, _LF.reward] = r
    lf[k, _LF.override] = ov
    lf[k, _LF.prev_action] = a
    for j in range(n):
        tmp[j] = torque[j, 0] * torque[j, 0] + torque[j, 1] * torque[j, 1]
    tsq = np_mean(tmp[:n])
    peak = row_largest(eps, n)
    o = f.out[k]
    o[_Out.t_s] = t
    o[_Out.command_x_mm_s] = cmd[n - 1, 0]
    o[_Out.command_y_mm_s] = cmd[n - 1, 1]
    o[_Out.x_mm] = xe
    o[_Out.y_mm] = ye
    o[_Out.x_ref_mm] = rxe
    o[_Out.y_ref_mm] = rye
    o[_Out.contour_error_mm] = eps[n - 1]
    o[_Out.peak_contour_error_mm] = peak
    o[_Out.tracking_error_mm] = etrack
    o[_Out.vx_mm_s] = vel[n, 0]
    o[_Out.vy_mm_s] = vel[n, 1]
    o[_Out.torque_x_Nm] = torque[n - 1, 0]
    o[_Out.torque_y_Nm] = torque[n - 1, 1]
    o[_Out.torque_sq_Nm2] = tsq
    o[_Out.load_x_Nm] = load[n - 1, 0]
    o[_Out.load_y_Nm] = load[n - 1, 1]
    o[_Out.feed_override] = ov
    o[_Out.path_speed_mm_s] = ov * lf[k, _LF.feed] if s1 < length else 0.0
    o[_Out.path_s_mm] = s1
    o[_Out.machining_time_s] = (li[k, _LI.k] - n + hit + 1) * ts if finished else np.nan
    li[k, _LI.segment] = path_segment_index(tab, length, s1)
    flags = f.flags
    flags[k, _Flag.diverged] = diverged
    flags[k, _Flag.finished] = finished
    flags[k, _Flag.terminated] = terminated
    flags[k, _Flag.truncated] = truncated
    sig = (eps[n - 1], peak, rxe - xe, rye - ye, vel[n, 0], vel[n, 1])
    _feed_obs(k, tab, f, sig)


@numba.njit(cache=True, _nrt=False, nogil=True)
def _feed_step(
    lf, li, tabs, load_t, load_v, loops, groups, state, consts, obs, flags, out, sc, order
):
    """One decision step of every lane (``ContouringFeedEnv.step`` after its input checks).

    ``lf`` and ``li`` hold the per-lane floats and integers (columns ``_LF``, ``_LI``),
    ``loops`` the lanes' closed loops (``ServoLanes.buf``), ``groups`` the same eight lanes
    to a row (``ServoLanes.groups``, of all lanes: a block's lanes are ``li[0, _LI.lane]``
    on), ``consts`` the env's constants (``_C``): where ``ACTUATED`` is 1 the override is
    ``applied`` (what the CNC's actuation made of the action's), else the action's.
    ``flags[k]`` (``_Flag``) = ``[diverged, finished, terminated, truncated]``; ``sc``,
    ``order`` = float and integer scratch (``FeedCore._scratch``). The env calls it
    through :func:`_feed_step_packed` (one table for every argument).

    Each lane's step is its inputs (:func:`_lane_inputs`), its closed loops over the
    block, then its outputs (:func:`_lane_outputs`). One lane (the single env) runs its
    loops by ``run_block``; more run ``LANES`` at a time, their loops side by side
    (``run_lanes``, about six times faster a lane: the same numbers)."""
    f = _Feed(lf, li, tabs, load_t, load_v, state, consts, obs, flags, out)
    n = int(consts[_C.N_SUB])
    n_lanes = lf.shape[0]
    if n_lanes == 1:  # one lane (the single env): its loops by run_block
        st, rx, ry, px, py, eps, tmp, ref, load, pos, vel, cmd, torque, zb, lower, pts = _carve(
            sc, n, order.size
        )
        ac, bc, cu, du, gu, tq, umax = lane_loops(loops[0])
        k = n_lanes - 1  # lane 0, not the constant 0: each function it reaches
        # would be compiled once more for a constant lane
        _lane_inputs(k, f, (st, rx, ry), ref, load, pts)
        block = ServoBlock(ref, load, pos, vel, cmd, torque)
        run_block((ac, bc, cu, du, gu, tq, umax[0]), state[0], block, zb)
        nan = 0.0  # NaN if a position or velocity is not finite (x - x is 0 for the others)
        for j in range(n):
            for q in range(2):
                nan += (pos[j, q] - pos[j, q]) + (vel[j + 1, q] - vel[j + 1, q])
        work = (px, py, eps, tmp, lower, order)
        _lane_outputs(k, f, (st, rx, ry), work, (pos, vel, cmd, torque, load), nan != nan)
        return
    # Several lanes: their loops LANES at a time (run_lanes: the same numbers, faster).
    _, _, _, px, py, eps, tmp, _, _, _, _, _, _, _, lower, pts = _carve(sc, n, order.size)
    gst, grx, gry, z, nan, gref, gload, gpos, gcmd, gtorque, gvel = _carve_lanes(sc, n, order.size)
    ref3 = gref.reshape((n, 2, LANES))
    load3 = gload.reshape((n, 2, LANES))
    pos3 = gpos.reshape((n, 2, LANES))
    cmd3 = gcmd.reshape((n, 2, LANES))
    torque3 = gtorque.reshape((n, 2, LANES))
    vel3 = gvel.reshape((n + 1, 2, LANES))
    ns = state.shape[1] // 2
    g0 = li[0, _LI.lane] // LANES  # the block's first group (blocks start at multiples of LANES)
    work = (px, py, eps, tmp, lower, order)
    for k0 in range(0, n_lanes, LANES):
        m = min(LANES, n_lanes - k0)
        for p in range(m):
            path = (gst[p], grx[p], gry[p])
            _lane_inputs(k0 + p, f, path, ref3[:, :, p], load3[:, :, p], pts)
        for p in range(m, LANES):  # places without a lane: zero inputs (they stay zero)
            for j in range(n):
                for q in range(2):
                    ref3[j, q, p] = 0.0
                    load3[j, q, p] = 0.0
        gather_states(state, k0, m, z)
        run_lanes(groups[g0 + k0 // LANES], ns, n, z, gref, gload, gpos, gvel, gcmd, gtorque)
        scatter_lanes(state, k0, m, z)
        # Whether each place's positions or velocities hold a value not finite, the eight
        # places at once: nan[p] is NaN then (x - x is 0 for the others).
        for p in range(LANES):
            nan[p] = 0.0
        for j in range(n):
            for q in range(2):
                a = (2 * j + q) * LANES
                b = a + 2 * LANES  # velocities: from the second row on
                for p in range(LANES):
                    nan[p] += (gpos[a + p] - gpos[a + p]) + (gvel[b + p] - gvel[b + p])
        for p in range(m):
            path = (gst[p], grx[p], gry[p])
            block = (pos3[:, :, p], vel3[:, :, p], cmd3[:, :, p], torque3[:, :, p], load3[:, :, p])
            _lane_outputs(k0 + p, f, path, work, block, nan[p] != nan[p])


@numba.njit(cache=True, nogil=True)
def _feed_step_packed(t):
    """:func:`_feed_step` with its arguments in one table (``core.compiled.packed``): what every
    step calls (one array to unbox, not one per argument)."""
    _feed_step(*_step_tables(t), f8_1(t, 12), i8_1(t, 13))


@numba.njit(cache=True, inline="always")
def _step_tables(t):
    """:func:`_feed_step`'s arguments before its scratch, from the kernel's table ``t``."""
    tables = (f8_2(t, 0), i8_2(t, 1), f8_3(t, 2), f8_2(t, 3), f8_3(t, 4), f8_2(t, 5))
    rest = (f8_2(t, 6), f8_2(t, 7), f8_1(t, 8), f4_2(t, 9), b1_2(t, 10), f8_2(t, 11))
    return tables + rest


@numba.njit(cache=True, inline="always")
def _feed_of(t):
    """The step's lane tables (:class:`_Feed`) from the kernel's table ``t``."""
    lf, li, tabs, load_t, load_v, _, _, state, consts, obs, flags, out = _step_tables(t)
    return _Feed(lf, li, tabs, load_t, load_v, state, consts, obs, flags, out)


@numba.njit(cache=True, nogil=True)
def _serve_feed_step(ctl, table, polls):
    """The lane blocks' worker loop for :func:`_feed_step_packed` (``core.compiled.blocks``),
    compiled with this module and cached, not at the first step on several threads."""
    return serve_one_table(_feed_step_packed, ctl, table, polls)


#: Where :func:`_feed_step`'s arguments (``FeedCore._args``) hold the lanes: axis 0, none
#: (shared) or scratch space, for :class:`~machining_envs.core.compiled.blocks.LaneBlocks`.
_STEP_AXES = (
    *(0, 0, 0, 0, 0, 0, None, 0, None, 0, 0, 0, SCRATCH, SCRATCH),  # _feed_step's
    *(0, 0, 0, None, *[None] * 8),  # the start's (_F_START)
)
#: Where the kernel's table (``FeedCore._args``) holds, after :func:`_feed_step`'s
#: arguments, what a batch's start (:func:`_start_batch`) writes besides or reads: the
#: score bounds, whether each lane's path is a circle and its circle, the start's
#: constants (``FeedCore._start_consts``) and both axes' designs (``A``, ``B``, ``C``,
#: ``D`` of X, then of Y).
_F_START = 14
# The kernel's blocks of lanes start at multiples of ALIGN, and so at a group's first lane:
# a block reads its groups' coefficients from its first lane's group on (li[0, _LI.lane]).
assert ALIGN % LANES == 0


@numba.njit(cache=True)
def _feed_reset_obs(k, f):
    """The first observation of lane ``k``'s episode (table at rest at the path's start)."""
    _feed_obs(k, f.tabs[k, : f.li[k, _LI.nseg]], f, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0))


@numba.njit(cache=True)
def _feed_reset_packed(t, k):
    """:func:`_feed_reset_obs` on the kernel's table ``t``."""
    _feed_reset_obs(k, _feed_of(t))


@numba.njit(cache=True)
def _start_drawn_lanes(f, lanes, drawn, t_load, t_max, override_max, bound):
    """:meth:`FeedCore.start`'s arrays (``f``, and the score bounds ``bound``) for every
    lane ``lanes[i]`` of a split's batch, from its drawn numbers (``drawn``,
    ``_RandomPaths.draw_lanes``: ``ints``, ``floats``, the tables, feeds; the load times
    ``t_load``), in ``start``'s arithmetic; ``t_max`` NaN: the time limit from the
    programmed time. The servo loops are started apart (:func:`_start_batch`)."""
    ints, floats, drawn_tabs, feed = drawn.ints, drawn.floats, drawn.tabs, drawn.feed
    lf, li, tabs, load_t, load_v, state, out = (
        f.lf,
        f.li,
        f.tabs,
        f.load_t,
        f.load_v,
        f.state,
        f.out,
    )
    for i in range(lanes.size):
        k = lanes[i]
        n = ints[i, 0]
        for r in range(tabs.shape[1]):
            for c in range(tabs.shape[2]):
                tabs[k, r, c] = drawn_tabs[i, r, c] if r < n else 0.0
        li[k, _LI.nseg] = n
        d = floats[i]
        length = d[_D_LENGTH]
        x0 = d[_D_X0]
        y0 = d[_D_Y0]
        prog = length / feed[i]
        p = lf[k]
        p[_LF.length] = length
        p[_LF.x0] = x0
        p[_LF.y0] = y0
        p[_LF.x_end] = d[_D_XE]
        p[_LF.y_end] = d[_D_YE]
        p[_LF.feed] = feed[i]
        p[_LF.programmed_time] = prog
        p[_LF.time_limit] = 5.0 * prog + 0.5 if t_max != t_max else t_max
        bound[k] = length / (override_max * feed[i])
        for q in range(load_t.shape[1]):
            load_t[k, q] = np.inf
        for q in range(load_v.shape[1]):
            load_v[k, q, 0] = 0.0
            load_v[k, q, 1] = 0.0
        if ints[i, 1]:
            load_t[k, 0] = t_load[i]
            load_v[k, 1, 0] = d[_D_A]
            load_v[k, 1, 1] = d[_D_B]
        li[k, _LI.n_load] = 1
        p[_LF.s] = 0.0
        li[k, _LI.k] = 0
        p[_LF.override] = 0.0
        p[_LF.prev_action] = -1.0
        li[k, _LI.n_clipped] = 0
        for q in range(state.shape[1]):
            state[k, q] = 0.0
        _feed_reset_obs(k, f)
        tab = tabs[k, :n]
        rx, ry = path_point(tab, length, 0.0)
        o = out[k]
        for q in range(o.shape[0]):
            o[q] = 0.0
        o[_Out.x_mm] = x0
        o[_Out.y_mm] = y0
        o[_Out.x_ref_mm] = rx
        o[_Out.y_ref_mm] = ry
        o[_Out.path_speed_mm_s] = 0.0 * feed[i] if 0.0 < length else 0.0
        o[_Out.machining_time_s] = np.nan
        for q in range(f.flags.shape[1]):
            f.flags[k, q] = False
        li[k, _LI.in_clipped] = 0
        li[k, _LI.segment] = path_segment_index(tab, length, 0.0)


@numba.njit(cache=True)
def _start_batch(t, lanes, drawn):
    """:meth:`FeedCore.start_lanes`' arrays for every lane ``lanes[i]`` of a split's batch
    from its drawn numbers (``drawn``, ``_RandomPaths.draw_lanes``), in one call on the
    kernel's table ``t``: its servo loops on the nominal plant with the inertias scaled by
    ``drawn.scale[i]`` (``ServoLanes.start_scaled``'s numbers), then
    :func:`_start_drawn_lanes`; the lane's path is no circle (paths of several segments)."""
    buf, groups = f8_2(t, 5), f8_2(t, 6)
    o = _F_START
    bound, has_circle, circle, sc = f8_1(t, o), b1_1(t, o + 1), f8_2(t, o + 2), f8_1(t, o + 3)
    designs = (
        (f8_2(t, o + 4), f8_2(t, o + 5), f8_2(t, o + 6), f8_2(t, o + 7)),
        (f8_2(t, o + 8), f8_2(t, o + 9), f8_2(t, o + 10), f8_2(t, o + 11)),
    )
    m = lanes.size
    floats, feed = drawn.floats, drawn.feed
    t_load = np.empty(m)
    for i in range(m):
        f = floats[i]
        t_load[i] = load_time(f[_D_LENGTH], feed[i], f[_D_T])
    start_scaled_loops(lanes, sc[:_S_TMAX], drawn.scale, designs, buf, groups)
    _start_drawn_lanes(_feed_of(t), lanes, drawn, t_load, sc[_S_TMAX], sc[_S_OVERRIDE], bound)
    for i in range(m):
        has_circle[lanes[i]] = False
        for q in range(3):
            circle[lanes[i], q] = 0.0


#: ``FeedCore._start_consts``: the nominal plant's numbers (``NOMINAL_LOOP_NUMBERS``), then
#: the time limit (NaN: from the programmed time) and the largest override.
_S_TMAX = len(NOMINAL_LOOP_NUMBERS)
_S_OVERRIDE = _S_TMAX + 1


#: The step's signals in ``out`` from ``x_mm`` to ``path_s_mm``, info's keys, and their
#: columns (as plain ints, as those of the peak contour error and the machining time).
_SIGNALS = tuple(_Out.__members__)[_Out.x_mm : _Out.machining_time_s]
_SIGNAL_COLUMNS = slice(int(_Out.x_mm), int(_Out.machining_time_s))
_OUT_ERROR, _OUT_TIME = int(_Out.peak_contour_error_mm), int(_Out.machining_time_s)
#: The float keys between the flags and ``segment`` in the info's order.
_INFO_OUT = (
    *_SIGNALS,
    "contour_tolerance_mm",
    "cost",
    "score_bound",
    "path_length_mm",
)
#: The float keys of a vector step's info, one row each of the table :func:`_info_rows`
#: fills (``FeedCore.info_arrays``).
_INFO_F = (
    *("t_s", "command_x_mm_s", "command_y_mm_s", *_INFO_OUT),
    *("feed_mm_s", "programmed_time_s", "time_limit_s", "machining_time_s"),
)


#: The boolean and integer keys of a vector step's info, one row each of the tables
#: :func:`_info_rows` fills (``_machining_time_s``: the lanes that finished).
_INFO_B = ("action_clipped", "breakage", "diverged", "finished", "_machining_time_s")
_INFO_I = ("n_action_clipped", "segment")


@numba.njit(cache=True)
def _info_rows(out, lf, bound, flags, li, tol, rows, command, bits, ints):
    """Every lane's info, as :meth:`FeedCore.lane_info` reports it, one column per lane:
    the float keys into ``rows`` (one row per key of ``_INFO_F``; rows spaced apart,
    ``core.compiled.packed.spaced_rows``), its two commands into ``command`` (``(N, 2)``), the
    boolean keys into ``bits`` (``_INFO_B``) and the integer ones into ``ints``
    (``_INFO_I``)."""
    m = out.shape[1] - 4  # the outputs x_mm .. path_s_mm
    for k in range(out.shape[0]):
        o = out[k]
        command[k, 0] = o[1]
        command[k, 1] = o[2]
        rows[0, k] = o[0]
        rows[1, k] = o[1]
        rows[2, k] = o[2]
        for i in range(m):
            rows[3 + i, k] = o[3 + i]
        rows[3 + m, k] = tol
        rows[4 + m, k] = 1.0 if o[_Out.peak_contour_error_mm] > tol else 0.0
        rows[5 + m, k] = bound[k]
        rows[6 + m, k] = lf[k, _LF.length]
        rows[7 + m, k] = lf[k, _LF.feed]
        rows[8 + m, k] = lf[k, _LF.programmed_time]
        rows[9 + m, k] = lf[k, _LF.time_limit]
        rows[10 + m, k] = o[_Out.machining_time_s] if flags[k, _Flag.finished] else np.nan
        bits[0, k] = li[k, _LI.in_clipped] != 0
        bits[1, k] = False
        bits[2, k] = flags[k, _Flag.diverged]
        bits[3, k] = flags[k, _Flag.finished]
        bits[4, k] = flags[k, _Flag.finished]
        ints[0, k] = li[k, _LI.n_clipped]
        ints[1, k] = li[k, _LI.segment]


class FeedCore(LaneCore):
    """The state and arithmetic of N ContouringFeed-v0 episodes, shared by
    ``ContouringFeedEnv`` (one lane) and ``ContouringFeedVectorEnv`` (N lanes): each lane's
    path (``Path.table``), loads and closed loops (``ServoLanes``), advanced by one compiled
    function (:func:`_feed_step`), so that a lane and the single env agree to the last bit."""

    #: What a scenario may be: an object of this class or one of these names.
    scenario_types = (ContouringScenario, CONTOURING_SCENARIOS)
    #: The named views of the lane tables (made again on unpickling): ``lf``'s per-lane
    #: floats before ``length``, ``pf`` (``lf``'s columns from ``length`` on), every
    #: column of ``li``.
    VIEWS = frozenset({*_LF.__members__, *_LI.__members__, "pf", "_args"})

    def __init__(
        self,
        owner,
        n,
        scenario,
        *,
        params,
        servo,
        tolerance_mm,
        reward,
        decision_interval_s,
        override_max,
        max_episode_time_s,
        in_position_mm,
        divergence_mm,
        overrides,
        actuation=None,
    ):
        self.params = resolve_params(
            owner, params, ContouringParams, ContouringParams.choi_et_al, overrides
        )
        self.actuation = resolve_actuation(actuation)
        if servo not in SERVO_KINDS:
            raise ValueError(f"servo must be one of {SERVO_KINDS}, got {servo!r}")
        self.servo = servo
        if tolerance_mm is None:
            tolerance_mm = DEFAULT_TOLERANCE_MM[servo]
        self.tolerance_mm = positive_setting("tolerance_mm", tolerance_mm, 0.0, 100.0)
        self.reward_weights = resolve_reward(reward, FeedReward)
        ts = self.params.sample_time_s
        dec = positive_setting("decision_interval_s", decision_interval_s, 0.0, 1.0)
        n_sub = int(round(dec / ts))
        if n_sub < 1 or abs(n_sub * ts - dec) > 1e-9 * dec:
            raise ValueError(
                f"decision_interval_s must be a whole number of servo periods "
                f"({ts} s), got {decision_interval_s!r}"
            )
        self.decision_interval_s = dec
        self.n_sub = n_sub
        self.override_max = positive_setting("override_max", override_max, 0.0, 10.0)
        self.max_episode_time_s, self.in_position_mm, self.divergence_mm = run_limits(
            max_episode_time_s, in_position_mm, divergence_mm
        )
        check_scenario_spec(scenario, ContouringScenario, CONTOURING_SCENARIOS)
        # Design the servo now (cached per process), so that a bad design fails here.
        designs = tuple(servo_design(servo, self.params, ax) for ax in AXES)
        self.command_map = ActionMap(0.0, self.override_max)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        high = np.array(_LIMS, dtype=np.float32)
        high[4] = self.override_max
        low = -high
        low[[0, 1, 4, 5, 6, 12]] = 0.0
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        w = self.reward_weights
        cm = self.command_map
        # The kernel's constants (_C), with the bounds as the observation clips to them
        # (Python floats of the float32 box).
        scalars = (n_sub, ts, self.tolerance_mm, self.in_position_mm, self.divergence_mm)
        weights = (w.progress, w.time, w.tolerance, w.divergence)
        self.consts = np.array(
            [*scalars, cm.mid, cm.half, 0.0, *weights, *LOOKAHEAD_MM, *low.tolist(), *high.tolist()]
        )
        assert self.consts.size == _C.HI + _N_OBS
        self.n = n
        # Per-lane floats and integers, each set in one array (one argument of the kernel)
        # and named by views of its columns (_LF, _LI).
        self.lf = np.zeros((n, len(_LF)))
        self.lf[:, _LF.length :] = 1.0
        self.li = np.zeros((n, len(_LI)), dtype=np.int64)
        self.bind_views()
        self.lane[:] = np.arange(n)  # each lane's index (the kernel's blocks read theirs)
        self.prev_action[:] = -1.0
        # The CNC's override handling, made now if the option sets it (its checks fail
        # here), else when a scenario first brings its own.
        self.act_lanes = None if self.actuation is None else self.actuation_lanes()
        self.nseg[:] = 1
        self.loops = ServoLanes(designs, n_sub, n)
        self.state = np.zeros((n, 2 * self.loops.n_states_axis))
        self.tabs = np.zeros((n, 4, SEGMENT_COLUMNS))
        self.bound = np.full(n, np.nan)
        self.load_t = np.full((n, 1), np.inf)
        self.load_v = np.zeros((n, 2, 2))
        self.obs = np.zeros((n, 16), dtype=np.float32)
        self.flags = np.zeros((n, 4), dtype=np.bool_)
        self.out = np.zeros((n, len(_Out)))
        #: Every lane's scenario and true parameters (built when read, for lanes started
        #: together by :meth:`start_lanes`).
        self.scenarios = LaneObjects(n)
        self.truths = LaneObjects(n)
        #: The generators the lanes of a batch draw their scenarios from (``start_lanes``).
        self.rngs = LaneGenerators(n)
        self._batch_ok: dict = {}  # batches' checks, by factory
        self.names = LaneNames(n)
        self.servos = np.full(n, servo, dtype=object)
        self.servos.flags.writeable = False  # every step's info holds it
        #: Per lane, the values of info that hold for the whole episode; None for a lane
        #: started with others until :meth:`lane_info` reads them from the arrays.
        self.episode_info: list[dict | None] = [{}] * n
        self.has_circle = np.zeros(n, dtype=bool)
        self.circle = np.zeros((n, 3))
        self._circles = 0  # lanes whose path is a circle (has_circle's count)
        p = self.params
        t_max = self.max_episode_time_s
        nominal = [getattr(p, name) for name in NOMINAL_LOOP_NUMBERS]
        t_max = math.nan if t_max is None else float(t_max)
        self._start_consts = np.array([*nominal, t_max, self.override_max])  # (_S_*)
        n_seg = self.tabs.shape[1]
        self._scratch = (self._float_scratch(n_seg), np.zeros(n_seg, dtype=np.int64))
        self._packed = PackedArgs()  # the kernel's arguments in one table (core.compiled.packed)
        #: The blocks of lanes the kernel steps at once (one thread unless a vector env
        #: asks for more).
        self.blocks = LaneBlocks(n)
        self._bind()

    def bind_views(self) -> None:
        """Name the columns of ``lf`` (``_LF``; ``pf``, from ``length`` on) and ``li``
        (``_LI``)."""
        for col in _LF:
            if col < _LF.length:
                setattr(self, col.name, self.lf[:, col])
        self.pf = self.lf[:, _LF.length :]
        for col in _LI:
            setattr(self, col.name, self.li[:, col])

    def __setstate__(self, state: dict) -> None:
        state["servos"].flags.writeable = False  # (a pickle's array is writable)
        super().__setstate__(state)
        self._bind()

    def _float_scratch(self, n_seg: int) -> np.ndarray:
        return np.zeros(_scratch_size(self.n_sub, n_seg, self.n > 1))

    def actuation_lanes(self) -> ActuationLanes:
        """The CNC's actuation between the actions and the override, for every lane (a lane
        without settings passes its override unchanged)."""
        self.consts[_C.ACTUATED] = 1.0
        return ActuationLanes(
            self.n, self.override_max, 0.0, self.decision_interval_s, self.actuation
        )

    # ---- per-lane episodes ---------------------------------------------------------------
    def _grow(self, n_seg: int, n_load: int) -> None:
        """Widen the per-lane tables to ``n_seg`` segments and ``n_load`` load steps where
        they are narrower; the kernel's arguments are gathered again only then (new
        arguments are packed into a new table, some 60 µs at N = 1024)."""
        grown = False
        if n_seg > self.tabs.shape[1]:
            tabs = np.zeros((self.n, n_seg, SEGMENT_COLUMNS))
            tabs[:, : self.tabs.shape[1]] = self.tabs
            self.tabs = tabs
            self._scratch = (self._float_scratch(n_seg), np.zeros(n_seg, dtype=np.int64))
            grown = True
        if n_load > self.load_t.shape[1]:
            lt = np.full((self.n, n_load), np.inf)
            lt[:, : self.load_t.shape[1]] = self.load_t
            lv = np.zeros((self.n, n_load + 1, 2))
            lv[:, : self.load_v.shape[1]] = self.load_v
            self.load_t, self.load_v = lt, lv
            grown = True
        if grown:
            self._bind()

    def start(self, lane: int, spec, rng: np.random.Generator) -> None:
        """Start an episode in ``lane`` on the scenario ``spec`` (drawn with ``rng``); its
        first observation goes to ``obs[lane]``, its reset info is its :meth:`lane_info`
        (and its column of :meth:`info_arrays`) until the first step."""
        sc = contouring_scenario(spec, rng)
        if sc.is_step:
            raise ValueError(
                f"scenario {sc.name!r} is a step command; ContouringFeed-v0 needs a path with a feed"
            )
        check_feed(sc, self.params)
        self.act_lanes = configure_lane(
            self.act_lanes, lane, sc.actuation, self.actuation, self.actuation_lanes
        )
        self.scenarios[lane] = sc
        truth = self.truths[lane] = sc.true_params(self.params)
        self.loops.start(lane, truth)
        self.state[lane] = 0.0
        path = sc.path
        tab = path.table()
        self._grow(tab.shape[0], len(sc.load_steps))
        self.tabs[lane, : tab.shape[0]] = tab
        self.tabs[lane, tab.shape[0] :] = 0.0  # no rows of an earlier path left behind
        self.nseg[lane] = tab.shape[0]
        prog = path.length / sc.feed_mm_s
        t_max = self.max_episode_time_s
        if t_max is None:
            t_max = 5.0 * prog + 0.5
        x0, y0 = path.start
        self.pf[lane] = (path.length, x0, y0, *path.end, sc.feed_mm_s, prog, t_max)
        # The floor of the cycle time: the set point must travel the path, at most at the
        # largest override of the programmed feed.
        self.bound[lane] = path.length / (self.override_max * sc.feed_mm_s)
        self.load_t[lane] = np.inf
        self.load_v[lane] = 0.0
        for i, (t, a, b) in enumerate(sc.load_steps):
            self.load_t[lane, i] = t
            self.load_v[lane, i + 1] = (a, b)
        self.n_load[lane] = max(len(sc.load_steps), 1)
        self.s[lane] = 0.0
        self.k[lane] = 0
        self.override[lane] = 0.0
        self.prev_action[lane] = -1.0
        self.n_clipped[lane] = 0
        self.names[lane] = sc.name
        circles = circle_info(path)
        self._circles += bool(circles) - bool(self.has_circle[lane])
        self.has_circle[lane] = bool(circles)
        self.circle[lane] = tuple(circles.values()) or (0.0, 0.0, 0.0)
        # The values of info that hold for the whole episode.
        self.episode_info[lane] = {
            "contour_tolerance_mm": self.tolerance_mm,
            "score_bound": float(self.bound[lane]),
            "path_length_mm": float(self.pf[lane, 0]),
            "feed_mm_s": sc.feed_mm_s,
            "programmed_time_s": float(self.pf[lane, 6]),
            "time_limit_s": float(self.pf[lane, 7]),
            "servo": self.servo,
            "scenario": sc.name,
            **circles,
        }
        _feed_reset_packed(self._packed(self._args), lane)
        rx, ry = path.point(0.0)
        o = self.out[lane]
        o[:] = 0.0
        o[_Out.x_mm], o[_Out.y_mm] = x0, y0
        o[_Out.x_ref_mm], o[_Out.y_ref_mm] = rx, ry
        o[_Out.path_speed_mm_s] = 0.0 * sc.feed_mm_s if 0.0 < path.length else 0.0
        o[_Out.machining_time_s] = np.nan
        self.flags[lane] = False
        self.in_clipped[lane] = 0  # no action yet (the next step sets it)
        self.segment[lane] = path.segment_index(0.0)

    def start_lanes(self, lanes: np.ndarray, spec, rngs) -> None:
        """:meth:`start` for each lane ``k`` of ``lanes`` on the scenario ``spec``, drawn
        with ``rngs[k]``: the same episodes, the same numbers. A split's scenarios (a name
        such as ``"train"``) are drawn for all lanes in one compiled call and their arrays
        set in another; each lane's servo loops are designed on its true table here, and
        its scenario object is built only when read (``scenarios[k]``)."""
        factory = split_batch(self, lanes, spec, rngs, CONTOURING_SCENARIOS)
        if factory is None:
            return
        drawn = factory.draw_lanes(self.rngs.table, lanes)
        if factory.segments[1] > self.tabs.shape[1]:
            self._grow(factory.segments[1], 1)
        ks = settle_batch(
            self, lanes, factory.build_lane, (drawn,), factory.actuation, factory.name
        )
        if self._circles:  # the batch's paths are no circles
            self._circles -= int(np.count_nonzero(self.has_circle[lanes]))
        _start_batch(self._packed(self._args), lanes, drawn)
        info = self.episode_info
        for k in ks:
            info[k] = None  # lane_info reads it from the arrays

    def batches(self, factory) -> bool:
        """Whether :meth:`start_lanes` may start ``factory``'s scenarios in one batch: a
        split's random paths of two segments or more (no circle test), whose every
        scenario passes the check ``start`` makes (those of the ranges' two ends, checked
        once)."""
        if not isinstance(factory, _RandomPaths) or factory.segments[0] < 2:
            return False

        def check(sc) -> bool:
            check_feed(sc, self.params)  # raises ValueError for a scenario it refuses
            return True

        return self._extremes_pass(factory, check)

    def set_action(self, lane: int, action: list[float], clipped: bool) -> None:
        self.in_action[lane] = action[0]
        self.in_clipped[lane] = clipped

    def set_actions(self, actions: np.ndarray) -> None:
        clip_unit(actions[:, 0], self.in_action, self.in_clipped)

    def outcome(self, lane: int) -> tuple[float, bool, bool]:
        terminated, truncated = self.flags[lane, 2:].tolist()
        return float(self.reward[lane]), terminated, truncated

    def step_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.reward, self.flags[:, 2], self.flags[:, 3]

    def clipped_count(self, lane: int) -> int:
        return int(self.n_clipped[lane])

    def step(self) -> None:
        """Advance every lane with the (checked, clipped) actions in ``in_action``; whether
        each was clipped is in ``in_clipped``. With CNC actuation on, the overrides the
        actions ask for pass through it first (``machining_envs.core.actuation``)."""
        if self.act_lanes is not None:
            c = self.consts
            asked = c[_C.MID] + c[_C.HALF] * self.in_action
            self.applied[:] = self.act_lanes.apply(asked)
        if self.blocks.one:  # the single env, or few lanes: no blocks to hand out
            _feed_step_packed(self._packed(self._args))
        else:
            self.blocks.run(
                _feed_step, self._args, _STEP_AXES, packed=_feed_step_packed, serve=_serve_feed_step
            )

    def _bind(self) -> None:
        """Gather the kernel's arguments once (again whenever an array is replaced, as
        :meth:`_grow` does), not attribute by attribute every step."""
        tables = (self.lf, self.li, self.tabs, self.load_t, self.load_v)
        loops = (self.loops.buf, self.loops.groups, self.state, self.consts)
        # then what a batch's start writes besides or reads (_F_START)
        start = (self.bound, self.has_circle, self.circle, self._start_consts)
        designs = tuple(m for axis in self.loops._design_arrays for m in axis)
        self._args = (
            *tables,
            *loops,
            self.obs,
            self.flags,
            self.out,
            *self._scratch,
            *start,
            *designs,
        )

    def lane_info(self, k: int) -> dict:
        """The info of lane ``k`` after its reset or its last step."""
        out = self.out[k]
        o = out.tolist()
        diverged, finished, _, _ = self.flags[k].tolist()
        in_clipped, _, _, _, n_clipped, segment, _ = self.li[k].tolist()  # _LI
        info = {
            "t_s": o[0],
            "command": out[1:3].copy(),
            "command_x_mm_s": o[1],
            "command_y_mm_s": o[2],
            "action_clipped": in_clipped != 0,
            "n_action_clipped": n_clipped,
            "breakage": False,
            "diverged": diverged,
            "finished": finished,
            **dict(zip(_SIGNALS, o[_SIGNAL_COLUMNS], strict=True)),
            "cost": 1.0 if o[_OUT_ERROR] > self.tolerance_mm else 0.0,
            "segment": segment,
            **self._episode_info(k),
        }
        if finished:
            info["machining_time_s"] = o[_OUT_TIME]
        return info

    def _episode_info(self, k: int) -> dict:
        """The values of lane ``k``'s info that hold for its whole episode."""
        info = self.episode_info[k]
        if info is None:  # a lane started with others (start_lanes): a path of several
            # segments, so no circle; the numbers start wrote, as Python values
            info = self.episode_info[k] = {
                "contour_tolerance_mm": self.tolerance_mm,
                "score_bound": float(self.bound[k]),
                "path_length_mm": float(self.pf[k, 0]),
                "feed_mm_s": float(self.pf[k, 5]),
                "programmed_time_s": float(self.pf[k, 6]),
                "time_limit_s": float(self.pf[k, 7]),
                "servo": self.servo,
                "scenario": self.names[k],
            }
        return info

    def info_arrays(self) -> dict:
        """The step info of every lane, as arrays (keys that only some lanes have come with
        their ``_key`` masks): the float, boolean and integer keys rows of three tables
        filled in one compiled call (:func:`_info_rows`); the servo and scenario names
        arrays no reset writes to."""
        n = self.n
        rows = spaced_rows(len(_INFO_F), n)
        # The commands are filled with the rows: a copy of out's two columns is slower.
        command = np.empty((n, 2))
        bits = np.empty((len(_INFO_B), n), dtype=np.bool_)
        ints = np.empty((len(_INFO_I), n), dtype=np.int64)
        _info_rows(
            self.out,
            self.lf,
            self.bound,
            self.flags,
            self.li,
            self.tolerance_mm,
            rows,
            command,
            bits,
            ints,
        )
        r = dict(zip(_INFO_F, rows, strict=True))
        b = dict(zip(_INFO_B, bits, strict=True))
        i = dict(zip(_INFO_I, ints, strict=True))
        info = {
            "t_s": r["t_s"],
            "command": command,
            "command_x_mm_s": r["command_x_mm_s"],
            "command_y_mm_s": r["command_y_mm_s"],
            "action_clipped": b["action_clipped"],
            "n_action_clipped": i["n_action_clipped"],
            "breakage": b["breakage"],
            "diverged": b["diverged"],
            "finished": b["finished"],
        }
        for name in _INFO_OUT:
            info[name] = r[name]
        info["segment"] = i["segment"]
        for name in ("feed_mm_s", "programmed_time_s", "time_limit_s"):
            info[name] = r[name]
        info["servo"] = self.servos  # read-only, one servo for every lane
        info["scenario"] = self.names.array()
        if self._circles:
            for j, key in enumerate(("circle_cx_mm", "circle_cy_mm", "circle_radius_mm")):
                info[key] = self.circle[:, j].copy()
                info["_" + key] = self.has_circle.copy()
        info["machining_time_s"] = r["machining_time_s"]
        info["_machining_time_s"] = b["_machining_time_s"]
        return info
