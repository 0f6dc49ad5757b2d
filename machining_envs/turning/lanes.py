"""The engine of ``Turning-v0``: the reward weights, the lane tables and the compiled
step, start and info of N lathes, which :class:`TurningEnv` (one lane) and
:class:`TurningVectorEnv` (N lanes) drive."""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np
from gymnasium import spaces

from machining_envs.core.actions import ActionMap
from machining_envs.core.actuation import (
    ActuationLanes,
    configure_lane,
    resolve_actuation,
)
from machining_envs.core.checks import PY_NUMBER_TYPES, check_below, check_range
from machining_envs.core.compiled.blocks import LaneBlocks, serve_one_table_with_tail
from machining_envs.core.compiled.kernels import clip_unit_linear
from machining_envs.core.compiled.normals import LaneGenerators, lane_noise
from machining_envs.core.compiled.packed import (
    PackedArgs,
    as_float,
    as_int,
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
    check_episode_time,
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
from machining_envs.core.reward import LimitReward, resolve_reward
from machining_envs.core.sensors import PowerSensorLanes, resolve_power_sensor
from machining_envs.core.workpieces import lane_segments, traverse_time
from machining_envs.turning.plant import (
    SPINDLE_RPM_RANGE,
    TurningLanes,
    TurningParams,
    lane_ints,
    spindle_drive,
    start_lane,
    step_lane,
)
from machining_envs.turning.scenarios import (
    TURNING_SCENARIOS,
    TurningScenario,
    _SplitFactory,
    bound_coefficient,
    machining_time_bound,
    turning_scenario,
)

_HISTORY = 3
_FORCE_OBS = (-1.0, 10.0)


#: The weights of the Turning reward (:class:`TurningEnv`, section Rewards): the
#: regulation envs' one weights type.
TurningReward = LimitReward


@numba.njit(cache=True)
def _env_lane(k, out, finish, t, gain, fs, meas, fr, vmax, brk, max_t, w, prev_action, fr_obs,
              rpm_obs, obs, reward, flags):  # fmt: skip
    """Reward, observation and episode flags of lane ``k`` from the plant's signals.

    ``fr`` holds the force limits; ``w`` = ``[tracking, overforce, target, progress,
    breakage]``; ``flags[k]`` = ``[diverged, breakage, finished, terminated, truncated,
    over the limit]``.
    """
    lo, hi = _FORCE_OBS
    force, peak, counts, pos = out[k, 0], out[k, 1], out[k, 2], out[k, 5]
    diverged = not (np.isfinite(force) and np.isfinite(counts) and np.isfinite(pos))
    if diverged:  # never seen; kept so that no NaN can reach an observation or a reward
        force = 0.0
        peak = 0.0
        counts = 0.0
        out[k, 0] = 0.0
        out[k, 1] = 0.0
        out[k, 2] = 0.0
    m = meas[k]
    for i in range(m.size - 1, 0, -1):
        m[i] = m[i - 1]
    m[0] = counts / gain
    breakage = peak > brk[k]
    finished = not np.isnan(finish[k])
    terminated = diverged or breakage or finished
    truncated = (not terminated) and t[k] >= max_t - 1e-9
    e = force / fr[k]
    r = -w[0] * abs(e / w[2] - 1.0) - w[1] * max(0.0, e - 1.0)
    if w[3]:
        r += w[3] * out[k, 4] / vmax[k]
    if breakage or diverged:
        r -= w[4]
    reward[k] = r
    flags[k, 0] = diverged
    flags[k, 1] = breakage
    flags[k, 2] = finished
    flags[k, 3] = terminated
    flags[k, 4] = truncated
    flags[k, 5] = force > fr[k]
    o = obs[k]
    o[0] = min(max(m[0] / fs, lo), hi)
    o[1] = fr_obs[k]
    o[2] = prev_action[k]
    o[3] = rpm_obs[k]
    for i in range(1, m.size):
        o[3 + i] = min(max(m[i] / fs, lo), hi)


#: Columns of ``TurningCore.ef``, the env's per-lane floats.
_EF = ("in_action", "in_command", "in_noise", "force_limit", "vmax", "breakage_force",
       "prev_action", "fr_obs", "rpm_obs", "reward", "command")  # fmt: skip
#: Columns of ``TurningCore.eb``, the env's per-lane flags: the six of ``flags``, then
#: ``in_clipped`` and ``clipped``.
_EB = ("diverged", "breakage", "finished", "terminated", "truncated", "over", "in_clipped",
       "clipped")  # fmt: skip


_EF_COMMAND = _EF.index("command")
_EF_REWARD = _EF.index("reward")
_EF_FORCE_LIMIT = _EF.index("force_limit")
_EF_VMAX = _EF.index("vmax")
_EF_BREAKAGE = _EF.index("breakage_force")
_EF_PREV_ACTION = _EF.index("prev_action")
_EF_FR_OBS = _EF.index("fr_obs")
_EF_RPM_OBS = _EF.index("rpm_obs")


#: The float keys of a vector step's info, one row each of the table
#: :func:`_info_rows` fills (``TurningCore.info_arrays``).
_INFO_F = ("t_s", "command", "force_N", "force_limit_N", "cost", "score_bound", "measured",
           "measured_counts", "peak_force_N", "feed_mm_per_rev", "feed_velocity_mm_s",
           "position_mm", "depth_mm", "spindle_rpm", "spindle_power_W", "cutting_power_W",
           "workpiece_length_mm", "machining_time_s")  # fmt: skip


@numba.njit(cache=True)
def _info_rows(lane_f, ef, eb, out, out_finish, meas, bound, spindle, diameter, length, rows):
    """Every lane's float info into ``rows`` (one row per key of ``_INFO_F``, one column per
    lane; rows spaced apart, ``core.compiled.packed.spaced_rows``), as
    :meth:`TurningCore.lane_info` reports it: the feed, feed velocity and position 0 after
    a divergence, the machining time NaN until the lane finishes, both powers
    ``cutting_power_W``'s (its arithmetic, in its order: an ideal spindle; the caller puts
    in the power-limited lanes' own)."""
    for k in range(out.shape[0]):
        o = out[k]
        ok = not eb[k, 0]
        rows[0, k] = lane_f[k, 5]
        rows[1, k] = ef[k, _EF_COMMAND]
        rows[2, k] = o[0]
        rows[3, k] = ef[k, _EF_FORCE_LIMIT]
        rows[4, k] = 1.0 if eb[k, 5] else 0.0
        rows[5, k] = bound[k]
        rows[6, k] = meas[k, 0]
        rows[7, k] = o[2]
        rows[8, k] = o[1]
        rows[9, k] = o[3] if ok else 0.0
        rows[10, k] = o[4] if ok else 0.0
        rows[11, k] = o[5] if ok else 0.0
        rows[12, k] = o[6]
        rows[13, k] = spindle[k]
        f = o[0] if (o[0] >= 0.0 or o[0] != o[0]) else 0.0  # numpy's maximum(f, 0.0)
        rows[14, k] = rows[15, k] = f * (spindle[k] * (math.pi / 30.0)) * (diameter[k] * 0.0005)
        rows[16, k] = length[k]
        rows[17, k] = out_finish[k] if eb[k, 2] else np.nan


@numba.njit(cache=True, inline="always")
def _env_floats(ef):
    """The columns of ``ef`` (``_EF``), as views."""
    return (ef[:, 0], ef[:, 1], ef[:, 2], ef[:, 3], ef[:, 4], ef[:, 5], ef[:, 6], ef[:, 7],
            ef[:, 8], ef[:, 9], ef[:, 10])  # fmt: skip


@numba.njit(cache=True, _nrt=False, nogil=True)
def _step(ef, eb, feed, li, filt, z, buf, base, edges, d0, slope, lane_f, finished, m, n_f,
          out, out_finish, gain, fs, meas, max_t, w, obs, n_clipped, rng_table,
          noise_counts, work):  # fmt: skip
    """One step of every lane: the actions' bookkeeping, the sensor noise, the plant, the
    env's outputs.

    ``ef`` and ``eb`` hold the env's per-lane floats and flags (``TurningCore``'s ``_EF``
    and ``_EB`` columns), ``li`` the plant's integers (``TurningLanes.li``). A lane with
    noise (``noise_counts[k]`` counts per unit normal) draws a normal from its generator
    (row ``rng_table[k]``, ``core.compiled.normals``), a lane without draws none. ``work`` is the
    plant's scratch (``TurningLanes.work``): nothing is allocated here, so it is compiled
    without reference counting (``_nrt=False``): the views of each lane's rows it makes cost
    no atomic counts (they took a fifth of it). ``matvec``, which it calls for filters outside
    the two-row scheme, keeps the runtime for what it hands to ``np.dot``.
    The env calls it through :func:`_step_packed` (one table for every argument)."""
    (actions, commands, noise, fr, vmax, brk, prev_action, fr_obs, rpm_obs, reward,
     last_command) = _env_floats(ef)  # fmt: skip
    flags, clipped, last_clipped = eb[:, :6], eb[:, 6], eb[:, 7]
    cols, nseg, seg, out_seg = lane_ints(li)
    t = lane_f[:, 5]
    for k in range(z.shape[0]):
        prev_action[k] = actions[k]
        last_command[k] = commands[k]
        last_clipped[k] = clipped[k]
        n_clipped[k] += clipped[k]
        noise[k] = lane_noise(rng_table, k, noise_counts[k])
        step_lane(
            k, feed, base, cols, li, filt, z, buf, work, edges, d0, slope, nseg, seg, lane_f,
            finished, m, n_f, commands[k], noise[k], out, out_seg, out_finish,
        )  # fmt: skip
        _env_lane(k, out, out_finish, t, gain, fs, meas, fr, vmax, brk, max_t, w, prev_action,
                  fr_obs, rpm_obs, obs, reward, flags)  # fmt: skip


@numba.njit(cache=True, nogil=True)
def _step_packed(t, op):
    """The core's kernel with its arguments in one table (``core.compiled.packed``;
    ``TurningCore._kernel_args``), one array to unbox, not one per argument: ``op`` 0 is
    :func:`_step` of the table's lanes, 1 starts those of its lanes that the pending table
    lists (:func:`_start_pending`). On several threads each block of lanes runs it on its
    own table, so a vector env's resetting lanes start on the blocks' threads too."""
    if op == 0:
        _step(f8_2(t, 0), b1_2(t, 1), f8_2(t, 2), i8_2(t, 3), f8_2(t, 4), f8_2(t, 5), f8_2(t, 6),
              f8_1(t, 7), f8_2(t, 8), f8_2(t, 9), f8_2(t, 10), f8_2(t, 11), b1_1(t, 12),
              as_int(t, 13), as_int(t, 14), f8_2(t, 15), f8_1(t, 16), as_float(t, 17),
              as_float(t, 18), f8_2(t, 19), as_float(t, 20), f8_1(t, 21), f4_2(t, 22),
              i8_1(t, 23), i8_2(t, 24), f8_1(t, 25), f8_2(t, 26))  # fmt: skip
    else:
        _start_pending(t)


@numba.njit(cache=True, nogil=True)
def _serve_step(ctl, table, polls):
    """The lane blocks' worker loop for :func:`_step_packed` (``core.compiled.blocks``), compiled with
    this module and cached, not at the first step on several threads."""
    return serve_one_table_with_tail(_step_packed, ctl, table, polls)


#: Where the kernel's table (``TurningCore._kernel_args``) holds, after :func:`_step`'s
#: arguments, the other arrays :func:`_start` writes and the linear blocks' tables, then
#: each lane's index, then the pending starts: ``[count, lanes...]``, the split's numbers,
#: and each pending lane's speed, uniforms, segments, segment count and whether its step
#: matrix was made. (The noise scales :func:`_start` writes are :func:`_step`'s, at 25.)
_T_START = 27
_T_LANE = _T_START + 13
_T_PENDING = _T_LANE + 1


@numba.njit(cache=True)
def _start_pending(t):
    """:func:`_start_drawn_lanes` for the pending lanes (the table's, ``_T_PENDING``) that
    lie in the table's block of lanes (its first lane's index at ``_T_LANE``), each lane
    writing its own rows and its ``ok``."""
    first = i8_1(t, _T_LANE)
    pending = i8_1(t, _T_PENDING)
    p = _T_PENDING
    _start_drawn_lanes(t, pending[1 : pending[0] + 1], first[0], first[0] + first.size,
                       f8_1(t, p + 1), f8_1(t, p + 2), f8_2(t, p + 3), f8_3(t, p + 4),
                       i8_1(t, p + 5), b1_1(t, p + 6))  # fmt: skip


@numba.njit(cache=True)
def _start(k, full_history, consts, segments, x, ef, eb, feed, li, z, buf, edges, d0, slope,
           lane_f, finished, out, out_finish, fs, meas, obs, n_clipped, bound, noise_counts,
           spindle, spindle_set, power, diameter, length, spindle_rpm, phis, gams,
           base, sa, sb, ts):  # fmt: skip
    """The arrays of lane ``k`` at the start of an episode (``TurningCore.start``): the
    plant's (:func:`~machining_envs.turning.plant.start_lane`, whose return it returns),
    then the env's, the tool at rest at the workpiece's start.

    ``x`` = ``[rpm, force limit, Vmax, breakage force, noise (counts), diameter, score
    bound, spindle power]`` of the cut (the bound NaN: computed here, for a sharp tool, as
    :func:`~machining_envs.turning.scenarios.machining_time_bound` does), ``consts`` the
    plant's lane constants (``TurningLanes.lane_constants``).
    """
    rpm, limit, vmax, brk, noise, diam, b = x[0], x[1], x[2], x[3], x[4], x[5], x[6]
    ok = start_lane(k, rpm, full_history, consts, segments, phis, gams, base, sa, sb, ts, feed,
                    li, z, buf, edges, d0, slope, lane_f, finished, spindle_rpm)  # fmt: skip
    if b != b:  # machining_time_bound with no wear: traverse_time_s's closed form (left
        # NaN, for machining_time_bound to refuse, where that refuses its numbers)
        p = consts[1]
        c = bound_coefficient(consts[0], p, limit, x[7], diam, rpm)
        if c > 0.0 and p > 0.0 and vmax > 0.0:
            b = traverse_time(segments, c, 1.0 / p, vmax)
    fr_obs = min(limit / fs, 10.0)
    rpm_obs = rpm / 1000.0
    e = ef[k]
    e[_EF_FORCE_LIMIT] = limit
    e[_EF_VMAX] = vmax
    e[_EF_BREAKAGE] = brk
    e[_EF_PREV_ACTION] = -1.0
    e[_EF_FR_OBS] = fr_obs
    e[_EF_RPM_OBS] = rpm_obs
    e[_EF_COMMAND] = 0.0
    bound[k] = b
    noise_counts[k] = noise
    meas[k, :] = 0.0
    n_clipped[k] = 0
    spindle[k] = rpm
    spindle_set[k] = rpm
    power[k, :] = 0.0
    diameter[k] = diam
    ns = segments.shape[1] - 1
    length[k] = segments[0, ns]
    o = obs[k]
    o[:] = 0.0
    o[1] = fr_obs
    o[2] = -1.0
    o[3] = rpm_obs
    # The signals of a cut not yet begun, where lane_info and info_arrays read them until the
    # first step (which writes every one): the tool at rest at the workpiece's start.
    eb[k, :] = False
    out[k, :] = 0.0
    out[k, 6] = segments[1, 0]  # the depth at the start
    li[k, 3] = 0  # the segment
    out_finish[k] = np.nan
    return ok


#: The numbers :func:`_start_drawn_lanes` reads of a split and the nominal parameters
#: (``_batch_numbers``), in its order.
_BATCH_NUMBERS = (
    "force_coefficient", "feed_exponent", "sensor_gain", "command_max", "margin",
    "spindle_power_W", "max_feed_velocity_mm_s", "breakage_force_N", "noise_std_N",
    "workpiece_diameter_mm", "kf_low", "kf_span", "p_low", "p_span", "noise_low", "noise_span",
    "limit_varies", "limit_low", "limit_span",
)  # fmt: skip


def _batch_numbers(core, factory) -> np.ndarray:
    """What :func:`_start_drawn_lanes` reads (``_BATCH_NUMBERS``) for lanes of
    ``factory``'s split on ``core``'s nominal parameters: the numbers
    ``TurningScenario.true_params`` and ``TurningLanes.lane_constants`` take."""
    p = core.params
    power = factory.shop["spindle_power_W"]
    power = power if math.isfinite(power) else p.spindle_power_W
    ke, cmax, margin = core.lanes.lane_constants(p)[2:5]
    lows, spans = factory.lows, factory.spans
    varies = factory.limit_varies
    limit = (lows[3], spans[3]) if varies else (float(factory.limit_N[0]), 0.0)
    nums = np.array([
        p.force_coefficient, p.feed_exponent, ke, cmax, margin, power,
        p.max_feed_velocity_mm_s, p.breakage_force_N, p.noise_std_N, p.workpiece_diameter_mm,
        lows[0], spans[0], lows[1], spans[1], lows[2], spans[2], float(varies), *limit,
    ], dtype=np.float64)  # fmt: skip
    assert nums.size == len(_BATCH_NUMBERS)
    return nums


@numba.njit(cache=True)
def _start_drawn_lanes(t, lanes, lo, hi, nums, rpm, v, segments, counts, ok):
    """:func:`_start_packed` for every lane ``lanes[i]`` of a split's batch that lies in
    ``lo .. hi - 1`` (the lanes of ``t``, whose first is lane ``lo``): its speed ``rpm[i]``,
    segments ``segments[i, :, : counts[i] + 1]`` and uniforms ``v[i]`` (the split factory's
    ``draw_lanes``), on the split's and nominal numbers ``nums`` (``_batch_numbers``): the
    true parameters ``TurningScenario.true_params`` makes of them (a sharp tool), in its
    order of operations. ``ok[i]``: whether the lane's step matrix was made
    (:func:`_start_packed`'s return)."""
    (kf, pexp, ke, cmax, margin, power, vmax, brk, noise_std, diam, kf_lo, kf_span, p_lo,
     p_span, n_lo, n_span, varies, l_lo, l_span) = (
        nums[0], nums[1], nums[2], nums[3], nums[4], nums[5], nums[6], nums[7], nums[8],
        nums[9], nums[10], nums[11], nums[12], nums[13], nums[14], nums[15], nums[16],
        nums[17], nums[18])  # fmt: skip
    full = math.isfinite(power)
    x = np.empty(8)
    for i in range(lanes.size):
        if not lo <= lanes[i] < hi:
            continue
        vi = v[i]
        consts = (kf * (kf_lo + kf_span * vi[0]), pexp * (p_lo + p_span * vi[1]), ke, cmax,
                  margin, 0.0)  # fmt: skip
        x[0] = rpm[i]
        x[1] = l_lo + l_span * vi[3] if varies != 0.0 else l_lo
        x[2] = vmax
        x[3] = brk
        x[4] = ke * (noise_std * (n_lo + n_span * vi[2]))  # the sensor's gain Ke
        x[5] = diam
        x[6] = np.nan
        x[7] = power
        ok[i] = _start_packed(t, lanes[i] - lo, full, consts, lane_segments(segments, i, counts), x)


@numba.njit(cache=True)
def _start_packed(t, k, full_history, consts, segments, x):
    """:func:`_start` with its arrays in the kernel's table ``t`` (:func:`_step_packed`'s:
    the step's, then the start's from ``_T_START``); ``k`` is the lane's index in ``t``."""
    s = _T_START
    return _start(
        k, full_history, consts, segments, x, f8_2(t, 0), b1_2(t, 1), f8_2(t, 2), i8_2(t, 3),
        f8_2(t, 5), f8_2(t, 6), f8_2(t, 8), f8_2(t, 9), f8_2(t, 10), f8_2(t, 11), b1_1(t, 12),
        f8_2(t, 15), f8_1(t, 16), as_float(t, 18), f8_2(t, 19), f4_2(t, 22), i8_1(t, 23),
        f8_1(t, s), f8_1(t, 25), f8_1(t, s + 1), f8_1(t, s + 2), f8_2(t, s + 3),
        f8_1(t, s + 4), f8_1(t, s + 5), f8_1(t, s + 6), f8_3(t, s + 7), f8_2(t, s + 8),
        f8_2(t, s + 9), f8_2(t, s + 10), f8_2(t, s + 11), as_float(t, s + 12),
    )  # fmt: skip


#: Where :func:`_step`'s arguments (``TurningCore._kernel_args``) hold the lanes: axis 0
#: or none (shared), for :class:`~machining_envs.core.compiled.blocks.LaneBlocks`.
_STEP_AXES = (
    0, 0, 0, 0, None, 0, 0, None, 0, 0, 0, 0, 0, None, None, 0, 0, None, None, 0, None, None, 0, 0, 0,
    0, 0,  # _step's
    0, 0, 0, 0, 0, 0, 0, None, None, None, None, None, None,  # the start's (_T_START)
    0,  # each lane's index (_T_LANE)
    None, None, None, None, None, None, None,  # the pending starts (_T_PENDING)
)  # fmt: skip


class TurningCore(LaneCore):
    """The state and arithmetic of N turning episodes, shared by ``TurningEnv`` (one lane)
    and ``TurningVectorEnv`` (N lanes): the plant (:class:`TurningLanes`) and the reward,
    observation and episode end computed for all lanes by one compiled function, so that a
    lane of the vector env and the single env agree to the last bit."""

    #: What a scenario may be: an object of this class or one of these names.
    scenario_types = (TurningScenario, TURNING_SCENARIOS)
    VIEWS = frozenset({*_EF, "flags", "in_clipped", "clipped", "_args"})

    def __init__(self, owner, n, scenario, params, spindle_rpm, reward, max_episode_time_s,
                 overrides, actuation=None, power_sensor=None):  # fmt: skip
        self.params = resolve_params(
            owner, params, TurningParams, TurningParams.noh_kim_kim_1992, overrides
        )
        sensor = resolve_power_sensor(power_sensor)  # the spindle power as the load channel
        self.power_sensor = sensor and PowerSensorLanes(sensor, n, self.params.sample_time_s)
        self.actuation = resolve_actuation(actuation)
        if spindle_rpm is not None:
            spindle_rpm = check_range(
                "spindle_rpm", spindle_rpm, *SPINDLE_RPM_RANGE, types=PY_NUMBER_TYPES
            )
        self.spindle_rpm_override = spindle_rpm
        self.reward_weights = resolve_reward(reward, TurningReward)
        w = self.reward_weights
        self._w = w.weights()
        self.max_episode_time_s = check_episode_time(max_episode_time_s)
        check_scenario_spec(scenario, TurningScenario, TURNING_SCENARIOS)
        self._gain = float(self.params.sensor_gain)
        self._fs = float(self.params.force_scale_N)
        self.command_map = ActionMap(0.0, self.params.command_max)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        f_lo, f_hi = _FORCE_OBS
        low = np.array([f_lo, 0.0, -1.0, 0.0] + [f_lo] * _HISTORY, dtype=np.float32)
        high = np.array(
            [f_hi, 10.0, 1.0, SPINDLE_RPM_RANGE[1] / 1000.0] + [f_hi] * _HISTORY, dtype=np.float32
        )
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.n = n
        # The CNC's actuation, made now if the option sets it (its checks fail here), else
        # when a scenario first brings its own.
        self.act_lanes = None if self.actuation is None else self.actuation_lanes()
        self.lanes = TurningLanes(self.params, n)
        #: Every lane's scenario and true parameters (built when read, for lanes started
        #: together by :meth:`start_lanes`).
        self.scenarios = LaneObjects(n)
        # The per-lane floats and flags the kernel reads and writes, each set in one array
        # (one argument of the kernel) and named here by views of its columns.
        self.ef = np.zeros((n, len(_EF)))
        self.eb = np.zeros((n, len(_EB)), dtype=np.bool_)
        self.bind_views()
        self.force_limit[:] = 1.0
        self.vmax[:] = 1.0
        self.breakage_force[:] = 1.0
        self.prev_action[:] = -1.0
        self.bound = np.full(n, np.nan)
        self.noise_counts = np.zeros(n)
        self.meas = np.zeros((n, _HISTORY + 1))  # newest first, N
        self.n_clipped = np.zeros(n, dtype=np.int64)
        self.obs = np.zeros((n, 4 + _HISTORY), dtype=np.float32)
        #: The generators the lanes draw their sensor noise from (their episodes').
        self.rngs = LaneGenerators(n)
        self.spindle = np.zeros(n)
        self.spindle_set = np.zeros(n)
        #: Drive power delivered and cutting power at the last sample, W.
        self.power = np.zeros((n, 2))
        self.truths = LaneObjects(n)
        self._batch_ok: dict = {}  # batches' checks, by factory
        self._batch_numbers: dict = {}  # _batch_numbers, by factory
        #: Per lane: (score bound, workpiece length, scenario name, set spindle speed,
        #: diameter) of its episode, as Python values; None for a lane started with others
        #: until lane_info reads it from the arrays.
        self.episode_info: list[tuple | None] = [(math.nan, 0.0, "", 0.0, 0.0)] * n
        self.diameter = np.ones(n)
        #: Lanes whose spindle is power-limited (their speed may change within the cut).
        self.power_lanes: set[int] = set()
        self.length = np.zeros(n)
        self.names = LaneNames(n)
        self._args: tuple | None = None
        self._args_version = -1
        self._packed = PackedArgs()  # the kernel's arguments in one table (core.compiled.packed)
        #: Each lane's index (a block's first tells the kernel where its lanes begin).
        self.lane_index = np.arange(n, dtype=np.int64)
        #: The starts a vector env's blocks make (_start_pending): [count, lanes...], the
        #: split's numbers, and each lane's draws (sized for the first batch, grown with it).
        self._pending = np.zeros(n + 1, dtype=np.int64)
        self._pending_draws = (np.zeros(len(_BATCH_NUMBERS)), np.zeros(n), np.zeros((n, 4)),
                               np.zeros((n, 4, 2)), np.zeros(n, dtype=np.int64),
                               np.zeros(n, dtype=np.bool_))  # fmt: skip
        #: The blocks of lanes the kernel steps at once (one thread unless a vector env
        #: asks for more).
        self.blocks = LaneBlocks(n)

    def bind_views(self) -> None:
        """Name the columns of ``ef`` (``_EF``) and ``eb`` (``_EB``)."""
        for i, name in enumerate(_EF):
            setattr(self, name, self.ef[:, i])
        self.flags = self.eb[:, :6]
        self.in_clipped = self.eb[:, 6]
        self.clipped = self.eb[:, 7]

    def set_action(self, lane: int, action: float, clipped: bool) -> None:
        ef = self.ef[lane]
        ef[0] = action  # in_action, in_command (_EF)
        ef[1] = self.command_map.action_to_command(action)
        self.in_clipped[lane] = clipped

    def set_actions(self, actions: np.ndarray) -> None:
        m = self.command_map  # linear: one compiled pass clips and maps
        clip_unit_linear(actions[:, 0], self.in_action, self.in_clipped, self.in_command,
                         m.mid, m.half)  # fmt: skip

    def outcome(self, lane: int) -> tuple[float, bool, bool]:
        terminated, truncated = self.eb[lane, 3:5].tolist()
        return float(self.ef[lane, _EF_REWARD]), terminated, truncated

    def step_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.reward, self.flags[:, 3], self.flags[:, 4]

    def clipped_count(self, lane: int) -> int:
        return int(self.n_clipped[lane])

    def actuation_lanes(self) -> ActuationLanes:
        """The CNC's actuation between the commands and the servo, every lane on the env's
        option until its scenario says otherwise."""
        p = self.params
        return ActuationLanes(self.n, p.command_max, 0.0, p.sample_time_s, self.actuation)

    def start(self, lane: int, spec, rng: np.random.Generator) -> None:
        """Start an episode in ``lane`` on the scenario ``spec`` (drawn with ``rng``); its
        first observation goes to ``obs[lane]``, its reset info is its :meth:`lane_info`
        (and its column of :meth:`info_arrays`) until the first step."""
        sc = turning_scenario(spec, rng)
        self.rngs.bind(lane, rng)  # the episode's sensor noise comes from it too
        if self.spindle_rpm_override is not None:
            sc = dataclasses.replace(sc, spindle_rpm=self.spindle_rpm_override)
        self.scenarios[lane] = sc
        truth = sc.true_params(self.params)
        limit = float(sc.force_limit_N)
        if not limit < truth.breakage_force_N:  # the message is made only when it fails
            check_below(
                f"scenario {sc.name!r}: force_limit_N",
                limit,
                "the tool's breakage_force_N",
                truth.breakage_force_N,
                "the tool would break before the limit binds",
            )
        # (true_params changes no field of the linear blocks, so the lane fits the batch.)
        lanes = self.lanes
        profile = sc.profile
        segments = profile.segment_copy()
        lanes.fit_segments(segments.shape[1] - 1)
        rpm = float(sc.spindle_rpm)
        power_W = float(truth.spindle_power_W)
        full = math.isfinite(power_W)
        diameter = float(truth.workpiece_diameter_mm)
        # The score bound: computed by the kernel for a sharp tool, here with wear.
        bound = math.nan if truth.wear_per_100mm == 0.0 else machining_time_bound(sc, truth)
        x = np.array((rpm, limit, truth.max_feed_velocity_mm_s, truth.breakage_force_N,
                      truth.sensor_gain * truth.noise_std_N, diameter, bound, power_W))  # fmt: skip
        if not _start_packed(
            self._packed(self._kernel_args()), lane, full, lanes.lane_constants(truth),
            segments, x,
        ):  # fmt: skip
            lanes._load_matrices(lane, rpm, full)
        if not self.bound[lane] == self.bound[lane]:  # refused by the kernel: let it say why
            self.bound[lane] = machining_time_bound(sc, truth)
        self.act_lanes = configure_lane(
            self.act_lanes, lane, sc.actuation, self.actuation, self.actuation_lanes
        )
        self.truths[lane] = truth
        if full:
            self.power_lanes.add(lane)
        else:
            self.power_lanes.discard(lane)
        self.names[lane] = sc.name
        # What the episode's infos repeat, as Python values: read once, not at every step.
        self.episode_info[lane] = (float(self.bound[lane]), float(self.length[lane]), sc.name,
                                   rpm, diameter)  # fmt: skip
        if self.power_sensor:
            self._sense_power([lane])

    def start_lanes(self, lanes: np.ndarray, spec, rngs) -> None:
        """:meth:`start` for each lane ``k`` of ``lanes`` on the scenario ``spec``, drawn
        with ``rngs[k]``: the same episodes, the same numbers. A split's scenarios (a name
        such as ``"train"``) are drawn and started for all lanes in two compiled calls, and
        a lane's scenario and true parameters are built only when read (``scenarios[k]``,
        ``truths[k]``)."""
        factory = split_batch(self, lanes, spec, rngs, TURNING_SCENARIOS)
        if factory is None:
            return
        rpm, segments, counts, v = factory.draw_lanes(self.rngs.table, lanes)
        nums = self._batch_numbers.get(factory)
        if nums is None:
            nums = self._batch_numbers[factory] = _batch_numbers(self, factory)
        full = math.isfinite(nums[5])
        self.lanes.fit_segments(int(counts.max()))
        if self.blocks.one:
            ok = np.empty(lanes.size, dtype=np.bool_)
            _start_drawn_lanes(self._packed(self._kernel_args()), lanes, 0, self.n, nums, rpm, v,
                               segments, counts, ok)  # fmt: skip
        else:  # each block of lanes starts its own, on its thread
            ok = self._start_in_blocks(lanes, nums, rpm, v, segments, counts)
        ks = lanes.tolist()
        if not ok.all():
            for i in np.flatnonzero(~ok).tolist():  # left for zoh (never in the plant's ranges)
                self.lanes._load_matrices(ks[i], float(rpm[i]), full)
        settle_batch(self, lanes, factory.build_lane, (rpm, segments, counts, v),
                     factory.shop["actuation"], factory.name)  # fmt: skip
        bounds = self.bound[lanes]
        if np.isnan(bounds).any():  # refused by the kernel: let it say why
            for i in np.flatnonzero(bounds != bounds).tolist():
                k = ks[i]
                self.bound[k] = machining_time_bound(self.scenarios[k], self.truths[k])
        if full:
            self.power_lanes.update(ks)
        else:
            self.power_lanes.difference_update(ks)
        info = self.episode_info
        for k in ks:
            info[k] = None  # lane_info reads it from the arrays
        if self.power_sensor:
            self._sense_power(lanes)

    def batches(self, factory) -> bool:
        """Whether :meth:`start_lanes` may start ``factory``'s scenarios in one batch: a
        split's, without wear (whose score bound is integrated in Python) or a spindle
        speed set by the env, whose every true parameter set passes the checks
        ``start`` makes (those of the ranges' two ends, checked once)."""
        if not isinstance(factory, _SplitFactory) or factory.wear is not None:
            return False
        if self.spindle_rpm_override is not None:
            return False
        ok = self._batch_ok.get(factory)
        if ok is None:
            try:
                for sc in factory.extremes:
                    truth = sc.true_params(self.params)
                    ok = float(sc.force_limit_N) < truth.breakage_force_N
                    if not ok:
                        break
            except ValueError:
                ok = False
            self._batch_ok[factory] = ok
        return ok

    def _kernel_args(self) -> tuple:
        """The kernel's arguments (:func:`_step`'s, then from ``_T_START`` on what
        :func:`_start` writes besides and the pending starts), in order, rebuilt when the
        plant's arrays are: one table serves the step and every start."""
        lanes = self.lanes
        if self._args is None or self._args_version != lanes.version:
            self._args = (
                self.ef,
                self.eb,
                lanes.feed,
                lanes.li,
                lanes.filt,
                lanes.z,
                lanes.buf,
                lanes.base,
                lanes.edges,
                lanes.d0,
                lanes.slope,
                lanes.lane_f,
                lanes.finished,
                lanes.m,
                lanes.n_f,
                lanes.out,
                lanes.out_finish,
                self._gain,
                self._fs,
                self.meas,
                self.max_episode_time_s,
                self._w,
                self.obs,
                self.n_clipped,
                self.rngs.table,
                self.noise_counts,
                lanes.work,
                # what _start writes besides (_T_START), and the linear blocks' tables
                self.bound,
                self.spindle,
                self.spindle_set,
                self.power,
                self.diameter,
                self.length,
                lanes.spindle_rpm,
                *lanes.speed_free,
                self.lane_index,
                self._pending,
                *self._pending_draws,
            )
            self._args_version = lanes.version
        return self._args

    def step(self) -> None:
        """Advance every lane with the inputs in ``in_action`` (clipped to the box),
        ``in_clipped`` (whether it was clipped) and ``in_command`` (the command it maps to),
        each lane's sensor noise drawn from the generator its episode started with; with CNC
        actuation on, the commands pass through it first (``machining_envs.core.actuation``)."""
        if self.act_lanes is not None:
            self.in_command[:] = self.act_lanes.apply(self.in_command)
        if self.blocks.one:  # the single env, or few lanes: no blocks to hand out
            _step_packed(self._packed(self._kernel_args()), 0)
        else:
            self._run_blocks(0)
        if self.power_lanes:
            self._spindle_drives()
        if self.power_sensor:
            self._sense_power()

    def _sense_power(self, lanes=None) -> None:
        """The drive's power reading into the observations (option ``power_sensor``,
        ``machining_envs.core.sensors``): of ``lanes`` that start, else a step of all."""
        # info's spindle_rpm, cutting_power_W and force_limit_N, from the lanes' tables (the
        # arithmetic of _info_rows, in its order), without building the whole info
        rpm = self.spindle
        v = rpm * (math.pi / 30.0) * self.diameter * 0.0005  # cutting speed, m/s
        cutting = (
            np.maximum(self.lanes.out[:, 0], 0.0)
            * (rpm * (math.pi / 30.0))
            * (self.diameter * 0.0005)
        )
        for k in self.power_lanes:  # a power-limited spindle's own
            cutting[k] = self.power[k, 1]
        self.power_sensor.update(self.obs, lanes, cutting, rpm, self.ef[:, _EF_FORCE_LIMIT] * v)

    def _run_blocks(self, op: int) -> None:
        """:func:`_step_packed`'s ``op`` on every block of lanes, on the blocks' threads
        (its tables always pack: every array holds the lanes on axis 0 or is shared)."""
        self.blocks.run(_step, self._kernel_args(), _STEP_AXES, op, packed=_step_packed,
                        serve=_serve_step)  # fmt: skip

    def _start_in_blocks(self, lanes, nums, rpm, v, segments, counts) -> np.ndarray:
        """:func:`_start_drawn_lanes` for a batch, each block of lanes starting its own on
        its thread (:func:`_start_pending`): the same numbers as one call over the batch.
        Whether each lane's step matrix was made."""
        size = lanes.size
        shapes = (v.shape[1], segments.shape[2])
        draws = self._pending_draws
        if shapes[0] > draws[2].shape[1] or shapes[1] > draws[3].shape[2]:  # grow them
            n = self.n
            self._pending_draws = draws = (
                draws[0], draws[1], np.zeros((n, max(shapes[0], draws[2].shape[1]))),
                np.zeros((n, 4, max(shapes[1], draws[3].shape[2]))), draws[4], draws[5],
            )  # fmt: skip
            self._args = None  # the kernel's table holds them
        p_nums, p_rpm, p_v, p_segments, p_counts, p_ok = draws
        self._pending[0] = size
        self._pending[1 : size + 1] = lanes
        p_nums[:] = nums
        p_rpm[:size] = rpm
        p_v[:size, : shapes[0]] = v
        p_segments[:size, :, : shapes[1]] = segments
        p_counts[:size] = counts
        self._run_blocks(1)
        return p_ok[:size].copy()

    def _spindle_drives(self) -> None:
        """The power-limited spindles (``TurningParams.spindle_power_W``): each lane's speed
        for the next sample from :func:`~machining_envs.turning.plant.spindle_drive`; the
        next observation shows it."""
        for k in self.power_lanes:
            if self.flags[k, 3]:
                continue
            rpm = float(self.spindle[k])
            new, p_drive, p_cut = spindle_drive(
                self.truths[k], rpm, float(self.spindle_set[k]), float(self.lanes.out[k, 0])
            )
            self.power[k] = (p_drive, p_cut)
            if new != rpm:
                self.lanes.set_speed(k, new)
                self.spindle[k] = new
                self.rpm_obs[k] = new / 1000.0
                self.obs[k, 3] = self.rpm_obs[k]

    def lane_info(self, k: int) -> dict:
        """The step info of lane ``k`` (after :meth:`step`)."""
        lanes = self.lanes
        force, peak, counts, feed, vel, pos, depth = lanes.out[k].tolist()
        diverged, breakage, finished, _, _, over, _, clipped = self.eb[k].tolist()
        ef = self.ef[k].tolist()
        episode = self.episode_info[k]
        if episode is None:  # a lane started with others (start_lanes)
            episode = self.episode_info[k] = (
                float(self.bound[k]), float(self.length[k]), self.names[k],
                float(self.spindle_set[k]), float(self.diameter[k]),
            )  # fmt: skip
        bound, length, name, rpm, diameter = episode
        if k in self.power_lanes:  # drive and cutting power from the spindle's drive
            p_drive, p_cut = self.power[k].tolist()
            rpm = float(self.spindle[k])
        else:  # an ideal spindle delivers what the cut asks: cutting_power_W's arithmetic,
            # in its order, on Python floats (the same numbers as _info_rows)
            p_drive = p_cut = max(force, 0.0) * (rpm * (math.pi / 30.0)) * (diameter * 0.0005)
        info = {
            "t_s": float(lanes.lane_f[k, 5]),
            "command": ef[_EF_COMMAND],
            "action_clipped": clipped,
            "n_action_clipped": int(self.n_clipped[k]),
            "breakage": breakage,
            "diverged": diverged,
            "finished": finished,
            "force_N": force,
            "force_limit_N": ef[_EF_FORCE_LIMIT],
            "cost": 1.0 if over else 0.0,
            "score_bound": bound,
            "measured": float(self.meas[k, 0]),
            "measured_counts": counts,
            "peak_force_N": peak,
            "feed_mm_per_rev": feed if not diverged else 0.0,
            "feed_velocity_mm_s": vel if not diverged else 0.0,
            "position_mm": pos if not diverged else 0.0,
            "depth_mm": depth,
            "segment": int(lanes.out_segment[k]),
            "spindle_rpm": rpm,
            "spindle_power_W": p_drive,
            "cutting_power_W": p_cut,
            "workpiece_length_mm": length,
            "scenario": name,
        }
        if finished:
            info["machining_time_s"] = float(lanes.out_finish[k])
        if self.power_sensor:
            info.update(self.power_sensor.lane_info(k))
        return info

    def info_arrays(self) -> dict:
        """The step info of every lane, as arrays (``machining_time_s`` with its mask): views
        of one table of the float keys (:func:`_info_rows`) and one copy of the flags."""
        c = spaced_rows(len(_INFO_F), self.n)
        _info_rows(self.lanes.lane_f, self.ef, self.eb, self.lanes.out, self.lanes.out_finish,
                   self.meas, self.bound, self.spindle, self.diameter, self.length, c)  # fmt: skip
        for k in self.power_lanes:  # drive and cutting power from the spindle's drive
            c[14, k], c[15, k] = self.power[k]
        f = self.eb.copy()
        info = dict(zip(_INFO_F, c, strict=True))
        return {
            "t_s": info["t_s"],
            "command": info["command"],
            "action_clipped": f[:, 7],
            "n_action_clipped": self.n_clipped.copy(),
            "breakage": f[:, 1],
            "diverged": f[:, 0],
            "finished": f[:, 2],
            **{k: info[k] for k in _INFO_F[2:13]},
            "segment": self.lanes.out_segment.copy(),
            **{k: info[k] for k in _INFO_F[13:17]},
            "scenario": self.names.array(),
            "machining_time_s": info["machining_time_s"],
            "_machining_time_s": self.eb[:, 2].copy(),
            **(self.power_sensor.info_arrays() if self.power_sensor else {}),
        }
