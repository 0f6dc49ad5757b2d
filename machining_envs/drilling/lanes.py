"""The engine of ``MicroDrilling-v0``: the reward weights, the lane tables and the
compiled step, start and info of N drills, which :class:`MicroDrillingEnv` (one lane) and
:class:`MicroDrillingVectorEnv` (N lanes) drive."""

from __future__ import annotations

import math

import numba
import numpy as np
from gymnasium import spaces

from machining_envs.core.actions import ActionMap
from machining_envs.core.checks import check_below
from machining_envs.core.compiled.blocks import LaneBlocks, serve_one_table
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
    _P_BREAK,
    _P_D,
    _P_TARGET,
    _S_T,
    LANE_BLOCK,
    DrillingLanes,
    DrillingParams,
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
#: What the action commands: the valve voltage (the paper's loop) or the feed velocity.
CONTROL_MODES = ("voltage", "feed")


#: The weights of the MicroDrilling reward (:class:`MicroDrillingEnv`, section Rewards): the
#: regulation envs' one weights type.
DrillingReward = LimitReward


#: Columns of ``DrillingCore.ev`` (floats of the env per lane).
(_E_ACTION, _E_TR, _E_THRUST_MEAS, _E_SPEED_MEAS, _E_COMMAND, _E_VOLTAGE, _E_REWARD, _E_MEAS,
 _N_EV) = range(9)  # fmt: skip
#: Columns of ``DrillingCore.flags``.
(_F_IN_CLIPPED, _F_CLIPPED, _F_DIVERGED, _F_BREAKAGE, _F_FINISHED, _F_TERMINATED,
 _F_TRUNCATED, _F_OVER, _N_FLAGS) = range(9)  # fmt: skip
#: Columns of ``DrillingCore.counts``.
_C_N_CLIPPED, _C_SEGMENT = 0, 1
#: Entries of ``DrillingCore.consts``.
(_K_MID, _K_HALF, _K_FEED_MODE, _K_V0, _K_U0, _K_MAX_T, _K_TORQUE_SCALE, _K_THRUST_SCALE,
 _K_SPEED_SCALE, _K_LENGTH_SCALE, _K_W) = range(11)  # fmt: skip


