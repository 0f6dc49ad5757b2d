"""The engine of ``EndMilling-v0``: the reward weights, the lane tables and the compiled
step, start and info of N milling machines, which :class:`EndMillingEnv` (one lane) and
:class:`EndMillingVectorEnv` (N lanes) drive."""

from __future__ import annotations

import enum
import math

import numba
import numpy as np

from machining_envs.core.actions import ACTION_MAPS, ActionMap
from machining_envs.core.actuation import configure_lane
from machining_envs.core.checks import check_below
from machining_envs.core.compiled.blocks import LaneBlocks, serve_one_table_with_tail
from machining_envs.core.compiled.kernels import copy_into, set_episode_flags
from machining_envs.core.compiled.normals import LaneGenerators, lane_noise
from machining_envs.core.compiled.packed import PackedArgs, spaced_rows
from machining_envs.core.compiled.schema import axes, flatten, gather, offsets, record, via_table
from machining_envs.core.lanes import (
    REGULATION_HISTORY,
    FeedRegulationCore,
    LaneNames,
    LaneObjects,
    settle_batch,
)
from machining_envs.core.reward import LimitReward
from machining_envs.core.workpieces import lane_segments, traverse_time
from machining_envs.milling.plant import (
    KGF,
    LANE_CONSTANTS,
    LC,
    SPINDLE_RPM_RANGE,
    MillingArrays,
    MillingLanes,
    MillingParams,
    check_depth,
    start_lane,
    step_lanes,
)
from machining_envs.milling.scenarios import (
    MILLING_SCENARIOS,
    MillingScenario,
    _SplitFactory,
    bound_coefficient,
    cut_area_at,
    machining_time_bound,
    milling_scenario,
)

_HISTORY = REGULATION_HISTORY
#: Decades spanned by the command on the default logarithmic action map: the feeds that
#: hold the torque on the test set span about two (the feed exponent m ~ 0.4 turns a 2x
#: change of depth, Ks or reference into a ~5x change of feed), and one more keeps slow
#: approach feeds resolvable.
COMMAND_DECADES = 3.0
_TORQUE_OBS = (-1.0, 10.0)
#: The numeric step info computed by the compiled step, one row each (``MillingCore.info_f``).
_INFO_F = (
    "t_s",
    "command",
    "torque_Nmm",
    "measured",
    "measured_counts",
    "peak_torque_Nmm",
    "feed_mm_per_rev",
    "mean_feed_mm_per_rev",
    "feed_per_tooth_mm",
    "feed_velocity_mm_s",
    "position_mm",
    "depth_mm",
    "removed_volume_mm3",
    "machining_time_s",
    "cost",
)
#: Each episode's constants held after the signals, in the rows of ``MillingCore.info_f``
#: (the core's arrays of these names are views of those rows).
_INFO_LANE = ("torque_limit", "bound", "spindle", "length", "volume")
#: The rows of ``MillingCore.info_f`` by name: the signals, then the episode's constants.
IF = enum.IntEnum("IF", _INFO_F + _INFO_LANE, start=0, module=__name__)
#: The vector info's keys read from ``info_f`` with their rows, in the info's order: those
#: between the flags and the segment, then those after it.
_VECTOR_SIGNALS = (
    ("torque_Nmm", IF.torque_Nmm),
    ("torque_limit_Nmm", IF.torque_limit),
    ("cost", IF.cost),
    ("score_bound", IF.bound),
    *((key, IF[key]) for key in _INFO_F[IF.measured : IF.removed_volume_mm3]),
)
_VECTOR_EPISODE = (
    ("spindle_rpm", IF.spindle),
    ("removed_volume_mm3", IF.removed_volume_mm3),
    ("workpiece_length_mm", IF.length),
    ("workpiece_volume_mm3", IF.volume),
)


#: The weights of the EndMilling reward (:class:`EndMillingEnv`, section Rewards): the
#: regulation envs' one weights type.
MillingReward = LimitReward


@numba.njit(cache=True)
def _clamp(x, lo, hi):
    """``min(max(x, lo), hi)`` with Python's tie rules."""
    if lo > x:
        x = lo
    if hi < x:
        x = hi
    return x


