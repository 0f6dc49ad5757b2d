"""The engine of ``ContouringFeed-v0``: the reward weights, the lane tables and the
compiled step and start of N CNC feed overrides over their position loops, which
:class:`ContouringFeedEnv` (one lane) and :class:`ContouringFeedVectorEnv` (N lanes) drive."""

from __future__ import annotations

import math
from dataclasses import dataclass

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
from machining_envs.core.lanes import (
    LaneCore,
    LaneNames,
    LaneObjects,
    settle_batch,
    split_batch,
)
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

#: Columns of ``FeedCore.pf`` (per-lane path and run constants).
_PF = ("length", "x0", "y0", "x_end", "y_end", "feed", "programmed_time", "time_limit")
#: Columns of ``FeedCore.out`` (the step's signals, read into ``info``).
_OUT = ("t_s", "command_x_mm_s", "command_y_mm_s", "x_mm", "y_mm", "x_ref_mm", "y_ref_mm",
        "contour_error_mm", "peak_contour_error_mm", "tracking_error_mm", "vx_mm_s",
        "vy_mm_s", "torque_x_Nm", "torque_y_Nm", "torque_sq_Nm2", "load_x_Nm", "load_y_Nm",
        "feed_override", "path_speed_mm_s", "path_s_mm", "machining_time_s")  # fmt: skip
_O = {name: i for i, name in enumerate(_OUT)}


@numba.njit(cache=True, _nrt=False, error_model="numpy")
def _feed_obs(k, tab, pf, s, override, prev_action, eps, peak, ex, ey, vx, vy, tol, look,
              lo, hi, obs):  # fmt: skip
    """Observation of lane ``k`` (``ContouringFeedEnv``'s table) into ``obs[k]``. It
    allocates nothing, so it keeps no reference counts (``_nrt=False``: its views of the
    lane's rows cost none), and divides as numpy does (``error_model="numpy"``: no test of
    each divisor, a path's length, the tolerance, pi, all positive)."""
    length = pf[k, 0]
    sk = s[k]
    o = obs[k]
    _bound(o, 0, eps / tol, lo, hi)
    _bound(o, 1, peak / tol, lo, hi)
    _bound(o, 2, ex / ERROR_SCALE_MM, lo, hi)
    _bound(o, 3, ey / ERROR_SCALE_MM, lo, hi)
    _bound(o, 4, override[k] if sk < length else 0.0, lo, hi)
    _bound(o, 5, sk / length, lo, hi)
    _bound(o, 6, (length - sk) / 100.0, lo, hi)
    h0 = path_heading(tab, length, sk)
    for i in range(look.size):
        _bound(o, 7 + i, (path_heading(tab, length, sk + look[i]) - h0) / math.pi, lo, hi)
    _bound(o, 12, pf[k, 5] / 100.0, lo, hi)
    _bound(o, 13, vx / VELOCITY_SCALE_MM_S, lo, hi)
    _bound(o, 14, vy / VELOCITY_SCALE_MM_S, lo, hi)
    _bound(o, 15, prev_action[k], lo, hi)


@numba.njit(cache=True, inline="always")
def _bound(o, i, x, lo, hi):
    """``o[i]`` = ``x`` held within ``[lo[i], hi[i]]`` (as float32)."""
    o[i] = lo[i] if x < lo[i] else (hi[i] if x > hi[i] else x)


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


#: Columns of ``FeedCore.lf`` (per-lane floats) and ``FeedCore.li`` (per-lane integers).
_LF = ("in_action", "applied", "s", "override", "prev_action", "reward")
_LI = ("in_clipped", "nseg", "n_load", "k", "n_clipped", "segment")
#: ``FeedCore.consts``: ``c`` (see :func:`_feed_step`), the reward weights, the lookahead
#: distances, the observation's lower and upper bounds; where each starts.
_C_W = 8
_C_LOOK = _C_W + 4
_C_LO = _C_LOOK + len(LOOKAHEAD_MM)
_C_HI = _C_LO + len(_LIMS)
_N_OBS = len(_LIMS)