@numba.njit(cache=True)
def _env_lanes(k0, k1, par, state, out, c, ev, flags, counts, obs):
    """Episode flags, reward and observation of lanes ``k0 .. k1 - 1`` from the plant's
    signals ``out[k]`` (those that are not finite after a divergence are set to zero there)."""
    for k in range(k0, k1):
        torque, peak, meas = out[k, 0], out[k, 1], out[k, 3]
        diverged = not (
            np.isfinite(torque)
            and np.isfinite(peak)
            and np.isfinite(meas)
            and np.isfinite(out[k, 2])
            and np.isfinite(out[k, 4])
            and np.isfinite(out[k, 6])
            and np.isfinite(out[k, 5])
        )
        if diverged:  # never seen; kept so that no NaN can reach an observation or a reward
            torque = 0.0
            peak = 0.0
            meas = 0.0
            for i in (0, 1, 2, 3, 4, 5, 6, 10):  # torques, thrusts, speeds, feed per rev
                out[k, i] = 0.0
        ev[k, _E_MEAS] = meas
        ev[k, _E_THRUST_MEAS] = out[k, 4]
        ev[k, _E_SPEED_MEAS] = out[k, 5]
        if out[k, 15] != 0.0:
            counts[k, _C_SEGMENT] = 1
        breakage = peak > par[k, _P_BREAK]
        finished = not np.isnan(out[k, 17])
        terminated = diverged or breakage or finished
        t = state[k, _S_T]
        truncated = (not terminated) and t >= c[_K_MAX_T] - 1e-9
        e = torque / ev[k, _E_TR]
        reward = -c[_K_W + 0] * abs(e / c[_K_W + 2] - 1.0) - c[_K_W + 1] * _pymax(0.0, e - 1.0)
        if c[_K_W + 3] != 0.0:
            reward += c[_K_W + 3] * out[k, 9] / c[_K_V0]
        if breakage or diverged:
            reward -= c[_K_W + 4]
        ev[k, _E_REWARD] = reward
        flags[k, _F_DIVERGED] = diverged
        flags[k, _F_BREAKAGE] = breakage
        flags[k, _F_FINISHED] = finished
        flags[k, _F_TERMINATED] = terminated
        flags[k, _F_TRUNCATED] = truncated
        flags[k, _F_OVER] = out[k, 15] != 0.0 and torque > ev[k, _E_TR]
        lo, hi = _TORQUE_OBS
        ts = c[_K_TORQUE_SCALE]
        ls = c[_K_LENGTH_SCALE]
        # The torque history: the measured torques of the last steps, as they were observed.
        for i in range(8 + _HISTORY, 9, -1):
            obs[k, i] = obs[k, i - 1]
        obs[k, 9] = obs[k, 0]
        obs[k, 0] = _pymin(_pymax(meas / ts, lo), hi)
        obs[k, 2] = _pymin(_pymax(ev[k, _E_THRUST_MEAS] / c[_K_THRUST_SCALE], lo), hi)
        obs[k, 3] = _pymin(_pymax(ev[k, _E_SPEED_MEAS] / c[_K_SPEED_SCALE], 0.0), 3.0)
        obs[k, 4] = ev[k, _E_ACTION]
        obs[k, 5] = _pymin(_pymax(out[k, 11] / ls, -1.0), 2.0)
        obs[k, 6] = _pymin(out[k, 12] / ls, 2.0)


@numba.njit(cache=True, nogil=True)
def _step(m, g, par, eng, state, out, c, ev, flags, counts, obs, rng_table):
    """One step of every lane: the action's command, the plant, the env's outputs.

    Lane ``k`` applies ``ev[k, _E_ACTION]``, clipped to the box here (and counted as clipped,
    as it is when ``flags[k, _F_IN_CLIPPED]`` says it was clipped before), and draws five
    standard normals from its generator (row ``rng_table[k]``, ``core.compiled.normals``). The plant
    advances ``LANE_BLOCK`` lanes at a time.
    """
    feed_mode = c[_K_FEED_MODE] != 0.0
    n = state.shape[0]
    inputs = np.empty((LANE_BLOCK, _N_IN))
    tmp = np.empty((LANE_BLOCK, _N_TMP))
    rows = np.empty((2, LANE_BLOCK))
    for k0 in range(0, n, LANE_BLOCK):
        k1 = min(k0 + LANE_BLOCK, n)
        for k in range(k0, k1):
            a = ev[k, _E_ACTION]
            clipped = flags[k, _F_IN_CLIPPED]
            if a > 1.0:
                a = 1.0
                clipped = True
            elif a < -1.0:
                a = -1.0
                clipped = True
            ev[k, _E_ACTION] = a
            flags[k, _F_CLIPPED] = clipped
            counts[k, _C_N_CLIPPED] += clipped
            command = c[_K_MID] + c[_K_HALF] * a
            if feed_mode:
                voltage, feed = c[_K_U0], command
            else:
                voltage, feed = command, c[_K_V0]
            ev[k, _E_COMMAND] = command
            ev[k, _E_VOLTAGE] = voltage
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
    _step(as_int(t, 0), f8_1(t, 1), f8_2(t, 2), f8_3(t, 3), f8_2(t, 4), f8_2(t, 5), f8_1(t, 6),
          f8_2(t, 7), b1_2(t, 8), i8_2(t, 9), f4_2(t, 10), i8_2(t, 11))  # fmt: skip


