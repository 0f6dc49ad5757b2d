"""The engine of ``MicroDrilling-v0``: the reward weights, the lane tables and the
compiled step, start and info of N drills, which :class:`MicroDrillingEnv` (one lane) and
:class:`MicroDrillingVectorEnv` (N lanes) drive."""

from __future__ import annotations

import math
from enum import IntEnum
from typing import NamedTuple

import numba
import numpy as np
from gymnasium import spaces

from machining_envs.core.actions import ActionMap, ActionMaps
from machining_envs.core.checks import check_below
from machining_envs.core.compiled.blocks import LaneBlocks, serve_one_table
from machining_envs.core.compiled.kernels import unit_clip
from machining_envs.core.compiled.normals import LaneGenerators, standard_normal
from machining_envs.core.compiled.packed import (
    PackedArgs,
    as_int,
    b1_2,
    f4_2,
    f8_1,
    f8_2,
    f8_3,
    i8_2,
)
from machining_envs.core.env import (
    check_episode_time,
    check_scenario_spec,
    resolve_params,
)
from machining_envs.core.lanes import LaneCore, LaneNames
from machining_envs.core.reward import LimitReward, resolve_reward
from machining_envs.drilling.plant import (
    _N_IN,
    _N_TMP,
    _P,
    _S,
    LANE_BLOCK,
    DrillingLanes,
    DrillingParams,
    _Out,
    _pymax,
    _pymin,
    advance,
    restart_lane,
    start_lane,
)
from machining_envs.drilling.scenarios import (
    DRILLING_SCENARIOS,
    DrillingScenario,
    drilling_scenario,
)

_HISTORY = 3
#: Scales of the observation fields that are not set by the parameters.
SPEED_SCALE_HZ = 1000.0
LENGTH_SCALE_MM = 10.0
_TORQUE_OBS = (-1.0, 10.0)
#: What the action commands: the valve voltage (the paper's loop), the feed velocity, or
#: both (``[voltage, feed]``: the spindle command beside the stage, so that a controller
#: can peck while the spindle runs fast).
CONTROL_MODES = ("voltage", "feed", "voltage_feed")
#: The kernel's code of each control mode (``consts[_K.MODE]``).
_MODE_CODES = {"voltage": 0.0, "feed": 1.0, "voltage_feed": 2.0}


#: The weights of the MicroDrilling reward (:class:`MicroDrillingEnv`, section Rewards): the
#: regulation envs' one weights type.
DrillingReward = LimitReward


# The lane tables' columns, each declared once by name; the kernels index by these names
# (an IntEnum's members are constants to the compiler).
#: Columns of ``DrillingCore.ev`` (floats of the env per lane).
#: (``ACTION2`` and ``FEED``: the feed's action and command of ``control="voltage_feed"``.)
_Ev = IntEnum(
    "_Ev", "ACTION TR THRUST_MEAS SPEED_MEAS COMMAND VOLTAGE REWARD MEAS ACTION2 FEED", start=0
)
#: Columns of ``DrillingCore.flags``.
_Flag = IntEnum(
    "_Flag",
    "IN_CLIPPED CLIPPED DIVERGED BREAKAGE FINISHED TERMINATED TRUNCATED OVER",
    start=0,
)
#: Columns of ``DrillingCore.counts``.
_Count = IntEnum("_Count", "N_CLIPPED SEGMENT", start=0)
#: Entries of ``DrillingCore.consts`` (the reward weights from ``W`` on).
_K = IntEnum(
    "_K",
    "MID HALF MODE V0 U0 MAX_T TORQUE_SCALE THRUST_SCALE SPEED_SCALE LENGTH_SCALE MID2 HALF2 W",
    start=0,
)