#: The env's arrays the step reads and writes (``MillingCore``'s of these names; ``cmap``
#: the action map's constants, ``rng_table`` the lanes' noise generators' rows, ``ke``
#: the sensor's gain, ``max_t`` the episode's length, ``w`` the reward weights;
#: ``torque_limit`` a row of ``info_f``).
MillingEnvArrays = record(
    "MillingEnvArrays",
    __name__,
    """
    in_action noise_counts commands noise torque_limit breakage_torque vmax n_teeth w_axial
    prev_action tr_obs rpm_obs reward: lanes f8_1
    in_clipped n_clipped: lanes i8_1
    rng_table: lanes i8_2
    cumulative meas: lanes f8_2
    obs: lanes f4_2
    flags: lanes b1_2
    info_f: lanes_t f8_2_rows
    cmap w: shared f8_1
    ke max_t: shared f8
    """,
)
#: The records of the kernel's table (``MillingCore._kernel_args``), in order.
_TABLE = (MillingArrays, MillingEnvArrays)
_AT_PLANT, _AT_ENV, _ = offsets(*_TABLE)
#: Where the table's arguments hold the lanes (axis 0, axis 1: ``info_f``, or none), for
#: :class:`~machining_envs.core.compiled.blocks.LaneBlocks`.
_STEP_AXES = axes(*_TABLE)
_read_plant = MillingArrays.reader
_read_env = MillingEnvArrays.reader


@numba.njit(cache=True, _nrt=False, nogil=True)
def _step(a, e, stage):
    """One step of every lane of the plant's arrays ``a`` (:data:`MillingArrays`) and the
    env's ``e`` (:data:`MillingEnvArrays`): the actions (clipped to the box,
    ``in_clipped[k]`` set to 1 where they were) and their commands, the sensor noise
    (``stage`` 1), then the plant (:func:`step_lanes`) and each lane's reward,
    observation, episode flags and info (``stage`` 2); ``stage`` 3 does both. Between the
    two, the CNC's actuation may change ``commands`` (``machining_envs.core.actuation``).

    ``cmap`` = ``[log, command_min, span, c, g, mid, half]`` of the action map
    (:class:`machining_envs.core.env.ActionMap`): the command is
    ``command_min + span expm1(c (a + 1)) / g`` on the log map, ``mid + half a`` on the
    linear one. A lane with noise draws a normal from its generator (row ``rng_table[k]``,
    ``core.compiled.normals``).
    ``w`` = ``[tracking, overtorque, target, progress, breakage]``; ``flags[k]`` =
    ``[diverged, breakage, finished, terminated, truncated, over the limit]``;
    ``info_f[:, k]`` gets the signals of :data:`IF`. It allocates nothing, so it is
    compiled without reference counting (``_nrt=False``): each field it reads of a record
    would otherwise cost a count (a tenth of the single env's kernel).
    """
    actions, clipped, cmap, commands, noise = e.in_action, e.in_clipped, e.cmap, e.commands, e.noise
    prev_action, n_clipped, info_f, meas, obs = e.prev_action, e.n_clipped, e.info_f, e.meas, e.obs
    out, lane_f, out_finish, flags, tr = a.out, a.lane_f, a.out_finish, e.flags, e.torque_limit
    n = a.z.shape[0]
    log_map = cmap[0] != 0.0
    for k in range(n if stage & 1 else 0):  # stage 1: the commands
        act = actions[k]
        if act > 1.0:  # clipped to the box (np.clip's numbers; finite, checked before)
            act = actions[k] = 1.0
            clipped[k] = 1
        elif act < -1.0:
            act = actions[k] = -1.0
            clipped[k] = 1
        if log_map:
            cmd = cmap[1] + cmap[2] * math.expm1(cmap[3] * (act + 1.0)) / cmap[4]
        else:
            cmd = cmap[5] + cmap[6] * act
        commands[k] = cmd
        info_f[IF.command, k] = cmd
        noise[k] = lane_noise(e.rng_table, k, e.noise_counts[k])
        prev_action[k] = act
        n_clipped[k] += clipped[k]
    if not stage & 2:
        return
    step_lanes(a, commands, noise)
    lo, hi = _TORQUE_OBS
    n_meas = meas.shape[1]
    for k in range(n):
        torque = out[k, 0]
        peak = out[k, 1]
        counts = out[k, 2]
        vf = out[k, 3]
        feed = out[k, 4]
        mean_feed = out[k, 5]
        pos = out[k, 6]
        diverged = not (
            np.isfinite(torque)
            and np.isfinite(peak)
            and np.isfinite(counts)
            and np.isfinite(pos)
            and np.isfinite(mean_feed)
        )
        if diverged:  # never seen; kept so that no NaN can reach an observation or a reward
            torque = 0.0
            peak = 0.0
            counts = 0.0
        measured = counts / e.ke
        for i in range(n_meas - 1, 0, -1):
            meas[k, i] = meas[k, i - 1]
        meas[k, 0] = measured
        t = lane_f[k, LC.t_s]
        breakage = peak > e.breakage_torque[k]
        finished_k = not np.isnan(out_finish[k])
        terminated = diverged or breakage or finished_k
        truncated = (not terminated) and t >= e.max_t - 1e-9
        w = e.w
        x = torque / tr[k]
        over = x - 1.0
        r = -w[0] * abs(x / w[2] - 1.0) - w[1] * (over if over > 0.0 else 0.0)
        if w[3] != 0.0 and not diverged:
            r += w[3] * vf / e.vmax[k]
        if breakage or diverged:
            r -= w[4]
        e.reward[k] = r
        above = torque > tr[k]
        set_episode_flags(flags[k], diverged, breakage, finished_k, terminated, truncated, above)
        if diverged:
            feed = 0.0
            mean_feed = 0.0
            vf = 0.0
            pos = 0.0
        info_f[IF.t_s, k] = t
        info_f[IF.torque_Nmm, k] = torque
        info_f[IF.measured, k] = measured
        info_f[IF.measured_counts, k] = counts
        info_f[IF.peak_torque_Nmm, k] = peak
        info_f[IF.feed_mm_per_rev, k] = feed
        info_f[IF.mean_feed_mm_per_rev, k] = mean_feed
        info_f[IF.feed_per_tooth_mm, k] = feed / e.n_teeth[k]
        info_f[IF.feed_velocity_mm_s, k] = vf
        info_f[IF.position_mm, k] = pos
        info_f[IF.depth_mm, k] = out[k, 7]
        area = cut_area_at(pos, a.edges, a.d0, a.slope, e.cumulative, k, a.nseg[k])
        info_f[IF.removed_volume_mm3, k] = e.w_axial[k] * area
        # NaN unless the lane finished (flags[k, 2])
        info_f[IF.machining_time_s, k] = out_finish[k]
        info_f[IF.cost, k] = 1.0 if flags[k, 5] else 0.0
        sc = tr[k]
        obs[k, 0] = _clamp(measured / sc, lo, hi)
        obs[k, 1] = e.tr_obs[k]
        obs[k, 2] = prev_action[k]
        obs[k, 3] = e.rpm_obs[k]
        for i in range(1, n_meas):
            obs[k, 3 + i] = _clamp(meas[k, i] / sc, lo, hi)