@numba.njit(cache=True, inline="always")
def _override(k, actions, applied, c):
    """Lane ``k``'s feed override this step: what the CNC's actuation made of its action
    where ``c[7]`` (actuated) is set, else the action's own."""
    return applied[k] if c[7] != 0.0 else c[5] + c[6] * actions[k]


@numba.njit(cache=True, inline="always")
def _lane_inputs(k, tabs, nseg, pf, actions, applied, clipped, n_clipped, c, s, kk, n_load,
                 load_t, load_v, n, ts, st, rx, ry, ref, load, pts):  # fmt: skip
    """The first part of lane ``k``'s step (:func:`_feed_step`): the set point's path
    positions ``st`` over the block and its points ``rx``, ``ry``, the references ``ref``
    and load torques ``load`` of the servo periods."""
    tab = tabs[k, : nseg[k]]
    length = pf[k, 0]
    x0 = pf[k, 1]
    y0 = pf[k, 2]
    n_clipped[k] += clipped[k]
    ov = _override(k, actions, applied, c)
    v = pf[k, 5] * ov
    vts = v * ts
    s0 = s[k]
    for j in range(n + 1):
        st[j] = min(s0 + vts * float(j), length)
    path_points(tab, length, st, n, rx, ry, pts)
    for j in range(n):
        ref[j, 0] = rx[j] - x0
        ref[j, 1] = ry[j] - y0
    # The load torque of each period: the last step of the lane's load at or before its
    # instant. The instants rise, so each search goes on from the last one's step, and a
    # block whose last instant comes before the next step holds the first period's load.
    nl = n_load[k]
    k0 = kk[k]
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
def _lane_outputs(k, tabs, nseg, pf, actions, applied, c, w, look, lo, hi, tol, s, kk,
                  override, prev_action, reward, segment, state, flags, out, obs, n, ts, path,
                  work, block, unfinite):  # fmt: skip
    """The last part of lane ``k``'s step (:func:`_feed_step`), once its loops have run the
    block (``block`` = ``(pos, vel, cmd, torque, load)``, and its ``state`` at the block's
    end; ``unfinite``: whether a position or velocity of the block is not finite, which
    diverges the lane): contour errors, progress, the episode's flags, reward, outputs and
    observation.
    ``path`` = ``(st, rx, ry)`` from :func:`_lane_inputs`, ``work`` = ``(px, py, eps,
    tmp, lower, order)`` scratch. (Fewer than 30 arguments: a call with more passes them
    as a tuple, which the compiler cannot inline.)"""
    st, rx, ry = path
    px, py, eps, tmp, lower, order = work
    pos, vel, cmd, torque, load = block
    tab = tabs[k, : nseg[k]]
    length = pf[k, 0]
    x0 = pf[k, 1]
    y0 = pf[k, 2]
    a = actions[k]
    ov = _override(k, actions, applied, c)
    s0 = s[k]
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
    s[k] = st[n]
    kk[k] += n
    t = kk[k] * ts
    rxe, rye = path_point(tab, length, s[k])
    xe = px[n - 1]
    ye = py[n - 1]
    etrack = py_hypot(rxe - xe, rye - ye)
    diverged = diverged or etrack > c[4]
    hit = -1
    # The set point's positions rise along the block (a feed and override never negative),
    # so none reaches the end unless the last does: the search is skipped (its second
    # condition keeps it for positions that do not rise).
    if st[n] >= length or not st[n] >= st[0]:
        for j in range(n):
            if st[j + 1] >= length and math.hypot(px[j] - pf[k, 3], py[j] - pf[k, 4]) <= c[3]:
                hit = j
                break
    finished = hit >= 0 and not diverged
    terminated = diverged or finished
    truncated = (not terminated) and t >= pf[k, 7] - 1e-12
    for j in range(n):
        e = eps[j] / tol - 1.0
        tmp[j] = e if (e > 0.0 or e != e) else 0.0
    excess = np_mean(tmp[:n])
    r = w[0] * ds / length - w[1] * (n * ts) / pf[k, 6] - w[2] * excess
    if diverged:
        r -= w[3]
    reward[k] = r
    override[k] = ov
    prev_action[k] = a
    for j in range(n):
        tmp[j] = torque[j, 0] * torque[j, 0] + torque[j, 1] * torque[j, 1]
    tsq = np_mean(tmp[:n])
    peak = row_largest(eps, n)
    o = out[k]
    o[0] = t
    o[1] = cmd[n - 1, 0]
    o[2] = cmd[n - 1, 1]
    o[3] = xe
    o[4] = ye
    o[5] = rxe
    o[6] = rye
    o[7] = eps[n - 1]
    o[8] = peak
    o[9] = etrack
    o[10] = vel[n, 0]
    o[11] = vel[n, 1]
    o[12] = torque[n - 1, 0]
    o[13] = torque[n - 1, 1]
    o[14] = tsq
    o[15] = load[n - 1, 0]
    o[16] = load[n - 1, 1]
    o[17] = ov
    o[18] = ov * pf[k, 5] if s[k] < length else 0.0
    o[19] = s[k]
    o[20] = (kk[k] - n + hit + 1) * ts if finished else np.nan
    segment[k] = path_segment_index(tab, length, s[k])
    flags[k, 0] = diverged
    flags[k, 1] = finished
    flags[k, 2] = terminated
    flags[k, 3] = truncated
    _feed_obs(k, tab, pf, s, override, prev_action, o[7], peak, rxe - xe, rye - ye, o[10],
              o[11], tol, look, lo, hi, obs)  # fmt: skip


