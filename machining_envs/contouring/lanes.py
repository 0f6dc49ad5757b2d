"""The engine of ``Contouring-v0``: the reward weights, the lane tables and the compiled
step and start of N XY tables, which :class:`ContouringEnv` (one lane) and
:class:`ContouringVectorEnv` (N lanes) drive."""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from enum import IntEnum

import numba
import numpy as np
from gymnasium import spaces

from machining_envs.contouring._exact import py_hypot
from machining_envs.contouring.paths import (
    SEGMENT_COLUMNS,
    Path,
    path_distance,
    path_point,
    path_segment_index,
)
from machining_envs.contouring.plant import (
    PLANT_COLUMNS,
    ContouringParams,
    ContouringPlant,
    step_axes,
)
from machining_envs.contouring.scenarios import (
    CONTOURING_SCENARIOS,
    ContouringScenario,
    check_feed,
    contouring_scenario,
)
from machining_envs.core.actions import ActionMap
from machining_envs.core.checks import PY_NUMBER_TYPES, check_range, is_real
from machining_envs.core.compiled.blocks import LaneBlocks, serve_one_table
from machining_envs.core.compiled.kernels import py_square
from machining_envs.core.compiled.packed import PackedArgs, b1_2, f4_2, f8_1, f8_2, f8_3, i8_1, i8_2
from machining_envs.core.env import (
    check_scenario_spec,
    resolve_params,
)
from machining_envs.core.lanes import LaneCore, LaneNames
from machining_envs.core.reward import resolve_reward

ERROR_SCALE_MM = 1.0
#: Positions (the set point) in observations are divided by this, mm.
POSITION_SCALE_MM = 100.0
#: Velocities in observations are divided by this, mm/s.
VELOCITY_SCALE_MM_S = 100.0
#: Contour-error tolerance of Contouring-v0, mm (a finishing tolerance, the reward's
#: ``contour_scale_mm``): ``info["cost"]`` is 1 on a servo period whose contour error is
#: above it. The score is the largest contour error itself; the floor of a contour error
#: is zero, so the env reports no ``score_bound``.
CONTOUR_TOLERANCE_MM = 0.01
#: The observation previews the set point this many servo periods ahead (0.2, 2 and 10 ms
#: at 5 kHz), as the mean reference velocity over each horizon.
PREVIEW_TICKS = (1, 10, 50)
_P0, _P1, _P2 = PREVIEW_TICKS

#: The signals the contouring envs' render() draws: name -> the info key each is read from.
TRACE_LOG_FIELDS = {"t": "t_s", "x": "x_mm", "y": "y_mm", "eps": "contour_error_mm"}

_ERR_LIM = 100.0
_VEL_LIM = 10.0
_POS_LIM = 20.0
_PRE_LIM = 20.0


@dataclass(frozen=True)
class ContouringReward:
    r"""Weights of the Contouring-v0 reward (see :class:`ContouringEnv`, section Rewards).

    .. math::

        r = -w_c \frac{\varepsilon}{\varepsilon_0} - w_t \frac{|e|}{e_0}
            - w_u \sum_{i=x,y} \left(\frac{\tau_i}{\tau_0}\right)^2 - w_d [\text{diverged}]

    with the contour error ``epsilon``, the tracking error ``|e| = |r - p|`` and the motor
    torques ``tau``.
    """

    contour: float = 1.0
    """w_c, weight of the contour error."""
    contour_scale_mm: float = 0.01
    """epsilon_0, mm: 10 um, a finishing tolerance."""
    tracking: float = 0.01
    """w_t, weight of the tracking error. Small but not zero: the contour error alone is
    zero for a table that never leaves the path's start."""
    tracking_scale_mm: float = 1.0
    """e_0, mm."""
    effort: float = 0.001
    """w_u, weight of the squared motor torques (the control effort the drive pays)."""
    torque_scale_Nm: float = 5.4
    """tau_0, N m: the rated torque of a 0.85 kW servo motor."""
    divergence: float = 100.0
    """w_d, one-off penalty when the run diverges."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            ok = is_real(v, PY_NUMBER_TYPES) and math.isfinite(v) and v >= 0
            if f.name.endswith(("_mm", "_Nm")):
                ok = ok and v > 0
            if not ok:
                raise ValueError(
                    f"reward field {f.name} must be a finite number >= 0 "
                    f"(> 0 for scales), got {v!r}"
                )


#: ``positive_setting(name, value, lo, hi)``: ``value`` as a float if it is a Python number in
#: ``(lo, hi]``, else ``ValueError`` (the contouring envs' keyword checks).
positive_setting = functools.partial(check_range, lo_open=True, types=PY_NUMBER_TYPES)


def run_limits(
    max_episode_time_s, in_position_mm, divergence_mm
) -> tuple[float | None, float, float]:
    """The keywords that end a contouring run, checked: ``(max_episode_time_s or None,
    in_position_mm, divergence_mm)`` as floats."""
    return (
        None
        if max_episode_time_s is None
        else positive_setting("max_episode_time_s", max_episode_time_s, 0.0, 1e4),
        positive_setting("in_position_mm", in_position_mm, 0.0, 10.0),
        positive_setting("divergence_mm", divergence_mm, 0.0, 1e4),
    )


def circle_info(path: Path) -> dict:
    """The circle's centre and radius for a one-arc path (a circle test), else nothing."""
    c = path.circle()
    if c is None:
        return {}
    return {"circle_cx_mm": c[0], "circle_cy_mm": c[1], "circle_radius_mm": c[2]}