@numba.njit(cache=True, nogil=True)
def _step_packed(t, stage):
    """:func:`_step` with its arguments in one table (``core.compiled.packed``, records
    :data:`_TABLE`): what every step calls (one array to unbox, not one per argument).
    ``info_f`` holds the lanes on axis 1, so a block's is a view of some of its columns
    (``f8_2_rows``)."""
    _step(_read_plant(t, _AT_PLANT), _read_env(t, _AT_ENV), stage)


#: :func:`_step_packed` as :class:`~machining_envs.core.compiled.blocks.LaneBlocks` calls
#: a kernel of flat arguments.
_step_flat = via_table(_step_packed, len(_STEP_AXES))


@numba.njit(cache=True, nogil=True)
def _serve_step(ctl, table, polls):
    """The lane blocks' worker loop for :func:`_step_packed` (``core.compiled.blocks``),
    compiled with this module and cached, not at the first step on several threads."""
    return serve_one_table_with_tail(_step_packed, ctl, table, polls)


@numba.njit(cache=True)
def _start(k, row, x, segments, a, e):
    """The arrays of lane ``k`` at the start of an episode (``MillingCore.start``): the
    plant's (``a``, :func:`~machining_envs.milling.plant.start_lane`, from its constants
    ``row``), then the env's (``e``), the tool at rest at the workpiece's start.

    ``x`` = ``[torque limit, Vmax, breakage torque, noise (counts), teeth, axial depth,
    limit's observation, score bound, process lag]`` of the cut (the bound NaN: computed
    here, for a sharp tool, as
    :func:`~machining_envs.milling.scenarios.machining_time_bound` does). ``info_f[:, k]``
    gets the info of a cut not yet begun (what the info reports until the first step):
    every signal zero but the depth and the machining time (NaN), then the episode's
    constants (``_INFO_LANE``).
    """
    tr, vm, brk, noise, teeth, w, t_obs = x[0], x[1], x[2], x[3], x[4], x[5], x[6]
    b, lag_s = x[7], x[8]
    start_lane(k, row, lag_s, segments, a)
    rpm = row[LC.spindle_rpm]
    ns = segments.shape[1] - 1
    if b != b:  # machining_time_bound with no wear: traverse_time_s's closed form (left
        # NaN, for machining_time_bound to refuse, where that refuses its numbers)
        fexp = row[LC.feed_exponent]
        c = bound_coefficient(row[LC.torque_gain], fexp, tr, teeth, rpm)
        q = row[LC.depth_exponent] / fexp
        if c > 0.0 and q > 0.0 and vm > 0.0:
            b = traverse_time(segments, c, q, vm)
    cumulative, info_f, obs = e.cumulative, e.info_f, e.obs
    # The area under the profile up to each edge (CutArea's cumulative sums).
    area = 0.0
    cumulative[k, 0] = 0.0
    for i in range(ns):
        wi = segments[0, i + 1] - segments[0, i]
        area = area + wi * (segments[1, i] + 0.5 * segments[3, i] * wi)
        cumulative[k, i + 1] = area
    for i in range(ns + 1, cumulative.shape[1]):
        cumulative[k, i] = area
    for i in range(info_f.shape[0]):
        info_f[i, k] = 0.0
    info_f[IF.depth_mm, k] = segments[1, 0]
    info_f[IF.machining_time_s, k] = np.nan
    info_f[IF.torque_limit, k] = tr
    info_f[IF.bound, k] = b
    info_f[IF.spindle, k] = rpm
    info_f[IF.length, k] = segments[0, ns]
    info_f[IF.volume, k] = w * area
    e.vmax[k] = vm
    e.breakage_torque[k] = brk
    e.noise_counts[k] = noise
    e.n_teeth[k] = teeth
    e.w_axial[k] = w
    e.meas[k, :] = 0.0
    e.tr_obs[k] = t_obs
    e.rpm_obs[k] = rpm / 1000.0
    e.prev_action[k] = -1.0
    e.n_clipped[k] = 0
    o = obs[k]
    o[:] = 0.0
    o[1] = t_obs
    o[2] = -1.0
    o[3] = rpm / 1000.0
    e.flags[k, :] = False  # no flag, no clipped action yet
    e.in_clipped[k] = 0
    a.out_segment[k] = 0