@numba.njit(cache=True, _nrt=False, nogil=True)
def _feed_step(lf, li, tabs, pf, load_t, load_v, loops, groups, lane, state, consts, obs,
               flags, out, sc, order):  # fmt: skip
    """One decision step of every lane (``ContouringFeedEnv.step`` after its input checks).

    ``lf`` and ``li`` hold the per-lane floats and integers (columns ``_LF``, ``_LI``),
    ``loops`` the lanes' closed loops (``ServoLanes.buf``), ``groups`` the same eight lanes
    to a row (``ServoLanes.groups``, of all lanes: a block's lanes are ``lane[0]`` on,
    ``lane`` every lane's index),
    ``consts`` the env's constants: ``c`` = ``consts[:8]`` = ``[n_sub, Ts, tolerance,
    in_position, divergence, override mid, override half, actuated]``: where ``actuated``
    is 1 the override is ``applied[k]`` (what the CNC's actuation made of the action's),
    else the action's; then the reward weights ``w``, the lookahead distances and the
    observation's bounds (offsets ``_C_*``). ``flags[k]`` = ``[diverged, finished,
    terminated, truncated]``; ``sc``, ``order`` = float and integer scratch
    (``FeedCore._scratch``). The env calls it through :func:`_feed_step_packed` (one
    table for every argument).

    Each lane's step is its inputs (:func:`_lane_inputs`), its closed loops over the
    block, then its outputs (:func:`_lane_outputs`). One lane (the single env) runs its
    loops by ``run_block``; more run ``LANES`` at a time, their loops side by side
    (``run_lanes``, about six times faster a lane: the same numbers)."""
    actions, applied, s, override, prev_action, reward = (
        lf[:, 0], lf[:, 1], lf[:, 2], lf[:, 3], lf[:, 4], lf[:, 5]
    )  # fmt: skip
    clipped, nseg, n_load, kk, n_clipped, segment = (
        li[:, 0], li[:, 1], li[:, 2], li[:, 3], li[:, 4], li[:, 5]
    )  # fmt: skip
    c = consts[:_C_W]
    w = consts[_C_W:_C_LOOK]
    look = consts[_C_LOOK:_C_LO]
    lo = consts[_C_LO:_C_HI]
    hi = consts[_C_HI : _C_HI + _N_OBS]
    n = int(c[0])
    ts = c[1]
    tol = c[2]
    if actions.shape[0] == 1:  # one lane (the single env): its loops by run_block
        st, rx, ry, px, py, eps, tmp, ref, load, pos, vel, cmd, torque, zb, lower, pts = _carve(
            sc, n, order.size
        )
        ac, bc, cu, du, gu, tq, umax = lane_loops(loops[0])
        k = actions.shape[0] - 1  # lane 0, not the constant 0: each function it reaches
        # would be compiled once more for a constant lane
        _lane_inputs(k, tabs, nseg, pf, actions, applied, clipped, n_clipped, c, s, kk, n_load,
                     load_t, load_v, n, ts, st, rx, ry, ref, load, pts)  # fmt: skip
        run_block(ac, bc, cu, du, gu, tq, umax[0], state[0], ref, load, pos, vel, cmd, torque, zb)
        nan = 0.0  # NaN if a position or velocity is not finite (x - x is 0 for the others)
        for j in range(n):
            for q in range(2):
                nan += (pos[j, q] - pos[j, q]) + (vel[j + 1, q] - vel[j + 1, q])
        _lane_outputs(k, tabs, nseg, pf, actions, applied, c, w, look, lo, hi, tol, s, kk,
                      override, prev_action, reward, segment, state, flags, out, obs, n, ts,
                      (st, rx, ry), (px, py, eps, tmp, lower, order),
                      (pos, vel, cmd, torque, load), nan != nan)  # fmt: skip
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
    g0 = lane[0] // LANES  # the block's first group (blocks start at multiples of LANES)
    for k0 in range(0, actions.shape[0], LANES):
        m = min(LANES, actions.shape[0] - k0)
        for p in range(m):
            _lane_inputs(k0 + p, tabs, nseg, pf, actions, applied, clipped, n_clipped, c, s,
                         kk, n_load, load_t, load_v, n, ts, gst[p], grx[p], gry[p],
                         ref3[:, :, p], load3[:, :, p], pts)  # fmt: skip
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
            _lane_outputs(k0 + p, tabs, nseg, pf, actions, applied, c, w, look, lo, hi, tol, s,
                          kk, override, prev_action, reward, segment, state, flags, out, obs, n,
                          ts, (gst[p], grx[p], gry[p]), (px, py, eps, tmp, lower, order),
                          (pos3[:, :, p], vel3[:, :, p], cmd3[:, :, p], torque3[:, :, p],
                           load3[:, :, p]), nan[p] != nan[p])  # fmt: skip