# ---- the compiled step of every lane ------------------------------------------------------
#
# Per lane, ``lf`` holds the floats: the plant's numbers (``PLANT_COLUMNS``), its state
# ``[x, vx, y, vy]``, the path's length, the set point's advance per period, whether the
# run is a step command, the path's end, the time from which the run may finish, the load
# torques now and the previous action; ``li`` the integers. The set points ahead (``_RING``
# of them, the preview's horizon included) are kept in a ring ``rb[lane, k % _RING] = [x,
# y]``. Each table's columns are named once (an IntEnum: constants to the compiler).


class _LF(IntEnum):
    """Columns of ``ContouringCore.lf`` from the plant's state on (the plant's numbers
    fill those before it; ``ContouringCore.start`` writes a lane's row in this order)."""

    Z = PLANT_COLUMNS  # the state [x, vx, y, vy]
    LEN = Z + 4  # the path's length
    FTS = LEN + 1  # the set point's advance per period
    STEP = FTS + 1  # whether the run is a step command
    END = STEP + 1  # the path's end (x, y)
    FIN = END + 2  # the time from which the run may finish
    LOAD = FIN + 1  # the load torques now (x, y)
    PREV = LOAD + 2  # the previous action (x, y)


_NLF = _LF.PREV + 2
#: Columns of ``ContouringCore.li``: the period, the next load step, the load steps, the
#: periods' limit, the clipped actions, the path's segment.
_LI = IntEnum("_LI", "K LOAD NLOAD NMAX CLIP SEG", start=0)
_CIRCLE_KEYS = ("circle_cx_mm", "circle_cy_mm", "circle_radius_mm")
_RING = 64
#: Columns of ``ContouringCore.out`` (the step's signals, read into ``info``).
_Out = IntEnum(
    "_Out",
    "reward t_s command_x_mm_s command_y_mm_s x_mm y_mm x_ref_mm y_ref_mm contour_error_mm"
    " tracking_error_mm vx_mm_s vy_mm_s torque_x_Nm torque_y_Nm torque_sq_Nm2 load_x_Nm"
    " load_y_Nm path_s_mm machining_time_s",
    start=0,
)
_OUT = tuple(_Out.__members__)


def _ints(columns: type[IntEnum]) -> type:
    """``columns``' members as plain ints (class attributes), for the Python side: numpy
    takes an IntEnum member as an index by its slow path, and reading a member costs more
    than a class attribute (together some 10 % of a single env's step)."""
    return type(f"{columns.__name__}I", (), {c.name: int(c) for c in columns})


_LFI, _LII, _OutI = _ints(_LF), _ints(_LI), _ints(_Out)
#: The step's signals in ``out`` from ``x_mm`` to ``path_s_mm``, info's keys, and their
#: columns.
_SIGNALS = _OUT[_Out.x_mm : _Out.machining_time_s]
_SIGNAL_COLUMNS = slice(_OutI.x_mm, _OutI.machining_time_s)
#: Columns of ``ContouringCore.flags``.
_Flag = IntEnum("_Flag", "diverged finished terminated truncated clipped", start=0)