@numba.njit(cache=True)
def _start_packed(t, k, row, x, segments):
    """:func:`_start` with the step's table ``t`` (:func:`_step_packed`'s)."""
    _start(k, row, x, segments, _read_plant(t, _AT_PLANT), _read_env(t, _AT_ENV))


#: What :func:`_start_drawn_lanes` reads of the nominal parameters and a split's ranges
#: (:func:`_batch_numbers`), in this order after the nominal lane constants (so that
#: ``nominal[BN.n_teeth]`` is the nominal number of teeth).
BN = enum.IntEnum(
    "BN",
    "spindle_rpm torque_limit_Nmm power_law feed_exponent torque_coefficient_kgfmm"
    " tool_diameter_mm tangential_coefficient_N_mm2 n_teeth axial_depth_mm"
    " max_feed_velocity_mm_s breakage_torque_Nmm sensor_gain noise_std_Nmm process_lag_rev"
    " rpm_low rpm_high ks_low ks_span m_low m_span noise_low noise_span",
    start=len(LANE_CONSTANTS),
    module=__name__,
)


def _batch_numbers(params: MillingParams, factory: _SplitFactory) -> np.ndarray:
    """The numbers :func:`_start_drawn_lanes` reads: ``params``'s lane constants
    (:meth:`MillingLanes.lane_constants` at the nominal speed), then :data:`BN`."""
    p = params
    lows, spans = factory.lows, factory.spans
    given = {
        "power_law": p.force_model == "power_law",
        "rpm_low": SPINDLE_RPM_RANGE[0],
        "rpm_high": SPINDLE_RPM_RANGE[1],
        "ks_low": lows[2],
        "ks_span": spans[2],
        "m_low": lows[3],
        "m_span": spans[3],
        "noise_low": lows[4],
        "noise_span": spans[4],
    }
    numbers = [given[b.name] if b.name in given else getattr(p, b.name) for b in BN]
    row = MillingLanes.lane_constants(p, p.spindle_rpm)
    return np.concatenate((row, np.array(numbers, dtype=np.float64)))