@numba.njit(cache=True, nogil=True)
def _feed_step_packed(t):
    """:func:`_feed_step` with its arguments in one table (``core.compiled.packed``): what every
    step calls (one array to unbox, not one per argument)."""
    _feed_step(f8_2(t, 0), i8_2(t, 1), f8_3(t, 2), f8_2(t, 3), f8_2(t, 4), f8_3(t, 5), f8_2(t, 6),
               f8_2(t, 7), i8_1(t, 8), f8_2(t, 9), f8_1(t, 10), f4_2(t, 11), b1_2(t, 12),
               f8_2(t, 13), f8_1(t, 14), i8_1(t, 15))  # fmt: skip


@numba.njit(cache=True, nogil=True)
def _serve_feed_step(ctl, table, polls):
    """The lane blocks' worker loop for :func:`_feed_step_packed` (``core.compiled.blocks``),
    compiled with this module and cached, not at the first step on several threads."""
    return serve_one_table(_feed_step_packed, ctl, table, polls)


#: Where :func:`_feed_step`'s arguments (``FeedCore._args``) hold the lanes: axis 0, none
#: (shared) or scratch space, for :class:`~machining_envs.core.compiled.blocks.LaneBlocks`.
_STEP_AXES = (
    0, 0, 0, 0, 0, 0, 0, None, 0, 0, None, 0, 0, 0, SCRATCH, SCRATCH,  # _feed_step's
    0, 0, 0, None, None, None, None, None, None, None, None, None,  # the start's (_F_START)
)  # fmt: skip
#: Where the kernel's table (``FeedCore._args``) holds, after :func:`_feed_step`'s
#: arguments, what a batch's start (:func:`_start_batch`) writes besides or reads: the
#: score bounds, whether each lane's path is a circle and its circle, the start's
#: constants (``FeedCore._start_consts``) and both axes' designs (``A``, ``B``, ``C``,
#: ``D`` of X, then of Y).
_F_START = 16
# The kernel's blocks of lanes start at multiples of ALIGN, and so at a group's first lane:
# a block reads its groups' coefficients from its first lane's group on (lane[0]).
assert ALIGN % LANES == 0