@numba.njit(cache=True)
def _path_s(k, lf, lane):
    """Arc length of set point ``k`` (``ContouringEnv``'s schedule: ``min(k F Ts, L)``, or
    the path's end for a step command)."""
    length = lf[lane, _LF.LEN]
    if lf[lane, _LF.STEP]:
        return length
    return min(float(k) * lf[lane, _LF.FTS], length)


@numba.njit(cache=True)
def _set_point(k, lane, tab, lf, rb):
    """Set point ``k`` of ``lane`` into its ring."""
    x, y = path_point(tab, lf[lane, _LF.LEN], _path_s(k, lf, lane))
    r = rb[lane, k % _RING]
    r[0] = x
    r[1] = y


class _CF(IntEnum):
    """Entries of ``ContouringCore.cf``: the sample time, the nominal command limit, the
    in-position and divergence distances, the reward weights from ``W`` on (contour weight
    and scale, tracking weight and scale, effort weight, torque scale, divergence weight),
    the preview's scales (three) from ``PRE`` on, and the exponent 2 (read at run time:
    CPython's ``x ** 2`` is ``pow``)."""

    TS = 0
    UMAX = 1
    INPOS = 2
    DIV = 3
    W = 4
    PRE = W + 7
    TWO = PRE + 3


@numba.njit(cache=True)
def _contour_obs(lane, k, x, y, vx, vy, lf, cf, rb, obs):
    """Observation of ``lane`` at period ``k`` (``ContouringEnv``'s table) into ``obs``."""
    ring = rb[lane]
    r0 = ring[k % _RING]
    r0x = r0[0]
    r0y = r0[1]
    o = obs[lane]
    ex = (r0x - x) / ERROR_SCALE_MM
    ey = (r0y - y) / ERROR_SCALE_MM
    o[0] = min(max(ex, -_ERR_LIM), _ERR_LIM)
    o[1] = min(max(ey, -_ERR_LIM), _ERR_LIM)
    o[2] = min(max(vx / VELOCITY_SCALE_MM_S, -_VEL_LIM), _VEL_LIM)
    o[3] = min(max(vy / VELOCITY_SCALE_MM_S, -_VEL_LIM), _VEL_LIM)
    o[4] = min(max(r0x / POSITION_SCALE_MM, -_POS_LIM), _POS_LIM)
    o[5] = min(max(r0y / POSITION_SCALE_MM, -_POS_LIM), _POS_LIM)
    for i in range(3):
        ahead = ring[(k + _PTICKS[i]) % _RING]
        o[6 + i] = (ahead[0] - r0x) * cf[_CF.PRE + i]
        o[9 + i] = (ahead[1] - r0y) * cf[_CF.PRE + i]
    o[12] = lf[lane, _LF.PREV]
    o[13] = lf[lane, _LF.PREV + 1]


_PTICKS = np.array(PREVIEW_TICKS)


@numba.njit(cache=True, inline="always")
def _load_steps(lane, t, lfl, li, loads):
    """The load torques of ``lane`` (``lfl``: its row of ``lf``) at time ``t``: its load
    steps due by then, from the next one (``li``'s ``LOAD``) on."""
    i = li[lane, _LI.LOAD]
    nl = li[lane, _LI.NLOAD]
    while i < nl and loads[lane, i, 0] <= t + 1e-12:
        lfl[_LF.LOAD] = loads[lane, i, 1]
        lfl[_LF.LOAD + 1] = loads[lane, i, 2]
        i += 1
    li[lane, _LI.LOAD] = i