def floor_feed_mm_s(truth: DrillingParams, torque_per_feed: float, limit_Nmm: float) -> float:
    """The fastest feed at which a fully engaged drill's chip-free torque stays at the limit
    with the spindle at its top speed, mm/s (at most the stage's top speed): the torque is
    ``c_T v / f`` (eq. 20) with ``f`` at most the free spindle's frequency at
    ``voltage_max`` (the drilling torque only slows it) and packed chips only add to it.
    ``truth``: the hole's true parameters; ``torque_per_feed``: its drill's ``c_T``."""
    top_hz = truth.free_speed_hz(truth.voltage_max)
    return min(truth.feed_speed_max_mm_s, limit_Nmm * top_hz / torque_per_feed)


def floor_time_s(truth: DrillingParams, coeffs, target_mm: float, limit_Nmm: float) -> float:
    """The floor of the drilling time with ``control="voltage_feed"``, s: the point's entry
    (to full engagement, where the torque is a share of the full one) at the stage's top
    speed, the rest of the hole at :func:`floor_feed_mm_s`. No hole drilled under the
    limit is faster, but by the steps an allowance lets over it and by the cutting
    fluctuation's dips. ``coeffs``: the drill's ``CuttingCoefficients`` (truth)."""
    entry = min(coeffs.full_engagement_mm, target_mm)
    v = floor_feed_mm_s(truth, coeffs.torque_per_feed, limit_Nmm)
    return entry / truth.feed_speed_max_mm_s + (target_mm - entry) / v


def _ints(columns: type[IntEnum]) -> type:
    """``columns``' members as plain ints (class attributes), for the Python side: numpy
    takes an IntEnum member as an index by its slow path, and reading a member costs more
    than a class attribute (together some 10 % of a single env's step)."""
    return type(f"{columns.__name__}I", (), {c.name: int(c) for c in columns})


_EvI, _FlagI, _CountI = _ints(_Ev), _ints(_Flag), _ints(_Count)
_PI, _SI, _OutI = _ints(_P), _ints(_S), _ints(_Out)


class _Tables(NamedTuple):
    """The lane tables a start writes (:func:`_start`), views of the step's table."""

    par: np.ndarray
    eng: np.ndarray
    state: np.ndarray
    out: np.ndarray
    consts: np.ndarray
    ev: np.ndarray
    flags: np.ndarray
    counts: np.ndarray
    obs: np.ndarray
    bound: np.ndarray


class _Drill(NamedTuple):
    """A hole's drill for :func:`_start`: its ``par`` row and engagement tables, and ``x``
    = ``[voltage, valve x1, spindle speed (rad/s), start position, torque limit, feed of
    the bound, initial action, its command, initial feed action, its command]`` (the last
    two are read by ``control="voltage_feed"`` only)."""

    row: np.ndarray
    eng_depth: np.ndarray
    eng_torque: np.ndarray
    eng_thrust: np.ndarray
    x: np.ndarray