@numba.njit(cache=True)
def _feed_reset_obs(k, tabs, nseg, pf, s, override, prev_action, tol, look, lo, hi, obs):
    """The first observation of lane ``k``'s episode (table at rest at the path's start)."""
    _feed_obs(k, tabs[k, : nseg[k]], pf, s, override, prev_action, 0.0, 0.0, 0.0, 0.0, 0.0,
              0.0, tol, look, lo, hi, obs)  # fmt: skip


@numba.njit(cache=True)
def _start_drawn_lanes(lanes, ints, floats, drawn_tabs, feed, t_load, t_max, override_max,
                       tabs, nseg, pf, bound, load_t, load_v, n_load, lf, li, state, out, flags,
                       tol, look, lo, hi, obs):  # fmt: skip
    """:meth:`FeedCore.start`'s arrays for every lane ``lanes[i]`` of a split's batch, from
    its drawn numbers (``_RandomPaths.draw_lanes``: ``ints``, ``floats``, the tables, feeds
    and load times), in ``start``'s arithmetic; ``t_max`` NaN: the time limit from the
    programmed time. The servo loops are started apart (:func:`_start_batch`)."""
    s, override, prev_action = lf[:, 2], lf[:, 3], lf[:, 4]
    in_clipped, kk, n_clipped, segment = li[:, 0], li[:, 3], li[:, 4], li[:, 5]
    for i in range(lanes.size):
        k = lanes[i]
        n = ints[i, 0]
        for r in range(tabs.shape[1]):
            for c in range(tabs.shape[2]):
                tabs[k, r, c] = drawn_tabs[i, r, c] if r < n else 0.0
        nseg[k] = n
        f = floats[i]
        length = f[_D_LENGTH]
        x0 = f[_D_X0]
        y0 = f[_D_Y0]
        prog = length / feed[i]
        p = pf[k]
        p[0] = length
        p[1] = x0
        p[2] = y0
        p[3] = f[_D_XE]
        p[4] = f[_D_YE]
        p[5] = feed[i]
        p[6] = prog
        p[7] = 5.0 * prog + 0.5 if t_max != t_max else t_max
        bound[k] = length / (override_max * feed[i])
        for q in range(load_t.shape[1]):
            load_t[k, q] = np.inf
        for q in range(load_v.shape[1]):
            load_v[k, q, 0] = 0.0
            load_v[k, q, 1] = 0.0
        if ints[i, 1]:
            load_t[k, 0] = t_load[i]
            load_v[k, 1, 0] = f[_D_A]
            load_v[k, 1, 1] = f[_D_B]
        n_load[k] = 1
        s[k] = 0.0
        kk[k] = 0
        override[k] = 0.0
        prev_action[k] = -1.0
        n_clipped[k] = 0
        for q in range(state.shape[1]):
            state[k, q] = 0.0
        _feed_reset_obs(k, tabs, nseg, pf, s, override, prev_action, tol, look, lo, hi, obs)
        tab = tabs[k, :n]
        rx, ry = path_point(tab, length, 0.0)
        o = out[k]
        for q in range(o.shape[0]):
            o[q] = 0.0
        o[3] = x0
        o[4] = y0
        o[5] = rx
        o[6] = ry
        o[18] = 0.0 * feed[i] if 0.0 < length else 0.0
        o[20] = np.nan
        for q in range(flags.shape[1]):
            flags[k, q] = False
        in_clipped[k] = 0
        segment[k] = path_segment_index(tab, length, 0.0)