@numba.njit(cache=True, _nrt=False, nogil=True)
def _contour_step(act, clipped, lf, li, cf, tabs, nseg, rb, loads, obs, out, flags):
    """One servo period of every lane (``ContouringEnv.step`` after its input checks).

    ``act`` holds finite actions; one outside the box is clipped here (and ``clipped[lane]``
    set, as it is already where the caller clipped it). ``flags[k]`` = ``[diverged,
    finished, terminated, truncated, action clipped]``."""
    ts = cf[_CF.TS]
    umax = cf[_CF.UMAX]
    two = cf[_CF.TWO]
    for lane in range(act.shape[0]):
        ax = act[lane, 0]
        ay = act[lane, 1]
        if not (-1.0 <= ax <= 1.0 and -1.0 <= ay <= 1.0):  # finite here: clip to the box
            ax = min(max(ax, -1.0), 1.0)
            ay = min(max(ay, -1.0), 1.0)
            act[lane, 0] = ax
            act[lane, 1] = ay
            clipped[lane] = True
        li[lane, _LI.CLIP] += clipped[lane]
        ux = ax * umax
        uy = ay * umax
        k = li[lane, _LI.K]
        lfl = lf[lane]
        if li[lane, _LI.LOAD] < li[lane, _LI.NLOAD]:
            _load_steps(lane, k * ts, lfl, li, loads)
        lx = lfl[_LF.LOAD]
        ly = lfl[_LF.LOAD + 1]
        z = lfl[_LF.Z : _LF.Z + 4]
        tx, ty = step_axes(lfl, z, ux, uy, lx, ly)
        k += 1
        li[lane, _LI.K] = k
        tab = tabs[lane, : nseg[lane]]
        _set_point(k + _PTICKS[2], lane, tab, lf, rb)
        t = k * ts
        x = z[0]
        y = z[2]
        vx = z[1]
        vy = z[3]
        diverged = not (np.isfinite(x) and np.isfinite(y) and np.isfinite(vx) and np.isfinite(vy))
        r = rb[lane, k % _RING]
        rx = r[0]
        ry = r[1]
        if diverged:  # kept so that no NaN can reach an observation or a reward
            x = rx
            y = ry
            vx = vy = tx = ty = 0.0
            z[0] = rx
            z[1] = 0.0
            z[2] = ry
            z[3] = 0.0
        etrack = py_hypot(rx - x, ry - y)
        eps = path_distance(tab, x, y)
        diverged = diverged or etrack > cf[_CF.DIV]
        finished = (
            t >= lfl[_LF.FIN] - 1e-12
            and py_hypot(x - lfl[_LF.END], y - lfl[_LF.END + 1]) <= cf[_CF.INPOS]
        )
        terminated = diverged or finished
        truncated = (not terminated) and k >= li[lane, _LI.NMAX]
        t0 = cf[_CF.W + 5]
        rew = (
            -cf[_CF.W] * eps / cf[_CF.W + 1]
            - cf[_CF.W + 2] * etrack / cf[_CF.W + 3]
            - cf[_CF.W + 4] * (py_square(tx / t0, two) + py_square(ty / t0, two))
        )
        if diverged:
            rew -= cf[_CF.W + 6]
        lfl[_LF.PREV] = ax
        lfl[_LF.PREV + 1] = ay
        o = out[lane]
        o[_Out.reward] = rew
        o[_Out.t_s] = t
        o[_Out.command_x_mm_s] = ux
        o[_Out.command_y_mm_s] = uy
        o[_Out.x_mm] = x
        o[_Out.y_mm] = y
        o[_Out.x_ref_mm] = rx
        o[_Out.y_ref_mm] = ry
        o[_Out.contour_error_mm] = eps
        o[_Out.tracking_error_mm] = etrack
        o[_Out.vx_mm_s] = vx
        o[_Out.vy_mm_s] = vy
        o[_Out.torque_x_Nm] = tx
        o[_Out.torque_y_Nm] = ty
        o[_Out.torque_sq_Nm2] = tx * tx + ty * ty
        o[_Out.load_x_Nm] = lx
        o[_Out.load_y_Nm] = ly
        sk = _path_s(k, lf, lane)
        o[_Out.path_s_mm] = sk
        o[_Out.machining_time_s] = t if finished else np.nan
        li[lane, _LI.SEG] = path_segment_index(tab, lfl[_LF.LEN], sk)
        f = flags[lane]
        f[_Flag.diverged] = diverged
        f[_Flag.finished] = finished
        f[_Flag.terminated] = terminated
        f[_Flag.truncated] = truncated
        f[_Flag.clipped] = clipped[lane]
        _contour_obs(lane, k, x, y, vx, vy, lf, cf, rb, obs)


@numba.njit(cache=True, nogil=True)
def _contour_step_packed(t):
    """:func:`_contour_step` with its arguments in one table (``core.compiled.packed``): what every
    step calls (one array to unbox, not one per argument)."""
    lanes = (f8_2(t, 0), i8_1(t, 1), f8_2(t, 2), i8_2(t, 3), f8_1(t, 4), f8_3(t, 5))
    rest = (i8_1(t, 6), f8_3(t, 7), f8_3(t, 8), f4_2(t, 9), f8_2(t, 10), b1_2(t, 11))
    _contour_step(*(lanes + rest))