@numba.njit(cache=True)
def _env_lanes(k0, k1, par, state, out, c, ev, flags, counts, obs):
    """Episode flags, reward and observation of lanes ``k0 .. k1 - 1`` from the plant's
    signals ``out[k]`` (those that are not finite after a divergence are set to zero there)."""
    for k in range(k0, k1):
        torque, peak, meas = (
            out[k, _Out.torque_Nmm],
            out[k, _Out.peak_torque_Nmm],
            out[k, _Out.measured_torque_Nmm],
        )
        diverged = not (
            np.isfinite(torque)
            and np.isfinite(peak)
            and np.isfinite(meas)
            and np.isfinite(out[k, _Out.thrust_N])
            and np.isfinite(out[k, _Out.measured_thrust_N])
            and np.isfinite(out[k, _Out.speed_hz])
            and np.isfinite(out[k, _Out.measured_speed_hz])
        )
        if diverged:  # never seen; kept so that no NaN can reach an observation or a reward
            torque = 0.0
            peak = 0.0
            meas = 0.0
            for i in (0, 1, 2, 3, 4, 5, 6, 10):  # torques, thrusts, speeds, feed per rev
                out[k, i] = 0.0
        ev[k, _Ev.MEAS] = meas
        ev[k, _Ev.THRUST_MEAS] = out[k, _Out.measured_thrust_N]
        ev[k, _Ev.SPEED_MEAS] = out[k, _Out.measured_speed_hz]
        if out[k, _Out.cutting] != 0.0:
            counts[k, _Count.SEGMENT] = 1
        breakage = peak > par[k, _P.BREAK]
        finished = not np.isnan(out[k, _Out.finish_time_s])
        terminated = diverged or breakage or finished
        t = state[k, _S.T]
        truncated = (not terminated) and t >= c[_K.MAX_T] - 1e-9
        e = torque / ev[k, _Ev.TR]
        reward = -c[_K.W + 0] * abs(e / c[_K.W + 2] - 1.0) - c[_K.W + 1] * _pymax(0.0, e - 1.0)
        if c[_K.W + 3] != 0.0:
            reward += c[_K.W + 3] * out[k, _Out.cutting_feed_mm_s] / c[_K.V0]
        if breakage or diverged:
            reward -= c[_K.W + 4]
        ev[k, _Ev.REWARD] = reward
        flags[k, _Flag.DIVERGED] = diverged
        flags[k, _Flag.BREAKAGE] = breakage
        flags[k, _Flag.FINISHED] = finished
        flags[k, _Flag.TERMINATED] = terminated
        flags[k, _Flag.TRUNCATED] = truncated
        flags[k, _Flag.OVER] = out[k, _Out.cutting] != 0.0 and torque > ev[k, _Ev.TR]
        lo, hi = _TORQUE_OBS
        ts = c[_K.TORQUE_SCALE]
        ls = c[_K.LENGTH_SCALE]
        # The torque history: the measured torques of the last steps, as they were observed.
        for i in range(8 + _HISTORY, 9, -1):
            obs[k, i] = obs[k, i - 1]
        obs[k, 9] = obs[k, 0]
        obs[k, 0] = _pymin(_pymax(meas / ts, lo), hi)
        obs[k, 2] = _pymin(_pymax(ev[k, _Ev.THRUST_MEAS] / c[_K.THRUST_SCALE], lo), hi)
        obs[k, 3] = _pymin(_pymax(ev[k, _Ev.SPEED_MEAS] / c[_K.SPEED_SCALE], 0.0), 3.0)
        obs[k, 4] = ev[k, _Ev.ACTION]
        if obs.shape[1] > 9 + _HISTORY:  # control="voltage_feed": the feed's action too
            obs[k, 9 + _HISTORY] = ev[k, _Ev.ACTION2]
        obs[k, 5] = _pymin(_pymax(out[k, _Out.position_mm] / ls, -1.0), 2.0)
        obs[k, 6] = _pymin(out[k, _Out.depth_mm] / ls, 2.0)


@numba.njit(cache=True, nogil=True)
def _step(m, g, par, eng, state, out, c, ev, flags, counts, obs, rng_table):
    """One step of every lane: the action's command, the plant, the env's outputs.

    Lane ``k`` applies ``ev[k, _Ev.ACTION]`` (and with ``control="voltage_feed"`` the feed's
    ``ev[k, _Ev.ACTION2]``), clipped to the box here (and counted as clipped, once a step,
    as it is when ``flags[k, _Flag.IN_CLIPPED]`` says it was clipped before), and draws five
    standard normals from its generator (row ``rng_table[k]``, ``core.compiled.normals``). The plant
    advances ``LANE_BLOCK`` lanes at a time.
    """
    mode = c[_K.MODE]
    feed_mode = mode == 1.0
    pair = mode == 2.0
    n = state.shape[0]
    inputs = np.empty((LANE_BLOCK, _N_IN))
    tmp = np.empty((LANE_BLOCK, _N_TMP))
    rows = np.empty((2, LANE_BLOCK))
    for k0 in range(0, n, LANE_BLOCK):
        k1 = min(k0 + LANE_BLOCK, n)
        for k in range(k0, k1):
            a, boxed = unit_clip(ev[k, _Ev.ACTION])
            clipped = flags[k, _Flag.IN_CLIPPED] or boxed
            ev[k, _Ev.ACTION] = a
            command = c[_K.MID] + c[_K.HALF] * a
            if pair:
                a2, boxed2 = unit_clip(ev[k, _Ev.ACTION2])
                clipped = clipped or boxed2
                ev[k, _Ev.ACTION2] = a2
                voltage, feed = command, c[_K.MID2] + c[_K.HALF2] * a2
                ev[k, _Ev.FEED] = feed
            elif feed_mode:
                voltage, feed = c[_K.U0], command
            else:
                voltage, feed = command, c[_K.V0]
            flags[k, _Flag.CLIPPED] = clipped
            counts[k, _Count.N_CLIPPED] += clipped
            ev[k, _Ev.COMMAND] = command
            ev[k, _Ev.VOLTAGE] = voltage
            inputs[k - k0, 0] = voltage
            inputs[k - k0, 1] = feed
            for q in range(5):
                inputs[k - k0, 2 + q] = standard_normal(rng_table, k)
        advance(k0, k1, m, g, par, eng, state, inputs, out, tmp, rows)
        _env_lanes(k0, k1, par, state, out, c, ev, flags, counts, obs)