@numba.njit(cache=True)
def _start_drawn_lanes(t, lanes, nominal, v, scales, segments, counts):
    """:func:`_start_packed` for every lane ``lanes[i]`` of a split's batch: from its
    uniforms ``v[i]`` (:meth:`_SplitFactory.draw_lanes`), its spindle and limit scales
    ``scales[i]`` and its segments ``segments[i, :, : counts[i] + 1]``, the numbers
    ``MillingScenario`` (``spindle_rpm``, ``torque_limit_Nmm``, ``true_params``) and
    ``MillingCore.start`` work out, in their order of operations (the same bits), from
    ``nominal`` (:func:`_batch_numbers`). Returns the first ``i`` whose speed falls
    outside ``SPINDLE_RPM_RANGE`` (none is started from it on), or -1."""
    nc = len(LANE_CONSTANTS)
    b = nominal
    teeth, n_limit = b[BN.n_teeth], b[BN.torque_limit_Nmm]
    row = np.empty(nc)
    x = np.empty(9)
    for i in range(lanes.size):
        rpm = b[BN.spindle_rpm] * scales[i, 0]
        if not (b[BN.rpm_low] <= rpm <= b[BN.rpm_high]):
            return i
        limit = n_limit * scales[i, 1]
        ks_scale = b[BN.ks_low] + b[BN.ks_span] * v[i, 2]
        copy_into(row, nominal[:nc])  # the columns the truth keeps
        row[LC.ft_per_vf] = 60.0 / (rpm * teeth)
        if b[BN.power_law] != 0.0:
            row[LC.feed_exponent] = b[BN.feed_exponent] * (b[BN.m_low] + b[BN.m_span] * v[i, 3])
            ks = b[BN.torque_coefficient_kgfmm] * ks_scale
            row[LC.torque_gain] = KGF * ks * b[BN.tool_diameter_mm]
        else:  # the average-force model's torque_gain(1.0)
            kt = b[BN.tangential_coefficient_N_mm2] * ks_scale
            row[LC.torque_gain] = teeth * kt * b[BN.axial_depth_mm] * 1.0 / (2.0 * math.pi)
        row[LC.spindle_rpm] = rpm
        row[LC.rev_per_s] = rpm / 60.0
        row[LC.wear_per_mm] = 0.0  # a sharp tool (the batch takes no wear)
        x[0] = limit
        x[1] = b[BN.max_feed_velocity_mm_s]
        x[2] = b[BN.breakage_torque_Nmm]
        x[3] = b[BN.sensor_gain] * (
            b[BN.noise_std_Nmm] * (b[BN.noise_low] + b[BN.noise_span] * v[i, 4])
        )
        x[4] = teeth
        x[5] = b[BN.axial_depth_mm]
        x[6] = min(limit / n_limit, 10.0)
        x[7] = np.nan  # the score bound: worked out by _start
        x[8] = 60.0 * b[BN.process_lag_rev] / rpm
        _start_packed(t, lanes[i], row, x, lane_segments(segments, i, counts))
    return -1


def _info_table(n: int) -> np.ndarray:
    """A zero ``MillingCore.info_f`` for ``n`` lanes, its rows spaced apart
    (``core.compiled.packed.spaced_rows``: the kernel writes a lane's column at once; rows 8 kB apart
    cost 7 % of the step at N = 1024)."""
    table = spaced_rows(len(_INFO_F) + len(_INFO_LANE), n)
    table[:] = 0.0
    return table


def _map_constants(command_map: ActionMap) -> np.ndarray:
    """The action map's constants as the compiled step reads them (see :func:`_step`)."""
    return command_map.constants()