@numba.njit(cache=True, nogil=True)
def _serve_contour_step(ctl, table, polls):
    """The lane blocks' worker loop for :func:`_contour_step_packed` (``core.compiled.blocks``),
    compiled with this module and cached, not at the first step on several threads."""
    return serve_one_table(_contour_step_packed, ctl, table, polls)


#: Where :func:`_contour_step`'s arguments (``ContouringCore._args``) hold the lanes: axis
#: 0 or none (shared), for :class:`~machining_envs.core.compiled.blocks.LaneBlocks`.
_STEP_AXES = (0, 0, 0, 0, None, 0, 0, 0, 0, 0, 0, 0)


@numba.njit(cache=True)
def _contour_start(lane, lf, li, cf, tabs, nseg, rb, loads, obs, out, flags):
    """Set points ``0 .. 50``, the load at ``t = 0``, the first observation and the reset
    signals of ``lane`` (the rest of ``lf`` and ``li`` already set)."""
    tab = tabs[lane, : nseg[lane]]
    for k in range(_PTICKS[2] + 1):
        _set_point(k, lane, tab, lf, rb)
    lfl = lf[lane]
    li[lane, _LI.LOAD] = 0
    _load_steps(lane, 0.0, lfl, li, loads)
    x0 = lfl[_LF.Z]
    y0 = lfl[_LF.Z + 2]
    r = rb[lane, 0]
    o = out[lane]
    o[:] = 0.0
    o[_Out.x_mm] = x0
    o[_Out.y_mm] = y0
    o[_Out.x_ref_mm] = r[0]
    o[_Out.y_ref_mm] = r[1]
    o[_Out.tracking_error_mm] = py_hypot(r[0] - x0, r[1] - y0)
    o[_Out.load_x_Nm] = lfl[_LF.LOAD]
    o[_Out.load_y_Nm] = lfl[_LF.LOAD + 1]
    sk = _path_s(0, lf, lane)
    o[_Out.path_s_mm] = sk
    o[_Out.machining_time_s] = np.nan
    li[lane, _LI.SEG] = path_segment_index(tab, lfl[_LF.LEN], sk)
    flags[lane, :] = False
    _contour_obs(lane, 0, x0, y0, 0.0, 0.0, lf, cf, rb, obs)