@numba.njit(cache=True, nogil=True)
def _step_packed(t):
    """:func:`_step` with its arguments in one table (``core.compiled.packed``): what every
    step calls (one array to unbox, not one per argument)."""
    _step(*_step_args(t))


@numba.njit(cache=True, inline="always")
def _step_args(t):
    """:func:`_step`'s arguments from its table ``t`` (``DrillingCore._args``): the plant's
    tables, then the env's."""
    plant = (as_int(t, 0), f8_1(t, 1), f8_2(t, 2), f8_3(t, 3), f8_2(t, 4), f8_2(t, 5))
    env = (f8_1(t, 6), f8_2(t, 7), b1_2(t, 8), i8_2(t, 9), f4_2(t, 10), i8_2(t, 11))
    return plant + env


@numba.njit(cache=True, nogil=True)
def _serve_step(ctl, table, polls):
    """The lane blocks' worker loop for :func:`_step_packed` (``core.compiled.blocks``), compiled with
    this module and cached, not at the first step on several threads."""
    return serve_one_table(_step_packed, ctl, table, polls)


@numba.njit(cache=True)
def _start(k, drill, t):
    """The arrays of lane ``k`` at the start of a hole (``DrillingCore.start``) in the
    tables ``t`` (:class:`_Tables`): the plant's
    (:func:`~machining_envs.drilling.plant.start_lane` with the drill's ``par`` row and
    engagement tables, ``drill``, a :class:`_Drill`;
    :func:`~machining_envs.drilling.plant.restart_lane`), then the env's: the score bound,
    the first observation, and the signals of a hole not yet begun, where ``lane_info`` and
    ``info_arrays`` read them until the first step (which writes every one before it reads
    it): the drill at rest at its start position, the spindle at its initial speed, the
    valve and the voltage as the plant starts, the command of the initial action.
    """
    x, row = drill.x, drill.row
    volt, x1, omega, position, tr, v, a0, c0 = x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]
    start_lane(k, row, drill.eng_depth, drill.eng_torque, drill.eng_thrust, t.par, t.eng)
    restart_lane(k, volt, x1, omega, position, t.state)
    hz = omega / (2.0 * math.pi)
    target = row[_P.TARGET]
    t.bound[k] = (target - position) / v
    e = t.ev[k]
    e[:] = 0.0
    e[_Ev.ACTION] = a0
    e[_Ev.TR] = tr
    e[_Ev.SPEED_MEAS] = hz
    e[_Ev.COMMAND] = c0
    e[_Ev.VOLTAGE] = volt
    e[_Ev.ACTION2] = x[8]
    e[_Ev.FEED] = x[9]
    t.flags[k, :] = False
    t.counts[k, _Count.N_CLIPPED] = 0
    t.counts[k, _Count.SEGMENT] = 0
    lo, hi = _TORQUE_OBS
    c = t.consts  # the observation's scales
    ts, hs, ss, ls = c[_K.TORQUE_SCALE], c[_K.THRUST_SCALE], c[_K.SPEED_SCALE], c[_K.LENGTH_SCALE]
    # (the observation as Python's min and max make it)
    o = t.obs[k]
    o[0] = _pymin(_pymax(0.0 / ts, lo), hi)
    o[1] = _pymin(tr / ts, 10.0)
    o[2] = _pymin(_pymax(0.0 / hs, lo), hi)
    o[3] = _pymin(_pymax(hz / ss, 0.0), 3.0)
    o[4] = a0
    o[5] = _pymin(_pymax(position / ls, -1.0), 2.0)
    o[6] = _pymin(0.0 / ls, 2.0)
    o[7] = _pymin(target / ls, 2.0)
    o[8] = row[_P.D]
    for i in range(_HISTORY):
        o[9 + i] = _pymin(_pymax(0.0 / ts, lo), hi)
    if o.shape[0] > 9 + _HISTORY:
        o[9 + _HISTORY] = x[8]
    q = t.out[k]
    q[:] = 0.0
    q[_Out.measured_speed_hz] = q[_Out.speed_hz] = hz
    q[_Out.valve_opening] = x1
    q[_Out.position_mm] = position
    q[_Out.finish_time_s] = np.nan