class MillingCore(FeedRegulationCore):
    """The state and arithmetic of N end-milling episodes, shared by ``EndMillingEnv`` (one
    lane) and ``EndMillingVectorEnv`` (N lanes): the plant (:class:`MillingLanes`) and the
    command, noise, reward, observation, episode end and info computed for all lanes by one
    compiled function, so that a lane of the vector env and the single env agree to the
    last bit."""

    #: What a scenario may be: an object of this class or one of these names.
    scenario_types = (MillingScenario, MILLING_SCENARIOS)
    #: The nominal parameters' class, its default set and the reward weights' class.
    option_types = (MillingParams, MillingParams.park_yoon_1986, MillingReward)
    VIEWS = frozenset({*_INFO_LANE, "_args"})

    def __init__(
        self,
        owner: str,
        n: int,
        scenario: str | MillingScenario,
        *,
        params: MillingParams | None,
        reward: LimitReward | dict | None,
        max_episode_time_s: float,
        action_map: str,
        overrides: dict,
        actuation=None,
        power_sensor=None,
    ):
        self._set_regulation(owner, n, scenario, params, reward, max_episode_time_s, overrides)
        self._set_cnc(actuation, power_sensor)  # the spindle power: the load channel
        if action_map not in ACTION_MAPS:
            raise ValueError(
                f"{owner}: action_map must be one of {list(ACTION_MAPS)}, got {action_map!r}"
            )
        self.command_map = ActionMap(
            0.0, self.params.command_max, scale=action_map, decades=COMMAND_DECADES
        )
        self._cmap = _map_constants(self.command_map)
        self._set_regulation_spaces(_TORQUE_OBS, SPINDLE_RPM_RANGE[1])
        self._ke = float(self.params.sensor_gain)
        self.lanes = MillingLanes(self.params, n)
        #: Each lane's scenario and true parameters (built when read after a batched start).
        self.scenarios = LaneObjects(n)
        self.truths = LaneObjects(n)
        #: Whether a split factory's scenarios may start in one batch (:meth:`batches`),
        #: and the numbers its batches read (:func:`_batch_numbers`).
        self._batch_ok: dict = {}
        self._batch_numbers: dict = {}
        self.vmax = np.ones(n)
        self.breakage_torque = np.ones(n)
        self.noise_counts = np.zeros(n)
        self.n_teeth = np.ones(n)
        self.w_axial = np.zeros(n)
        self.cumulative = np.zeros((n, 2))
        self.meas = np.zeros((n, _HISTORY + 1))  # newest first, N·mm
        self.tr_obs = np.zeros(n)
        self.rpm_obs = np.zeros(n)
        self.prev_action = np.full(n, -1.0)
        self.n_clipped = np.zeros(n, dtype=np.int64)
        self.obs = np.zeros((n, 4 + _HISTORY), dtype=np.float32)
        self.reward = np.zeros(n)
        self.flags = np.zeros((n, 6), dtype=np.bool_)
        # One row per signal, then one per episode constant (info_arrays copies them at once)
        self.info_f = _info_table(n)
        self.bind_views()
        self.torque_limit[:] = 1.0
        self.bound[:] = np.nan
        #: The generators the lanes draw their sensor noise from (their episodes').
        self.rngs = LaneGenerators(n)
        self.names = LaneNames(n)
        self.in_action = np.zeros(n)
        self.in_clipped = np.zeros(n, dtype=np.int64)
        self.commands = np.zeros(n)
        self.noise = np.zeros(n)
        self._packed = PackedArgs()  # the kernel's arguments in one table (core.compiled.packed)
        #: The blocks of lanes the kernel steps at once (one thread unless a vector env
        #: asks for more).
        self.blocks = LaneBlocks(n)

    def bind_views(self) -> None:
        """Name the rows of ``info_f`` that hold the episode constants (``_INFO_LANE``)."""
        for i, name in enumerate(_INFO_LANE):
            setattr(self, name, self.info_f[len(_INFO_F) + i])

    def __setstate__(self, state: dict) -> None:
        info = state["info_f"]  # a pickle holds it as one block: spaced out again
        state["info_f"] = _info_table(info.shape[1])
        state["info_f"][:] = info
        super().__setstate__(state)

    def start(self, lane: int, spec, rng: np.random.Generator) -> None:
        """Start an episode in ``lane`` on the scenario ``spec`` (drawn with ``rng``); its
        first observation goes to ``obs[lane]``, its reset info is its :meth:`lane_info` (and
        its column of :meth:`info_arrays`) until the first step."""
        sc = milling_scenario(spec, rng)
        self.rngs.bind(lane, rng)  # the episode's sensor noise comes from it too
        nominal = self.params
        rpm = sc.spindle_rpm(nominal)
        truth = sc.true_params(nominal)
        profile = sc.profile
        check_depth(profile, truth)
        tr = sc.torque_limit_Nmm(nominal)
        if not tr < truth.breakage_torque_Nmm:  # the message is made only when it fails
            check_below(
                f"scenario {sc.name!r}: the torque limit (torque_limit_Nmm x torque_limit_scale)",
                tr,
                "the tool's breakage_torque_Nmm",
                truth.breakage_torque_Nmm,
                "the tool would break before the limit binds",
            )
        # (true_params changes no field of the servo, so the lane fits the batch.)
        segments = profile.segment_copy()
        self._fit(segments.shape[1] - 1)
        # The score bound: computed by the kernel for a sharp tool, here with wear.
        bound = math.nan if truth.wear_per_100mm == 0.0 else machining_time_bound(sc, truth, rpm)
        row = self.lanes.lane_constants(truth, rpm)
        noise = truth.sensor_gain * truth.noise_std_Nmm
        vmax, brk = truth.max_feed_velocity_mm_s, truth.breakage_torque_Nmm
        teeth, axial = truth.n_teeth, truth.axial_depth_mm
        tr_obs = min(tr / nominal.torque_limit_Nmm, 10.0)
        x = np.array((tr, vmax, brk, noise, teeth, axial, tr_obs, bound, truth.process_lag_s(rpm)))
        _start_packed(self._packed(self._kernel_args()), lane, row, x, segments)
        if not self.bound[lane] == self.bound[lane]:  # refused by the kernel: let it say why
            self.bound[lane] = machining_time_bound(sc, truth, rpm)
        self.scenarios[lane] = sc
        self.truths[lane] = truth
        self.act_lanes = configure_lane(
            self.act_lanes, lane, sc.actuation, self.actuation, self.actuation_lanes
        )
        self.names[lane] = sc.name
        if self.power_sensor:
            self._sense_power([lane])

    def _fit(self, n_segments: int) -> None:
        """Widen the lanes' workpiece tables (the plant's and the cumulative areas) to hold
        ``n_segments`` segments."""
        self.lanes.fit_segments(n_segments)
        if n_segments + 1 > self.cumulative.shape[1]:
            grow = n_segments + 1 - self.cumulative.shape[1]
            self.cumulative = np.pad(self.cumulative, ((0, 0), (0, grow)), mode="edge")
            self._args = None

    def _start_batch(self, lanes: np.ndarray, factory) -> None:
        segments, counts, v = factory.draw_lanes(self.rngs.table, lanes)
        p = self.params
        # The spindle and limit scales (numpy's exp, as the factory's), then every number
        # start() works out from them and the other uniforms, in one compiled call.
        scales = np.exp(factory.log_lows + factory.log_spans * v[:, :2])
        self._fit(int(counts.max()))
        nominal = self._batch_numbers.get(factory)
        if nominal is None:
            nominal = self._batch_numbers[factory] = _batch_numbers(self.params, factory)
        table = self._packed(self._kernel_args())
        bad = _start_drawn_lanes(table, lanes, nominal, v, scales, segments, counts)
        if bad >= 0:  # a range's end rounded past SPINDLE_RPM_RANGE: the lane's check says so
            sc = factory.build_lane(segments, counts, v, bad)
            sc.spindle_rpm(p)
            lo, hi = SPINDLE_RPM_RANGE
            raise ValueError(
                f"lane {int(lanes[bad])}: spindle_scale {sc.spindle_scale} gives "
                f"{p.spindle_rpm * sc.spindle_scale:g} rpm, outside the spindle_rpm range "
                f"[{lo}, {hi}]"
            )
        draws = (segments, counts, v)
        ks = settle_batch(self, lanes, factory.build_lane, draws, factory.actuation, factory.name)
        for k in ks:
            if not self.bound[k] == self.bound[k]:  # refused by the kernel: let it say why
                self.bound[k] = machining_time_bound(
                    self.scenarios[k], self.truths[k], float(self.spindle[k])
                )

    def batches(self, factory) -> bool:
        """Whether :meth:`start_lanes` may start ``factory``'s scenarios in one batch: a
        split's, without wear (whose score bound is integrated in Python), whose every
        scenario passes the checks :meth:`start` makes (those of the ranges' two ends,
        checked once: spindle speed, true parameters, radial depth, torque limit below the
        breakage torque)."""
        if not isinstance(factory, _SplitFactory) or factory.wear is not None:
            return False
        nominal = self.params

        def check(sc) -> bool:
            sc.spindle_rpm(nominal)
            truth = sc.true_params(nominal)
            return factory.depth[1] <= truth.tool_diameter_mm and (
                sc.torque_limit_Nmm(nominal) < truth.breakage_torque_Nmm
            )

        return self._extremes_pass(factory, check)

    def _make_kernel_args(self) -> tuple:
        """The arguments of :func:`_step_packed`'s table: the fields of its records
        (:data:`_TABLE`) in order (``_kernel_args`` keeps them until the lane arrays are
        replaced)."""
        env = gather(
            MillingEnvArrays,
            self,
            cmap=self._cmap,
            rng_table=self.rngs.table,
            ke=self._ke,
            max_t=self.max_episode_time_s,
            w=self._w,
        )
        return flatten(self.lanes.arrays(), env)

    def set_action(self, lane: int, action: float, clipped: bool) -> None:
        self.in_action[lane] = action
        self.in_clipped[lane] = clipped

    def set_actions(self, actions: np.ndarray) -> None:
        self.in_action[:] = actions[:, 0]  # clipped to the box by the kernel, which marks
        self.in_clipped.fill(0)  # the clipped ones here

    def outcome(self, lane: int) -> tuple[float, bool, bool]:
        flags = self.flags[lane]
        return float(self.reward[lane]), bool(flags[3]), bool(flags[4])

    def step(self) -> None:
        """Advance every lane with the actions in ``in_action`` (finite; clipped to the box
        here, and marked 1 in ``in_clipped``, which may mark them clipped before), each
        lane's sensor noise drawn from the generator its episode started with; with CNC
        actuation on, the commands pass through it first (``machining_envs.core.actuation``)
        and ``info["command"]`` is what the drives got."""
        args = self._kernel_args()
        if self.act_lanes is None:
            self._run(args, 3)
        else:
            self._run(args, 1)
            self.commands[:] = self.act_lanes.apply(self.commands)
            self.info_f[IF.command] = self.commands
            self._run(args, 2)
        if self.power_sensor:
            self._sense_power()

    def _sense_power(self, lanes=None) -> None:
        c = self.info_f  # the step's signals (info_arrays' rows), read without a copy
        rpm = c[IF.spindle]
        w = rpm * (math.pi / 30.0) * 1e-3  # angular speed, rad/s, per N·mm
        self.power_sensor.update(self.obs, lanes, c[IF.torque_Nmm] * w, rpm, c[IF.torque_limit] * w)

    def _run(self, args: tuple, stage: int) -> None:
        """:func:`_step` of ``stage`` over every lane (on the blocks of lanes, if several)."""
        if self.blocks.one:  # the single env, or few lanes: no blocks to hand out
            _step_packed(self._packed(args), stage)
        else:
            run = self.blocks.run
            run(_step_flat, args, _STEP_AXES, stage, packed=_step_packed, serve=_serve_step)

    def lane_info(self, k: int) -> dict:
        """The step info of lane ``k`` (after :meth:`step`)."""
        c = self.info_f[:, k].tolist()  # the rows of info_f (IF), in order
        t, command, torque, measured, counts, peak, feed, mean_feed, feed_tooth, vf = c[:10]
        pos, depth, removed, finish, cost, limit, bound, rpm, length, volume = c[10:]
        signals = {
            "torque_Nmm": torque,
            "torque_limit_Nmm": limit,
            "cost": cost,
            "score_bound": bound,
            "measured": measured,
            "measured_counts": counts,
            "peak_torque_Nmm": peak,
            "feed_mm_per_rev": feed,
            "mean_feed_mm_per_rev": mean_feed,
            "feed_per_tooth_mm": feed_tooth,
            "feed_velocity_mm_s": vf,
            "position_mm": pos,
            "depth_mm": depth,
        }
        episode = {
            "spindle_rpm": rpm,
            "removed_volume_mm3": removed,
            "workpiece_length_mm": length,
            "workpiece_volume_mm3": volume,
            "scenario": self.names[k],
        }
        head = (t, command, bool(self.in_clipped[k]))
        return self._info(k, head, self.flags[k, :3].tolist(), signals, episode, finish)

    def info_arrays(self) -> dict:
        """The step info of every lane, as arrays (``machining_time_s`` with its mask): views
        of one copy of the signals and constants and one of the flags, so that a step copies
        a few blocks of memory."""
        c = self.info_f.copy()
        f = self.flags.copy()
        head = (c[IF.t_s], c[IF.command], self.in_clipped.astype(bool))
        signals = {key: c[row] for key, row in _VECTOR_SIGNALS}
        episode = {key: c[row] for key, row in _VECTOR_EPISODE}
        episode["scenario"] = self.names.array()
        finish = c[IF.machining_time_s]  # NaN where the lane did not finish
        return self._info(None, head, (f[:, 0], f[:, 1], f[:, 2]), signals, episode, finish)