@numba.njit(cache=True)
def _start_batch(t, lanes, ints, floats, drawn_tabs, feed, scale):
    """:meth:`FeedCore.start_lanes`' arrays for every lane ``lanes[i]`` of a split's batch
    from its drawn numbers (``_RandomPaths.draw_lanes``), in one call on the kernel's
    table ``t``: its servo loops on the nominal plant with the inertias scaled by
    ``scale[i]`` (``ServoLanes.start_scaled``'s numbers), then :func:`_start_drawn_lanes`;
    the lane's path is no circle (paths of several segments)."""
    lf, li, tabs, pf = f8_2(t, 0), i8_2(t, 1), f8_3(t, 2), f8_2(t, 3)
    load_t, load_v, buf, groups = f8_2(t, 4), f8_3(t, 5), f8_2(t, 6), f8_2(t, 7)
    state, consts, obs, flags, out = f8_2(t, 9), f8_1(t, 10), f4_2(t, 11), b1_2(t, 12), f8_2(t, 13)
    o = _F_START
    bound, has_circle, circle, sc = f8_1(t, o), b1_1(t, o + 1), f8_2(t, o + 2), f8_1(t, o + 3)
    designs = (
        (f8_2(t, o + 4), f8_2(t, o + 5), f8_2(t, o + 6), f8_2(t, o + 7)),
        (f8_2(t, o + 8), f8_2(t, o + 9), f8_2(t, o + 10), f8_2(t, o + 11)),
    )
    m = lanes.size
    t_load = np.empty(m)
    for i in range(m):
        f = floats[i]
        t_load[i] = load_time(f[_D_LENGTH], feed[i], f[_D_T])
    start_scaled_loops(lanes, sc[:_S_TMAX], scale, designs, buf, groups)
    _start_drawn_lanes(
        lanes, ints, floats, drawn_tabs, feed, t_load, sc[_S_TMAX], sc[_S_OVERRIDE], tabs,
        li[:, 1], pf, bound, load_t, load_v, li[:, 2], lf, li, state, out, flags, consts[2],
        consts[_C_LOOK:_C_LO], consts[_C_LO:_C_HI], consts[_C_HI : _C_HI + _N_OBS], obs,
    )  # fmt: skip
    for i in range(m):
        has_circle[lanes[i]] = False
        for q in range(3):
            circle[lanes[i], q] = 0.0


#: ``FeedCore._start_consts``: the nominal plant's numbers (``NOMINAL_LOOP_NUMBERS``), then
#: the time limit (NaN: from the programmed time) and the largest override.
_S_TMAX = len(NOMINAL_LOOP_NUMBERS)
_S_OVERRIDE = _S_TMAX + 1


#: The float keys between the flags and ``segment`` in the info's order.
_INFO_OUT = (*_OUT[3:-1], "contour_tolerance_mm", "cost", "score_bound", "path_length_mm")
#: The float keys of a vector step's info, one row each of the table :func:`_info_rows`
#: fills (``FeedCore.info_arrays``).
_INFO_F = ("t_s", "command_x_mm_s", "command_y_mm_s", *_INFO_OUT, "feed_mm_s",
           "programmed_time_s", "time_limit_s", "machining_time_s")  # fmt: skip


#: The boolean and integer keys of a vector step's info, one row each of the tables
#: :func:`_info_rows` fills (``_machining_time_s``: the lanes that finished).
_INFO_B = ("action_clipped", "breakage", "diverged", "finished", "_machining_time_s")
_INFO_I = ("n_action_clipped", "segment")