@numba.njit(cache=True, nogil=True)
def _serve_step(ctl, table, polls):
    """The lane blocks' worker loop for :func:`_step_packed` (``core.compiled.blocks``), compiled with
    this module and cached, not at the first step on several threads."""
    return serve_one_table(_step_packed, ctl, table, polls)


@numba.njit(cache=True)
def _start(k, row, eng_depth, eng_torque, eng_thrust, x, par, eng, state, out, consts, ev, flags,
           counts, obs, bound):  # fmt: skip
    """The arrays of lane ``k`` at the start of a hole (``DrillingCore.start``): the
    plant's (:func:`~machining_envs.drilling.plant.start_lane` with the ``par`` row ``row``
    and the engagement tables, :func:`~machining_envs.drilling.plant.restart_lane`), then
    the env's: the score bound, the first observation, and the signals of a hole not yet
    begun, where ``lane_info`` and ``info_arrays`` read them until the first step (which
    writes every one before it reads it): the drill at rest at its start position, the
    spindle at its initial speed, the valve and the voltage as the plant starts, the command
    of the initial action. ``x`` = ``[voltage, valve x1, spindle speed (rad/s), start
    position, torque limit, feed of the bound, initial action, its command]``.
    """
    volt, x1, omega, position, tr, v, a0, c0 = x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]
    start_lane(k, row, eng_depth, eng_torque, eng_thrust, par, eng)
    restart_lane(k, volt, x1, omega, position, state)
    hz = omega / (2.0 * math.pi)
    target = row[_P_TARGET]
    bound[k] = (target - position) / v
    e = ev[k]
    e[:] = 0.0
    e[_E_ACTION] = a0
    e[_E_TR] = tr
    e[_E_SPEED_MEAS] = hz
    e[_E_COMMAND] = c0
    e[_E_VOLTAGE] = volt
    flags[k, :] = False
    counts[k, _C_N_CLIPPED] = 0
    counts[k, _C_SEGMENT] = 0
    lo, hi = _TORQUE_OBS
    ts, hs, ss, ls = consts[6], consts[7], consts[8], consts[9]  # the observation's scales
    # (the observation as Python's min and max make it)
    o = obs[k]
    o[0] = _pymin(_pymax(0.0 / ts, lo), hi)
    o[1] = _pymin(tr / ts, 10.0)
    o[2] = _pymin(_pymax(0.0 / hs, lo), hi)
    o[3] = _pymin(_pymax(hz / ss, 0.0), 3.0)
    o[4] = a0
    o[5] = _pymin(_pymax(position / ls, -1.0), 2.0)
    o[6] = _pymin(0.0 / ls, 2.0)
    o[7] = _pymin(target / ls, 2.0)
    o[8] = row[_P_D]
    for i in range(_HISTORY):
        o[9 + i] = _pymin(_pymax(0.0 / ts, lo), hi)
    q = out[k]
    q[:] = 0.0
    q[5] = hz
    q[6] = hz
    q[7] = x1
    q[11] = position
    q[17] = np.nan