class ContouringCore(LaneCore):
    """The state and arithmetic of N Contouring-v0 episodes, shared by ``ContouringEnv``
    (one lane) and ``ContouringVectorEnv`` (N lanes): each lane's table
    (:func:`~machining_envs.contouring.plant.step_axes`), path (``Path.table``), set points
    and loads, advanced by one compiled function (:func:`_contour_step`), so that a lane
    and the single env agree to the last bit."""

    #: What a scenario may be: an object of this class or one of these names.
    scenario_types = (ContouringScenario, CONTOURING_SCENARIOS)

    def __init__(
        self,
        owner: str,
        n: int,
        scenario: str | ContouringScenario,
        *,
        params: ContouringParams | None,
        reward: ContouringReward | dict | None,
        max_episode_time_s: float | None,
        in_position_mm: float,
        divergence_mm: float,
        overrides: dict,
    ) -> None:
        self.params = resolve_params(
            owner, params, ContouringParams, ContouringParams.choi_et_al, overrides
        )
        self.reward_weights = resolve_reward(reward, ContouringReward)
        self.max_episode_time_s, self.in_position_mm, self.divergence_mm = run_limits(
            max_episode_time_s, in_position_mm, divergence_mm
        )
        check_scenario_spec(scenario, ContouringScenario, CONTOURING_SCENARIOS)
        umax = self.params.command_max_mm_s
        self.command_map = ActionMap(-umax, umax)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        lim = [_ERR_LIM] * 2 + [_VEL_LIM] * 2 + [_POS_LIM] * 2 + [_PRE_LIM] * 6 + [1.0] * 2
        high = np.array(lim, dtype=np.float32)
        self.observation_space = spaces.Box(-high, high, dtype=np.float32)
        ts = self.params.sample_time_s
        w = self.reward_weights
        limits = (ts, umax, self.in_position_mm, self.divergence_mm)
        weights = (w.contour, w.contour_scale_mm, w.tracking, w.tracking_scale_mm, w.effort)
        weights += (w.torque_scale_Nm, w.divergence)
        preview = tuple(1.0 / (k * ts * VELOCITY_SCALE_MM_S) for k in PREVIEW_TICKS)
        self.cf = np.array([*limits, *weights, *preview, 2.0])  # (_CF)
        self.n = n
        self.lf = np.zeros((n, _NLF))
        self.li = np.zeros((n, len(_LI)), dtype=np.int64)
        self.tabs = np.zeros((n, 4, SEGMENT_COLUMNS))
        self.nseg = np.ones(n, dtype=np.int64)
        self.rb = np.zeros((n, _RING, 2))
        self.loads = np.zeros((n, 1, 3))
        self.obs = np.zeros((n, 14), dtype=np.float32)
        self.out = np.zeros((n, len(_OUT)))
        self.flags = np.zeros((n, 5), dtype=np.bool_)
        self.act = np.zeros((n, 2))
        self.clipped = np.zeros(n, dtype=np.int64)
        self.scenarios: list[ContouringScenario | None] = [None] * n
        self.plants: list[ContouringPlant | None] = [None] * n
        self.names = LaneNames(n)
        self.feeds = np.zeros(n)
        self.ref_end = np.zeros(n)
        self.circles: list[dict] = [{}] * n
        self.has_circle = np.zeros(n, dtype=bool)
        self.circle = np.zeros((n, 3))
        self._packed = PackedArgs()  # the kernel's arguments in one table (core.compiled.packed)
        #: The blocks of lanes the kernel steps at once (one thread unless a vector env
        #: asks for more).
        self.blocks = LaneBlocks(n)
        self._bind()

    def _bind(self) -> None:
        """Gather the kernel's arguments once (again whenever an array is replaced, as
        :meth:`_grow` does)."""
        tables = (self.lf, self.li, self.cf, self.tabs, self.nseg, self.rb, self.loads)
        self._args = (self.act, self.clipped, *tables, self.obs, self.out, self.flags)

    def _grow(self, n_seg: int, n_load: int) -> None:
        if n_seg > self.tabs.shape[1]:
            tabs = np.zeros((self.n, n_seg, SEGMENT_COLUMNS))
            tabs[:, : self.tabs.shape[1]] = self.tabs
            self.tabs = tabs
            self._bind()
        if n_load > self.loads.shape[1]:
            loads = np.zeros((self.n, n_load, 3))
            loads[:, : self.loads.shape[1]] = self.loads
            self.loads = loads
            self._bind()

    def start(self, lane: int, spec, rng: np.random.Generator) -> None:
        """Start an episode in ``lane`` on the scenario ``spec`` (drawn with ``rng``); its
        first observation goes to ``obs[lane]``, its reset info is its :meth:`lane_info`
        (and its column of :meth:`info_arrays`) until the first step."""
        sc = contouring_scenario(spec, rng)
        check_feed(sc, self.params)
        if sc.actuation is not None:
            raise ValueError(
                f"scenario {sc.name!r} has a feed-override actuation; Contouring-v0 commands "
                "the axes directly (run it on ContouringFeed-v0)"
            )
        self.scenarios[lane] = sc
        plant = ContouringPlant(sc.true_params(self.params))
        self.plants[lane] = plant
        path = sc.path
        tab = path.table()
        self._grow(tab.shape[0], len(sc.load_steps))
        self.tabs[lane, : tab.shape[0]] = tab
        self.nseg[lane] = tab.shape[0]
        ts = self.params.sample_time_s
        ref_end = sc.reference_time_s
        t_max = self.max_episode_time_s
        if t_max is None:
            t_max = ref_end + sc.dwell_s + 0.5
        x0, y0 = path.start
        # The lane's floats in one write, in the order of the _LF columns: the plant, its
        # state, the path's length, the set point's advance, step or not, the path's end,
        # the time from which it may finish, the loads and the previous action.
        run = (path.length, 0.0 if sc.is_step else sc.feed_mm_s * ts, float(sc.is_step))
        run += (*path.end, ref_end + sc.dwell_s)
        state = (x0, 0.0, y0, 0.0)
        self.lf[lane] = [*plant.coefficients.tolist(), *state, *run, 0.0, 0.0, 0.0, 0.0]
        li = self.li[lane]
        li[:] = 0
        li[_LI.NLOAD] = len(sc.load_steps)
        li[_LI.NMAX] = int(math.ceil(t_max / ts - 1e-9))
        for i, step in enumerate(sc.load_steps):
            self.loads[lane, i] = step
        self.names[lane] = sc.name
        self.feeds[lane] = 0.0 if sc.is_step else sc.feed_mm_s
        self.ref_end[lane] = ref_end
        self.circles[lane] = circle_info(path)
        self.has_circle[lane] = bool(self.circles[lane])
        self.circle[lane] = tuple(self.circles[lane].values()) or (0.0, 0.0, 0.0)
        _contour_start(lane, *self._args[2:])  # (the step's arguments after the actions)

    def set_action(self, lane: int, action: list[float], clipped: bool) -> None:
        act = self.act[lane]
        act[0] = action[0]
        act[1] = action[1]
        self.clipped[lane] = clipped

    def set_actions(self, actions: np.ndarray) -> None:
        self.clipped[:] = False
        self.act[:] = actions  # clipped to the box by the kernel

    def outcome(self, lane: int) -> tuple[float, bool, bool]:
        f = self.flags[lane]
        return float(self.out[lane, 0]), bool(f[2]), bool(f[3])

    def step_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.out[:, 0], self.flags[:, 2], self.flags[:, 3]

    def clipped_count(self, lane: int) -> int:
        return int(self.li[lane, _LII.CLIP])

    def step(self) -> None:
        """Advance every lane by one servo period with the (checked, clipped) actions in
        ``act``; whether each was clipped is in ``clipped``."""
        if self.blocks.one:  # the single env, or few lanes: no blocks to hand out
            _contour_step_packed(self._packed(self._args))
        else:
            self.blocks.run(
                _contour_step,
                self._args,
                _STEP_AXES,
                packed=_contour_step_packed,
                serve=_serve_contour_step,
            )

    def lane_info(self, k: int) -> dict:
        """The info of lane ``k`` after its reset or its last step."""
        o = self.out[k].tolist()
        diverged, finished, _, _, clipped = self.flags[k].tolist()
        info = {
            "t_s": o[1],
            "command": np.array(o[2:4]),
            "command_x_mm_s": o[2],
            "command_y_mm_s": o[3],
            "action_clipped": clipped,
            "n_action_clipped": int(self.li[k, _LII.CLIP]),
            "breakage": False,
            "diverged": diverged,
            "finished": finished,
        }
        info.update(zip(_SIGNALS, o[_SIGNAL_COLUMNS], strict=True))
        info["contour_tolerance_mm"] = CONTOUR_TOLERANCE_MM
        info["cost"] = 1.0 if o[_OutI.contour_error_mm] > CONTOUR_TOLERANCE_MM else 0.0
        info["path_length_mm"] = float(self.lf[k, _LFI.LEN])
        info["segment"] = int(self.li[k, _LII.SEG])
        info["feed_mm_s"] = float(self.feeds[k])
        info["reference_end_s"] = float(self.ref_end[k])
        info["scenario"] = self.names[k]
        info.update(self.circles[k])
        if finished:
            info["machining_time_s"] = o[_OutI.machining_time_s]
        return info

    def info_arrays(self) -> dict:
        """The step info of every lane, as arrays (keys that only some lanes have come with
        their ``_key`` masks): mostly views of one copy of the outputs and one of the flags."""
        o = self.out.copy()
        f = self.flags.copy()
        info = {
            "t_s": o[:, 1],
            "command": o[:, 2:4].copy(),
            "command_x_mm_s": o[:, 2],
            "command_y_mm_s": o[:, 3],
            "action_clipped": f[:, 4],
            "n_action_clipped": self.li[:, _LII.CLIP].copy(),
            "breakage": np.zeros(self.n, dtype=bool),
            "diverged": f[:, 0],
            "finished": f[:, 1],
        }
        for i, name in enumerate(_SIGNALS, start=int(_Out.x_mm)):
            info[name] = o[:, i]
        info["contour_tolerance_mm"] = np.full(self.n, CONTOUR_TOLERANCE_MM)
        info["cost"] = (o[:, 8] > CONTOUR_TOLERANCE_MM).astype(np.float64)
        info["path_length_mm"] = self.lf[:, _LFI.LEN].copy()
        info["segment"] = self.li[:, _LII.SEG].copy()
        info["feed_mm_s"] = self.feeds.copy()
        info["reference_end_s"] = self.ref_end.copy()
        info["scenario"] = self.names.array()
        if self.has_circle.any():
            for i, key in enumerate(_CIRCLE_KEYS):
                info[key] = self.circle[:, i].copy()
                info["_" + key] = self.has_circle.copy()
        info["machining_time_s"] = np.where(f[:, 1], o[:, 18], np.nan)
        info["_machining_time_s"] = f[:, 1]
        return info