@numba.njit(cache=True)
def _start_packed(t, k, row, eng_depth, eng_torque, eng_thrust, x, bound):
    """:func:`_start` with the step's table ``t`` (:func:`_step_packed`'s) and the drill's
    arrays (:class:`_Drill`'s fields: a record made here, not in Python, costs no typing of
    it at each call)."""
    drill = _Drill(row, eng_depth, eng_torque, eng_thrust, x)
    _, _, par, eng, state, out, consts, ev, flags, counts, obs, _ = _step_args(t)
    _start(k, drill, _Tables(par, eng, state, out, consts, ev, flags, counts, obs, bound))


#: Where :func:`_step`'s arguments (``DrillingCore._args``) hold the lanes: axis 0 or none
#: (shared), for :class:`~machining_envs.core.compiled.blocks.LaneBlocks`.
_STEP_AXES = (None, None, 0, 0, 0, 0, None, 0, 0, 0, 0, 0)


class DrillingCore(LaneCore):
    """The state and arithmetic of N drilling episodes, shared by ``MicroDrillingEnv`` (one
    lane) and ``MicroDrillingVectorEnv`` (N lanes): the plant (:class:`DrillingLanes`) and
    the reward, observation and episode end computed for all lanes by one compiled function,
    so that a lane of the vector env and the single env agree to the last bit.

    Noise: lane ``k`` draws the five standard normals of its plant's step from the
    generator its episode started with (``core.compiled.normals``), after the scenario, as the step
    needs them.
    """

    #: What a scenario may be: an object of this class or one of these names.
    scenario_types = (DrillingScenario, DRILLING_SCENARIOS)

    def __init__(
        self, owner, n, scenario, *, control, params, reward, max_episode_time_s, overrides
    ):
        self.params = resolve_params(
            owner, params, DrillingParams, DrillingParams.cheong_cho, overrides
        )
        if control not in CONTROL_MODES:
            raise ValueError(f"control must be one of {CONTROL_MODES}, got {control!r}")
        self.control = control
        self.reward_weights = resolve_reward(reward, DrillingReward)
        self.max_episode_time_s = check_episode_time(max_episode_time_s)
        check_scenario_spec(scenario, DrillingScenario, DRILLING_SCENARIOS)
        p = self.params
        volts = ActionMap(0.0, p.voltage_max)
        feeds = ActionMap(-p.feed_speed_max_mm_s, p.feed_speed_max_mm_s)
        #: The feed's map (``control="voltage_feed"``; else unused).
        self._feed_map = feeds
        self._pair = control == "voltage_feed"
        self._a0_feed = float(feeds.command_to_action(p.feed_velocity_mm_s))
        self._c0_feed = float(feeds.action_to_command(self._a0_feed))
        main = feeds if control == "feed" else volts
        self._a0 = float(
            main.command_to_action(p.feed_velocity_mm_s if control == "feed" else p.nominal_voltage)
        )
        self._c0 = float(main.action_to_command(self._a0))
        self.command_map = ActionMaps(volts, feeds) if self._pair else main
        n_act = 2 if self._pair else 1
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n_act,), dtype=np.float32)
        t_lo, t_hi = _TORQUE_OBS
        extra = [-1.0] if self._pair else []  # the feed's previous action
        low = np.array(
            [t_lo, 0.0, t_lo, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0] + [t_lo] * _HISTORY + extra,
            dtype=np.float32,
        )
        high = np.array(
            [t_hi, 10.0, t_hi, 3.0, 1.0, 2.0, 2.0, 2.0, 1.0]
            + [t_hi] * _HISTORY
            + [-e for e in extra],
            dtype=np.float32,
        )
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        w = self.reward_weights
        self.consts = np.array(
            [
                main.mid,
                main.half,
                _MODE_CODES[control],
                p.feed_velocity_mm_s,
                p.nominal_voltage,
                self.max_episode_time_s,
                p.torque_scale_Nmm,
                p.thrust_scale_N,
                SPEED_SCALE_HZ,
                LENGTH_SCALE_MM,
                feeds.mid,
                feeds.half,
                *w.weights(),
            ]
        )
        self.n = n
        self.lanes = DrillingLanes(p, n)
        self.scenarios: list[DrillingScenario | None] = [None] * n
        self.names = LaneNames(n)
        self.ev = np.zeros((n, len(_Ev)))
        self.flags = np.zeros((n, len(_Flag)), dtype=np.bool_)
        self.counts = np.zeros((n, len(_Count)), dtype=np.int64)
        self.bound = np.full(n, np.nan)
        self.obs = np.zeros((n, 9 + _HISTORY + len(extra)), dtype=np.float32)
        #: The generators the lanes draw their noise from (their episodes').
        self.rngs = LaneGenerators(n)
        lanes = self.lanes
        self._args = (
            lanes.m,
            lanes.shared,
            lanes.par,
            lanes.eng,
            lanes.state,
            lanes.out,
            self.consts,
            self.ev,
            self.flags,
            self.counts,
            self.obs,
            self.rngs.table,
        )
        self._packed = PackedArgs()  # the kernel's arguments in one table (core.compiled.packed)
        #: The blocks of lanes the kernel steps at once (one thread unless a vector env
        #: asks for more).
        self.blocks = LaneBlocks(n)

    def start(self, lane: int, spec, rng: np.random.Generator) -> None:
        """Start an episode in ``lane`` on the scenario ``spec`` (drawn with ``rng``); its
        first observation goes to ``obs[lane]``, its reset info is its :meth:`lane_info`
        (and its column of :meth:`info_arrays`) until the first step."""
        check_scenario_spec(spec, DrillingScenario, DRILLING_SCENARIOS)
        sc = drilling_scenario(spec, rng)
        self.scenarios[lane] = sc
        self.names[lane] = sc.name
        p = self.params
        d = sc.diameter_mm
        truth = sc.true_params(p)
        tr = sc.limit_Nmm(p)
        # (true_params changes no field the lanes share, and a scenario's hole lies within
        # the lanes' range of depths: DrillingLanes.start's checks hold.)
        c = truth.coefficients(d)
        target = sc.target_depth_mm
        u = p.nominal_voltage
        # The floor of the drilling time: the whole travel at the programmed feed (voltage
        # control), at the stage's top speed (feed control), or (voltage and feed) at the
        # feed of :func:`floor_feed_mm_s`, passed as the feed of the whole travel.
        if self.control == "voltage":
            v = p.feed_velocity_mm_s
        elif self.control == "feed":
            v = p.feed_speed_max_mm_s
        else:
            v = target / floor_time_s(truth, c, target, tr)
        x = (u, truth.valve_static_gain_per_V * u, truth.free_speed_rad_s(u), 0.0, tr, v)
        row = self.lanes.lane_row(truth, c, d, target)
        engagement = (c.engage_depth_mm, c.engage_torque, c.engage_thrust)
        x = np.array((*x, self._a0, self._c0, self._a0_feed, self._c0_feed))
        _start_packed(self._packed(self._args), lane, row, *engagement, x, self.bound)
        self.rngs.bind(lane, rng)  # the hole's noise comes from it too
        breakage = float(self.lanes.par[lane, _P.BREAK])
        if not tr < breakage:  # the message is made only when it fails
            check_below(
                f"scenario {sc.name!r}: the torque limit (torque_limit_Nmm x torque_limit_scale)",
                tr,
                f"the {d:g} mm drill's breakage torque (breakage_coeff_N_per_mm2 x D^3)",
                breakage,
                "the drill would break before the limit binds",
            )

    def set_action(self, lane: int, action, clipped: bool) -> None:
        """``action``: a float, or with ``control="voltage_feed"`` ``[voltage, feed]``."""
        if self._pair:
            self.ev[lane, _EvI.ACTION] = action[0]
            self.ev[lane, _EvI.ACTION2] = action[1]
        else:
            self.ev[lane, _EvI.ACTION] = action
        self.flags[lane, _FlagI.IN_CLIPPED] = clipped

    def set_actions(self, actions: np.ndarray) -> None:
        self.ev[:, _EvI.ACTION] = actions[:, 0]  # clipped to the box by the kernel
        if self._pair:
            self.ev[:, _EvI.ACTION2] = actions[:, 1]

    def outcome(self, lane: int) -> tuple[float, bool, bool]:
        f = self.flags[lane]
        return (
            float(self.ev[lane, _EvI.REWARD]),
            bool(f[_FlagI.TERMINATED]),
            bool(f[_FlagI.TRUNCATED]),
        )

    def step_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return (
            self.ev[:, _EvI.REWARD],
            self.flags[:, _FlagI.TERMINATED],
            self.flags[:, _FlagI.TRUNCATED],
        )

    def clipped_count(self, lane: int) -> int:
        return int(self.counts[lane, _CountI.N_CLIPPED])

    def step(self) -> None:
        """Advance every lane with its action ``ev[:, _Ev.ACTION]`` (finite; clipped to the
        box, ``flags[:, _Flag.IN_CLIPPED]`` saying whether it was clipped already)."""
        if self.blocks.one:  # the single env, or few lanes: no blocks to hand out
            _step_packed(self._packed(self._args))
        else:
            self.blocks.run(_step, self._args, _STEP_AXES, packed=_step_packed, serve=_serve_step)

    def lane_info(self, k: int) -> dict:
        """The step info of lane ``k`` (after :meth:`step`)."""
        (
            torque,
            peak,
            thrust,
            _,
            meas_thrust,
            meas_speed,
            speed,
            valve,
            feed,
            _,
            per_rev,
            position,
            depth,
            packed,
            chip,
            cutting,
            engagement,
            finish,
        ) = self.lanes.out[k].tolist()
        e = self.ev[k].tolist()
        clipped, diverged, breakage, finished = self.flags[
            k, _FlagI.CLIPPED : _FlagI.TERMINATED
        ].tolist()
        n_clipped, segment = self.counts[k].tolist()
        p = self.lanes.par[k]
        sc = self.scenarios[k]
        info = {
            "t_s": float(self.lanes.state[k, _SI.T]),
            "command": e[_EvI.COMMAND],
            "action_clipped": clipped,
            "n_action_clipped": n_clipped,
            "breakage": breakage,
            "diverged": diverged,
            "finished": finished,
            "torque_Nmm": torque,
            "torque_limit_Nmm": e[_EvI.TR],
            "cost": 1.0 if self.flags[k, _FlagI.OVER] else 0.0,
            "score_bound": float(self.bound[k]),
            "measured": e[_EvI.MEAS],
            "peak_torque_Nmm": peak,
            "breakage_torque_Nmm": float(p[_PI.BREAK]),
            "thrust_N": thrust,
            "measured_thrust_N": meas_thrust,
            "spindle_hz": speed,
            "measured_spindle_hz": meas_speed,
            "spindle_rpm": 60.0 * speed,
            "voltage_V": e[_EvI.VOLTAGE],
            "valve_opening": valve,
            "feed_velocity_mm_s": feed,
            "feed_mm_per_rev": per_rev,
            "cutting": cutting != 0.0,
            "engagement": engagement,
            "position_mm": position,
            "depth_mm": depth,
            "target_depth_mm": sc.target_depth_mm,
            "packed_chip_mm": packed,
            "chip_ratio": chip,
            "diameter_mm": sc.diameter_mm,
            "segment": segment,
            "scenario": sc.name,
        }
        if self._pair:
            info["command"] = np.array((e[_EvI.COMMAND], e[_EvI.FEED]))
        if finished:
            info["drilling_time_s"] = finish
            info["machining_time_s"] = finish
        return info

    def info_arrays(self) -> dict:
        """The step info of every lane, as arrays (the finish times with their masks): views
        of one copy of each of the core's tables, so a step copies a few blocks of memory."""
        o = self.lanes.out.copy()
        e = self.ev.copy()
        f = self.flags.copy()
        c = self.counts.copy()
        lane = self.lanes.par[:, [_PI.BREAK, _PI.TARGET, _PI.D]]
        done = f[:, _FlagI.FINISHED]
        finish = o[:, _OutI.finish_time_s]  # NaN unless the hole was finished in this step
        command = e[:, [_EvI.COMMAND, _EvI.FEED]] if self._pair else e[:, _EvI.COMMAND]
        return {
            "t_s": self.lanes.state[:, _SI.T].copy(),
            "command": command,
            "action_clipped": f[:, _FlagI.CLIPPED],
            "n_action_clipped": c[:, _CountI.N_CLIPPED],
            "breakage": f[:, _FlagI.BREAKAGE],
            "diverged": f[:, _FlagI.DIVERGED],
            "finished": done,
            "torque_Nmm": o[:, _OutI.torque_Nmm],
            "torque_limit_Nmm": e[:, _EvI.TR],
            "cost": f[:, _FlagI.OVER].astype(np.float64),
            "score_bound": self.bound.copy(),
            "measured": e[:, _EvI.MEAS],
            "peak_torque_Nmm": o[:, _OutI.peak_torque_Nmm],
            "breakage_torque_Nmm": lane[:, 0],
            "thrust_N": o[:, _OutI.thrust_N],
            "measured_thrust_N": o[:, _OutI.measured_thrust_N],
            "spindle_hz": o[:, _OutI.speed_hz],
            "measured_spindle_hz": o[:, _OutI.measured_speed_hz],
            "spindle_rpm": 60.0 * o[:, _OutI.speed_hz],
            "voltage_V": e[:, _EvI.VOLTAGE],
            "valve_opening": o[:, _OutI.valve_opening],
            "feed_velocity_mm_s": o[:, _OutI.feed_velocity_mm_s],
            "feed_mm_per_rev": o[:, _OutI.feed_mm_per_rev],
            "cutting": o[:, _OutI.cutting] != 0.0,
            "engagement": o[:, _OutI.engagement],
            "position_mm": o[:, _OutI.position_mm],
            "depth_mm": o[:, _OutI.depth_mm],
            "target_depth_mm": lane[:, 1],
            "packed_chip_mm": o[:, _OutI.packed_mm],
            "chip_ratio": o[:, _OutI.chip_ratio],
            "diameter_mm": lane[:, 2],
            "segment": c[:, _CountI.SEGMENT],
            "scenario": self.names.array(),
            "drilling_time_s": finish,
            "_drilling_time_s": done.copy(),
            "machining_time_s": finish.copy(),
            "_machining_time_s": done.copy(),
        }