@numba.njit(cache=True)
def _start_packed(t, k, row, eng_depth, eng_torque, eng_thrust, x, bound):
    """:func:`_start` with the step's table ``t`` (:func:`_step_packed`'s)."""
    _start(k, row, eng_depth, eng_torque, eng_thrust, x, f8_2(t, 2), f8_3(t, 3), f8_2(t, 4),
           f8_2(t, 5), f8_1(t, 6), f8_2(t, 7), b1_2(t, 8), i8_2(t, 9), f4_2(t, 10), bound)  # fmt: skip


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

    def __init__(self, owner, n, scenario, control, params, reward, max_episode_time_s,
                 overrides):  # fmt: skip
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
        if control == "voltage":
            self.command_map = ActionMap(0.0, p.voltage_max)
            self._a0 = float(self.command_map.command_to_action(p.nominal_voltage))
        else:
            self.command_map = ActionMap(-p.feed_speed_max_mm_s, p.feed_speed_max_mm_s)
            self._a0 = float(self.command_map.command_to_action(p.feed_velocity_mm_s))
        self._c0 = float(self.command_map.action_to_command(self._a0))
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        t_lo, t_hi = _TORQUE_OBS
        low = np.array(
            [t_lo, 0.0, t_lo, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0] + [t_lo] * _HISTORY,
            dtype=np.float32,
        )
        high = np.array(
            [t_hi, 10.0, t_hi, 3.0, 1.0, 2.0, 2.0, 2.0, 1.0] + [t_hi] * _HISTORY,
            dtype=np.float32,
        )
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        w = self.reward_weights
        m = self.command_map
        self.consts = np.array([
            m.mid, m.half, float(control == "feed"), p.feed_velocity_mm_s, p.nominal_voltage,
            self.max_episode_time_s, p.torque_scale_Nmm, p.thrust_scale_N,
            SPEED_SCALE_HZ, LENGTH_SCALE_MM,
            *w.weights(),
        ])  # fmt: skip
        self.n = n
        self.lanes = DrillingLanes(p, n)
        self.scenarios: list[DrillingScenario | None] = [None] * n
        self.names = LaneNames(n)
        self.ev = np.zeros((n, _N_EV))
        self.flags = np.zeros((n, _N_FLAGS), dtype=np.bool_)
        self.counts = np.zeros((n, 2), dtype=np.int64)
        self.bound = np.full(n, np.nan)
        self.obs = np.zeros((n, 9 + _HISTORY), dtype=np.float32)
        #: The generators the lanes draw their noise from (their episodes').
        self.rngs = LaneGenerators(n)
        lanes = self.lanes
        self._args = (
            lanes.m, lanes.shared, lanes.par, lanes.eng, lanes.state, lanes.out,
            self.consts, self.ev, self.flags, self.counts, self.obs, self.rngs.table,
        )  # fmt: skip
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
        # control) or at the stage's top speed (feed control).
        v = p.feed_velocity_mm_s if self.control == "voltage" else p.feed_speed_max_mm_s
        x = np.array((u, truth.valve_static_gain_per_V * u, truth.free_speed_rad_s(u), 0.0, tr,
                      v, self._a0, self._c0))  # fmt: skip
        _start_packed(self._packed(self._args), lane,
                      self.lanes.lane_row(truth, c, d, target), c.engage_depth_mm,
                      c.engage_torque, c.engage_thrust, x, self.bound)  # fmt: skip
        self.rngs.bind(lane, rng)  # the hole's noise comes from it too
        breakage = float(self.lanes.par[lane, _P_BREAK])
        if not tr < breakage:  # the message is made only when it fails
            check_below(
                f"scenario {sc.name!r}: the torque limit (torque_limit_Nmm x torque_limit_scale)",
                tr,
                f"the {d:g} mm drill's breakage torque (breakage_coeff_N_per_mm2 x D^3)",
                breakage,
                "the drill would break before the limit binds",
            )

    def set_action(self, lane: int, action: float, clipped: bool) -> None:
        self.ev[lane, _E_ACTION] = action
        self.flags[lane, _F_IN_CLIPPED] = clipped

    def set_actions(self, actions: np.ndarray) -> None:
        self.ev[:, _E_ACTION] = actions[:, 0]  # clipped to the box by the kernel

    def outcome(self, lane: int) -> tuple[float, bool, bool]:
        f = self.flags[lane]
        return float(self.ev[lane, _E_REWARD]), bool(f[_F_TERMINATED]), bool(f[_F_TRUNCATED])

    def step_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.ev[:, _E_REWARD], self.flags[:, _F_TERMINATED], self.flags[:, _F_TRUNCATED]

    def clipped_count(self, lane: int) -> int:
        return int(self.counts[lane, _C_N_CLIPPED])

    def step(self) -> None:
        """Advance every lane with its action ``ev[:, _E_ACTION]`` (finite; clipped to the
        box, ``flags[:, _F_IN_CLIPPED]`` saying whether it was clipped already)."""
        if self.blocks.one:  # the single env, or few lanes: no blocks to hand out
            _step_packed(self._packed(self._args))
        else:
            self.blocks.run(_step, self._args, _STEP_AXES, packed=_step_packed, serve=_serve_step)

    def lane_info(self, k: int) -> dict:
        """The step info of lane ``k`` (after :meth:`step`)."""
        (torque, peak, thrust, _, meas_thrust, meas_speed, speed, valve, feed, _, per_rev,
         position, depth, packed, chip, cutting, engagement, finish) = self.lanes.out[k].tolist()  # fmt: skip
        e = self.ev[k].tolist()
        clipped, diverged, breakage, finished = self.flags[k, _F_CLIPPED:_F_TERMINATED].tolist()
        n_clipped, segment = self.counts[k].tolist()
        p = self.lanes.par[k]
        sc = self.scenarios[k]
        info = {
            "t_s": float(self.lanes.state[k, _S_T]),
            "command": e[_E_COMMAND],
            "action_clipped": clipped,
            "n_action_clipped": n_clipped,
            "breakage": breakage,
            "diverged": diverged,
            "finished": finished,
            "torque_Nmm": torque,
            "torque_limit_Nmm": e[_E_TR],
            "cost": 1.0 if self.flags[k, _F_OVER] else 0.0,
            "score_bound": float(self.bound[k]),
            "measured": e[_E_MEAS],
            "peak_torque_Nmm": peak,
            "breakage_torque_Nmm": float(p[_P_BREAK]),
            "thrust_N": thrust,
            "measured_thrust_N": meas_thrust,
            "spindle_hz": speed,
            "measured_spindle_hz": meas_speed,
            "spindle_rpm": 60.0 * speed,
            "voltage_V": e[_E_VOLTAGE],
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
        lane = self.lanes.par[:, [_P_BREAK, _P_TARGET, _P_D]]
        done = f[:, _F_FINISHED]
        finish = o[:, 17]  # NaN unless the hole was finished in this step
        return {
            "t_s": self.lanes.state[:, _S_T].copy(),
            "command": e[:, _E_COMMAND],
            "action_clipped": f[:, _F_CLIPPED],
            "n_action_clipped": c[:, _C_N_CLIPPED],
            "breakage": f[:, _F_BREAKAGE],
            "diverged": f[:, _F_DIVERGED],
            "finished": done,
            "torque_Nmm": o[:, 0],
            "torque_limit_Nmm": e[:, _E_TR],
            "cost": f[:, _F_OVER].astype(np.float64),
            "score_bound": self.bound.copy(),
            "measured": e[:, _E_MEAS],
            "peak_torque_Nmm": o[:, 1],
            "breakage_torque_Nmm": lane[:, 0],
            "thrust_N": o[:, 2],
            "measured_thrust_N": o[:, 4],
            "spindle_hz": o[:, 6],
            "measured_spindle_hz": o[:, 5],
            "spindle_rpm": 60.0 * o[:, 6],
            "voltage_V": e[:, _E_VOLTAGE],
            "valve_opening": o[:, 7],
            "feed_velocity_mm_s": o[:, 8],
            "feed_mm_per_rev": o[:, 10],
            "cutting": o[:, 15] != 0.0,
            "engagement": o[:, 16],
            "position_mm": o[:, 11],
            "depth_mm": o[:, 12],
            "target_depth_mm": lane[:, 1],
            "packed_chip_mm": o[:, 13],
            "chip_ratio": o[:, 14],
            "diameter_mm": lane[:, 2],
            "segment": c[:, _C_SEGMENT],
            "scenario": self.names.array(),
            "drilling_time_s": finish,
            "_drilling_time_s": done.copy(),
            "machining_time_s": finish.copy(),
            "_machining_time_s": done.copy(),
        }