@numba.njit(cache=True)
def _info_rows(out, pf, bound, flags, li, tol, rows, command, bits, ints):
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
        rows[4 + m, k] = 1.0 if o[8] > tol else 0.0
        rows[5 + m, k] = bound[k]
        rows[6 + m, k] = pf[k, 0]
        rows[7 + m, k] = pf[k, 5]
        rows[8 + m, k] = pf[k, 6]
        rows[9 + m, k] = pf[k, 7]
        rows[10 + m, k] = o[20] if flags[k, 1] else np.nan
        bits[0, k] = li[k, 0] != 0
        bits[1, k] = False
        bits[2, k] = flags[k, 0]
        bits[3, k] = flags[k, 1]
        bits[4, k] = flags[k, 1]
        ints[0, k] = li[k, 4]
        ints[1, k] = li[k, 5]


class FeedCore(LaneCore):
    """The state and arithmetic of N ContouringFeed-v0 episodes, shared by
    ``ContouringFeedEnv`` (one lane) and ``ContouringFeedVectorEnv`` (N lanes): each lane's
    path (``Path.table``), loads and closed loops (``ServoLanes``), advanced by one compiled
    function (:func:`_feed_step`), so that a lane and the single env agree to the last bit."""

    #: What a scenario may be: an object of this class or one of these names.
    scenario_types = (ContouringScenario, CONTOURING_SCENARIOS)
    VIEWS = frozenset({*_LF, *_LI, "_c", "_lo", "_hi", "_args"})

    def __init__(self, owner, n, scenario, params, servo, tolerance_mm, reward,
                 decision_interval_s, override_max, max_episode_time_s, in_position_mm,
                 divergence_mm, overrides, actuation=None):  # fmt: skip
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
        # The kernel's constants (_C_* offsets), with the bounds as the observation clips to
        # them (Python floats of the float32 box); named by views.
        self.consts = np.array([
            n_sub, ts, self.tolerance_mm, self.in_position_mm, self.divergence_mm, cm.mid,
            cm.half, 0.0, w.progress, w.time, w.tolerance, w.divergence, *LOOKAHEAD_MM,
            *low.tolist(), *high.tolist(),
        ])  # fmt: skip
        self.n = n
        # Per-lane floats and integers, each set in one array (one argument of the kernel)
        # and named by views of its columns (_LF, _LI).
        self.lf = np.zeros((n, len(_LF)))
        self.li = np.zeros((n, len(_LI)), dtype=np.int64)
        self.bind_views()
        self.prev_action[:] = -1.0
        # The CNC's override handling, made now if the option sets it (its checks fail
        # here), else when a scenario first brings its own.
        self.act_lanes = None if self.actuation is None else self.actuation_lanes()
        self.nseg[:] = 1
        self.loops = ServoLanes(designs, n_sub, n)
        self.lane = np.arange(n)  # each lane's index (the kernel's blocks read theirs)
        self.state = np.zeros((n, 2 * self.loops.n_states_axis))
        self.tabs = np.zeros((n, 4, SEGMENT_COLUMNS))
        self.pf = np.ones((n, len(_PF)))
        self.bound = np.full(n, np.nan)
        self.load_t = np.full((n, 1), np.inf)
        self.load_v = np.zeros((n, 2, 2))
        self.obs = np.zeros((n, 16), dtype=np.float32)
        self.flags = np.zeros((n, 4), dtype=np.bool_)
        self.out = np.zeros((n, len(_OUT)))
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
        self._start_consts = np.array([  # (_S_*)
            *(getattr(p, name) for name in NOMINAL_LOOP_NUMBERS),
            math.nan if t_max is None else float(t_max), self.override_max,
        ])  # fmt: skip
        n_seg = self.tabs.shape[1]
        self._scratch = (self._float_scratch(n_seg), np.zeros(n_seg, dtype=np.int64))
        self._packed = PackedArgs()  # the kernel's arguments in one table (core.compiled.packed)
        #: The blocks of lanes the kernel steps at once (one thread unless a vector env
        #: asks for more).
        self.blocks = LaneBlocks(n)
        self._bind()

    def bind_views(self) -> None:
        """Name the columns of ``lf`` (``_LF``), ``li`` (``_LI``) and ``consts``."""
        for i, name in enumerate(_LF):
            setattr(self, name, self.lf[:, i])
        for i, name in enumerate(_LI):
            setattr(self, name, self.li[:, i])
        self._c = self.consts[:_C_W]
        self._lo = self.consts[_C_LO:_C_HI]
        self._hi = self.consts[_C_HI:]

    def __setstate__(self, state: dict) -> None:
        state["servos"].flags.writeable = False  # (a pickle's array is writable)
        super().__setstate__(state)
        self._bind()

    def _float_scratch(self, n_seg: int) -> np.ndarray:
        return np.zeros(_scratch_size(self.n_sub, n_seg, self.n > 1))

    def actuation_lanes(self) -> ActuationLanes:
        """The CNC's actuation between the actions and the override, for every lane (a lane
        without settings passes its override unchanged)."""
        self._c[7] = 1.0
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
        _feed_reset_obs(lane, self.tabs, self.nseg, self.pf, self.s, self.override,
                        self.prev_action, self.tolerance_mm, self.consts[_C_LOOK:_C_LO],
                        self._lo, self._hi, self.obs)  # fmt: skip
        rx, ry = path.point(0.0)
        o = self.out[lane]
        o[:] = 0.0
        o[_O["x_mm"]], o[_O["y_mm"]] = x0, y0
        o[_O["x_ref_mm"]], o[_O["y_ref_mm"]] = rx, ry
        o[_O["path_speed_mm_s"]] = 0.0 * sc.feed_mm_s if 0.0 < path.length else 0.0
        o[_O["machining_time_s"]] = np.nan
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
        ks = settle_batch(self, lanes, factory.build_lane, (drawn,), factory.actuation,
                          factory.name)  # fmt: skip
        if self._circles:  # the batch's paths are no circles
            self._circles -= int(np.count_nonzero(self.has_circle[lanes]))
        _start_batch(self._packed(self._args), lanes, drawn.ints, drawn.floats, drawn.tabs,
                     drawn.feed, drawn.scale)  # fmt: skip
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
        ok = self._batch_ok.get(factory)
        if ok is None:
            try:
                for sc in factory.extremes:
                    check_feed(sc, self.params)
                ok = True
            except ValueError:
                ok = False
            self._batch_ok[factory] = ok
        return ok

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
            asked = self._c[5] + self._c[6] * self.in_action
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
        self._args = (
            self.lf, self.li, self.tabs, self.pf, self.load_t, self.load_v, self.loops.buf,
            self.loops.groups, self.lane, self.state, self.consts, self.obs, self.flags,
            self.out,
            *self._scratch,
            # what a batch's start writes besides or reads (_F_START)
            self.bound, self.has_circle, self.circle, self._start_consts,
            *(m for axis in self.loops._design_arrays for m in axis),
        )  # fmt: skip

    def lane_info(self, k: int) -> dict:
        """The info of lane ``k`` after its reset or its last step."""
        out = self.out[k]
        o = out.tolist()
        diverged, finished, _, _ = self.flags[k].tolist()
        in_clipped, _, _, _, n_clipped, segment = self.li[k].tolist()  # _LI
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
            "x_mm": o[3],
            "y_mm": o[4],
            "x_ref_mm": o[5],
            "y_ref_mm": o[6],
            "contour_error_mm": o[7],
            "peak_contour_error_mm": o[8],
            "tracking_error_mm": o[9],
            "cost": 1.0 if o[8] > self.tolerance_mm else 0.0,
            "vx_mm_s": o[10],
            "vy_mm_s": o[11],
            "torque_x_Nm": o[12],
            "torque_y_Nm": o[13],
            "torque_sq_Nm2": o[14],
            "load_x_Nm": o[15],
            "load_y_Nm": o[16],
            "feed_override": o[17],
            "path_speed_mm_s": o[18],
            "path_s_mm": o[19],
            "segment": segment,
            **self._episode_info(k),
        }
        if finished:
            info["machining_time_s"] = o[20]
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
        _info_rows(self.out, self.pf, self.bound, self.flags, self.li, self.tolerance_mm, rows,
                   command, bits, ints)  # fmt: skip
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
