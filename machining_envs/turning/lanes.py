"""The engine of ``Turning-v0``: the reward weights, the lane tables and the compiled
step, start and info of N lathes, which :class:`TurningEnv` (one lane) and
:class:`TurningVectorEnv` (N lanes) drive."""

from __future__ import annotations

import dataclasses
import enum
import math

import numba
import numpy as np

from machining_envs.core.actions import ActionMap
from machining_envs.core.actuation import configure_lane
from machining_envs.core.checks import PY_NUMBER_TYPES, check_below, check_range
from machining_envs.core.compiled.blocks import LaneBlocks, serve_one_table_with_tail
from machining_envs.core.compiled.kernels import clip_unit_linear, set_episode_flags
from machining_envs.core.compiled.normals import LaneGenerators, lane_noise
from machining_envs.core.compiled.packed import PackedArgs, spaced_rows
from machining_envs.core.compiled.schema import (
    axes,
    bind_columns,
    flatten,
    gather,
    offsets,
    record,
    via_table,
)
from machining_envs.core.lanes import (
    REGULATION_HISTORY,
    FeedRegulationCore,
    LaneNames,
    LaneObjects,
    settle_batch,
)
from machining_envs.core.reward import LimitReward
from machining_envs.core.workpieces import lane_segments, traverse_time
from machining_envs.turning.plant import (
    SPINDLE_RPM_RANGE,
    SpeedFree,
    TurningArrays,
    TurningLanes,
    TurningParams,
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

_HISTORY = REGULATION_HISTORY
_FORCE_OBS = (-1.0, 10.0)


#: The weights of the Turning reward (:class:`TurningEnv`, section Rewards): the
#: regulation envs' one weights type.
TurningReward = LimitReward


#: Columns of ``TurningCore.ef``, the env's per-lane floats (views of the same names).
EF = enum.IntEnum(
    "EF",
    "in_action in_command in_noise force_limit vmax breakage_force prev_action fr_obs rpm_obs"
    " reward command",
    start=0,
    module=__name__,
)
#: Columns of ``TurningCore.eb``, the env's per-lane flags: the six of ``flags``, then
#: ``in_clipped`` and ``clipped``.
EB = enum.IntEnum(
    "EB",
    "diverged breakage finished terminated truncated over in_clipped clipped",
    start=0,
    module=__name__,
)

# The columns a single env's step reads and writes in Python, as plain ints (an enum
# member there costs a few tenths of a microsecond each).
_IN_ACTION, _IN_COMMAND, _REWARD = int(EF.in_action), int(EF.in_command), int(EF.reward)
_COMMAND, _FORCE_LIMIT = int(EF.command), int(EF.force_limit)
_TERMINATED, _OVER = int(EB.terminated), int(EB.over)

#: The env's arrays the step reads and writes (``TurningCore``'s; ``gain`` the sensor's,
#: ``fs`` the force scale, ``w`` the reward weights ``[tracking, overforce, target,
#: progress, breakage]``, ``rng_table`` the lanes' noise generators' rows).
TurningEnvArrays = record(
    "TurningEnvArrays",
    __name__,
    """
    ef meas: lanes f8_2
    eb: lanes b1_2
    obs: lanes f4_2
    n_clipped: lanes i8_1
    rng_table: lanes i8_2
    noise_counts: lanes f8_1
    gain fs max_t: shared f8
    w: shared f8_1
    """,
)
#: What an episode's start writes besides (``TurningCore``'s arrays of these names).
TurningEpisodes = record(
    "TurningEpisodes",
    __name__,
    """
    bound spindle spindle_set diameter length: lanes f8_1
    power: lanes f8_2
    """,
)
#: A batch of starts the blocks of lanes make (:func:`_start_pending`): each lane's index
#: (a block's first tells it where its lanes begin), the pending starts ``[count,
#: lanes...]``, the split's numbers (:data:`BN`), and each pending lane's speed,
#: uniforms, segments, segment count and whether its step matrix was made.
TurningBatch = record(
    "TurningBatch",
    __name__,
    """
    lane_index: lanes i8_1
    pending counts: shared i8_1
    nums rpm: shared f8_1
    v: shared f8_2
    segments: shared f8_3
    ok: shared b1_1
    """,
)
#: The records of the kernel's table (``TurningCore._kernel_args``), in order: the step
#: reads the first two, a start all but the last, a batch of starts all.
_TABLE = (TurningArrays, TurningEnvArrays, TurningEpisodes, SpeedFree, TurningBatch)
_AT_PLANT, _AT_ENV, _AT_EPISODE, _AT_FREE, _AT_BATCH, _ = offsets(*_TABLE)
#: Where the table's arguments hold the lanes, for
#: :class:`~machining_envs.core.compiled.blocks.LaneBlocks`.
_STEP_AXES = axes(*_TABLE)
_read_plant = TurningArrays.reader
_read_env = TurningEnvArrays.reader
_read_episode = TurningEpisodes.reader
_read_free = SpeedFree.reader
_read_batch = TurningBatch.reader


@numba.njit(cache=True)
def _env_lane(k, a, e):
    """Reward, observation and episode flags of lane ``k`` from the plant's signals (``a``,
    :data:`TurningArrays`) into the env's arrays (``e``, :data:`TurningEnvArrays`):
    ``e.eb[k]`` = ``[diverged, breakage, finished, terminated, truncated, over the limit,
    ...]``."""
    lo, hi = _FORCE_OBS
    out, ef, flags, w = a.out, e.ef, e.eb, e.w
    force, peak, counts, pos = out[k, 0], out[k, 1], out[k, 2], out[k, 5]
    diverged = not (np.isfinite(force) and np.isfinite(counts) and np.isfinite(pos))
    if diverged:  # never seen; kept so that no NaN can reach an observation or a reward
        force = 0.0
        peak = 0.0
        counts = 0.0
        out[k, 0] = 0.0
        out[k, 1] = 0.0
        out[k, 2] = 0.0
    m = e.meas[k]
    for i in range(m.size - 1, 0, -1):
        m[i] = m[i - 1]
    m[0] = counts / e.gain
    breakage = peak > ef[k, EF.breakage_force]
    finished = not np.isnan(a.out_finish[k])
    terminated = diverged or breakage or finished
    truncated = (not terminated) and a.lane_f[k, 5] >= e.max_t - 1e-9
    fr = ef[k, EF.force_limit]
    x = force / fr
    r = -w[0] * abs(x / w[2] - 1.0) - w[1] * max(0.0, x - 1.0)
    if w[3]:
        r += w[3] * out[k, 4] / ef[k, EF.vmax]
    if breakage or diverged:
        r -= w[4]
    ef[k, EF.reward] = r
    set_episode_flags(flags[k], diverged, breakage, finished, terminated, truncated, force > fr)
    o = e.obs[k]
    fs = e.fs
    o[0] = min(max(m[0] / fs, lo), hi)
    o[1] = ef[k, EF.fr_obs]
    o[2] = ef[k, EF.prev_action]
    o[3] = ef[k, EF.rpm_obs]
    for i in range(1, m.size):
        o[3 + i] = min(max(m[i] / fs, lo), hi)


#: The float keys of a vector step's info, one row each of the table
#: :func:`_info_rows` fills (``TurningCore.info_arrays``).
_INFO_F = (
    "t_s command force_N force_limit_N cost score_bound measured measured_counts peak_force_N"
    " feed_mm_per_rev feed_velocity_mm_s position_mm depth_mm spindle_rpm spindle_power_W"
    " cutting_power_W workpiece_length_mm machining_time_s"
).split()


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
        rows[1, k] = ef[k, EF.command]
        rows[2, k] = o[0]
        rows[3, k] = ef[k, EF.force_limit]
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


@numba.njit(cache=True, _nrt=False, nogil=True)
def _step(a, e):
    """One step of every lane: the actions' bookkeeping, the sensor noise, the plant, the
    env's outputs.

    ``a`` holds the plant's arrays (:data:`TurningArrays`), ``e`` the env's
    (:data:`TurningEnvArrays`: its per-lane floats and flags, columns :data:`EF` and
    :data:`EB`). A lane with noise (``noise_counts[k]`` counts per unit normal) draws a
    normal from its generator (row ``rng_table[k]``, ``core.compiled.normals``), a lane
    without draws none. ``a.work`` is the plant's scratch: nothing is allocated here, so it
    is compiled without reference counting (``_nrt=False``): the views of each lane's rows
    it makes cost no atomic counts. ``matvec``, which it calls for filters outside the
    two-row scheme, keeps the runtime for what it hands to ``np.dot``.
    The env calls it through :func:`_step_packed` (one table for every argument)."""
    ef, eb = e.ef, e.eb
    for k in range(a.z.shape[0]):
        ef[k, EF.prev_action] = ef[k, EF.in_action]
        ef[k, EF.command] = ef[k, EF.in_command]
        eb[k, EB.clipped] = eb[k, EB.in_clipped]
        e.n_clipped[k] += eb[k, EB.in_clipped]
        ef[k, EF.in_noise] = lane_noise(e.rng_table, k, e.noise_counts[k])
        step_lane(k, a, ef[k, EF.in_command], ef[k, EF.in_noise])
        _env_lane(k, a, e)


@numba.njit(cache=True, nogil=True)
def _step_packed(t, op):
    """The core's kernel with its arguments in one table (``core.compiled.packed``;
    ``TurningCore._kernel_args``, records :data:`_TABLE`), one array to unbox, not one per
    argument: ``op`` 0 is :func:`_step` of the table's lanes, 1 starts those of its lanes
    that the pending table lists (:func:`_start_pending`). On several threads each block
    of lanes runs it on its own table, so a vector env's resetting lanes start on the
    blocks' threads too."""
    if op == 0:
        _step(_read_plant(t, _AT_PLANT), _read_env(t, _AT_ENV))
    else:
        _start_pending(t)


#: :func:`_step_packed` as :class:`~machining_envs.core.compiled.blocks.LaneBlocks` calls
#: a kernel of flat arguments.
_step_flat = via_table(_step_packed, len(_STEP_AXES))


@numba.njit(cache=True, nogil=True)
def _serve_step(ctl, table, polls):
    """The lane blocks' worker loop for :func:`_step_packed` (``core.compiled.blocks``), compiled with
    this module and cached, not at the first step on several threads."""
    return serve_one_table_with_tail(_step_packed, ctl, table, polls)


@numba.njit(cache=True)
def _start_pending(t):
    """:func:`_start_drawn_lanes` for the pending lanes (the table's :data:`TurningBatch`)
    that lie in the table's block of lanes (its first lane's index first), each lane
    writing its own rows and its ``ok``."""
    b = _read_batch(t, _AT_BATCH)
    first = b.lane_index
    lanes = b.pending[1 : b.pending[0] + 1]
    lo, hi = first[0], first[0] + first.size
    _start_drawn_lanes(t, lanes, lo, hi, b.nums, b.rpm, b.v, b.segments, b.counts, b.ok)


@numba.njit(cache=True)
def _start(k, full_history, consts, segments, x, a, e, ep, free):
    """The arrays of lane ``k`` at the start of an episode (``TurningCore.start``): the
    plant's (``a``, :func:`~machining_envs.turning.plant.start_lane` on the tables
    ``free``, whose return it returns), then the env's (``e``) and the episode's (``ep``),
    the tool at rest at the workpiece's start.

    ``x`` = ``[rpm, force limit, Vmax, breakage force, noise (counts), diameter, score
    bound, spindle power]`` of the cut (the bound NaN: computed here, for a sharp tool, as
    :func:`~machining_envs.turning.scenarios.machining_time_bound` does), ``consts`` the
    plant's lane constants (``TurningLanes.lane_constants``).
    """
    rpm, limit, vmax, brk, noise, diam, b = x[0], x[1], x[2], x[3], x[4], x[5], x[6]
    ok = start_lane(k, rpm, full_history, consts, segments, free, a)
    if b != b:  # machining_time_bound with no wear: traverse_time_s's closed form (left
        # NaN, for machining_time_bound to refuse, where that refuses its numbers)
        p = consts[1]
        c = bound_coefficient(consts[0], p, limit, x[7], diam, rpm)
        if c > 0.0 and p > 0.0 and vmax > 0.0:
            b = traverse_time(segments, c, 1.0 / p, vmax)
    fr_obs = min(limit / e.fs, 10.0)
    rpm_obs = rpm / 1000.0
    f = e.ef[k]
    f[EF.force_limit] = limit
    f[EF.vmax] = vmax
    f[EF.breakage_force] = brk
    f[EF.prev_action] = -1.0
    f[EF.fr_obs] = fr_obs
    f[EF.rpm_obs] = rpm_obs
    f[EF.command] = 0.0
    ep.bound[k] = b
    e.noise_counts[k] = noise
    e.meas[k, :] = 0.0
    e.n_clipped[k] = 0
    ep.spindle[k] = rpm
    ep.spindle_set[k] = rpm
    ep.power[k, :] = 0.0
    ep.diameter[k] = diam
    ns = segments.shape[1] - 1
    ep.length[k] = segments[0, ns]
    o = e.obs[k]
    o[:] = 0.0
    o[1] = fr_obs
    o[2] = -1.0
    o[3] = rpm_obs
    # The signals of a cut not yet begun, where lane_info and info_arrays read them until the
    # first step (which writes every one): the tool at rest at the workpiece's start.
    e.eb[k, :] = False
    a.out[k, :] = 0.0
    a.out[k, 6] = segments[1, 0]  # the depth at the start
    a.li[k, 3] = 0  # the segment
    a.out_finish[k] = np.nan
    return ok


#: The numbers :func:`_start_drawn_lanes` reads of a split and the nominal parameters
#: (``_batch_numbers``), in its order: the nominal Kf, p, Ke, U_max, margin, spindle power,
#: Vmax, breakage force, noise and diameter, then the split's ranges (low, span) of the
#: scales of Kf, p and the noise, whether the limit varies, and its range.
BN = enum.IntEnum(
    "BN",
    "force_coefficient feed_exponent sensor_gain command_max margin spindle_power_W"
    " max_feed_velocity_mm_s breakage_force_N noise_std_N workpiece_diameter_mm kf_low kf_span"
    " p_low p_span noise_low noise_span limit_varies limit_low limit_span",
    start=0,
    module=__name__,
)


def _batch_numbers(core, factory) -> np.ndarray:
    """What :func:`_start_drawn_lanes` reads (:data:`BN`) for lanes of ``factory``'s split
    on ``core``'s nominal parameters: the numbers ``TurningScenario.true_params`` and
    ``TurningLanes.lane_constants`` take."""
    p = core.params
    power = factory.shop["spindle_power_W"]
    power = power if math.isfinite(power) else p.spindle_power_W
    ke, cmax, margin = core.lanes.lane_constants(p)[2:5]
    lows, spans = factory.lows, factory.spans
    varies = factory.limit_varies
    limit = (lows[3], spans[3]) if varies else (float(factory.limit_N[0]), 0.0)
    numbers = {
        "force_coefficient": p.force_coefficient,
        "feed_exponent": p.feed_exponent,
        "sensor_gain": ke,
        "command_max": cmax,
        "margin": margin,
        "spindle_power_W": power,
        "max_feed_velocity_mm_s": p.max_feed_velocity_mm_s,
        "breakage_force_N": p.breakage_force_N,
        "noise_std_N": p.noise_std_N,
        "workpiece_diameter_mm": p.workpiece_diameter_mm,
        "kf_low": lows[0],
        "kf_span": spans[0],
        "p_low": lows[1],
        "p_span": spans[1],
        "noise_low": lows[2],
        "noise_span": spans[2],
        "limit_varies": float(varies),
        "limit_low": limit[0],
        "limit_span": limit[1],
    }
    return np.array([numbers[b.name] for b in BN], dtype=np.float64)


@numba.njit(cache=True)
def _start_drawn_lanes(t, lanes, lo, hi, nums, rpm, v, segments, counts, ok):
    """:func:`_start_packed` for every lane ``lanes[i]`` of a split's batch that lies in
    ``lo .. hi - 1`` (the lanes of ``t``, whose first is lane ``lo``): its speed ``rpm[i]``,
    segments ``segments[i, :, : counts[i] + 1]`` and uniforms ``v[i]`` (the split factory's
    ``draw_lanes``), on the split's and nominal numbers ``nums`` (:data:`BN`): the
    true parameters ``TurningScenario.true_params`` makes of them (a sharp tool), in its
    order of operations. ``ok[i]``: whether the lane's step matrix was made
    (:func:`_start_packed`'s return)."""
    b = nums
    ke = b[BN.sensor_gain]
    full = math.isfinite(b[BN.spindle_power_W])
    x = np.empty(8)
    for i in range(lanes.size):
        if not lo <= lanes[i] < hi:
            continue
        vi = v[i]
        kf = b[BN.force_coefficient] * (b[BN.kf_low] + b[BN.kf_span] * vi[0])
        pexp = b[BN.feed_exponent] * (b[BN.p_low] + b[BN.p_span] * vi[1])
        consts = (kf, pexp, ke, b[BN.command_max], b[BN.margin], 0.0)
        x[0] = rpm[i]
        x[1] = b[BN.limit_low]
        if b[BN.limit_varies] != 0.0:
            x[1] = b[BN.limit_low] + b[BN.limit_span] * vi[3]
        x[2] = b[BN.max_feed_velocity_mm_s]
        x[3] = b[BN.breakage_force_N]
        # the sensor's gain Ke times the noise
        x[4] = ke * (b[BN.noise_std_N] * (b[BN.noise_low] + b[BN.noise_span] * vi[2]))
        x[5] = b[BN.workpiece_diameter_mm]
        x[6] = np.nan
        x[7] = b[BN.spindle_power_W]
        ok[i] = _start_packed(t, lanes[i] - lo, full, consts, lane_segments(segments, i, counts), x)


@numba.njit(cache=True)
def _start_packed(t, k, full_history, consts, segments, x):
    """:func:`_start` with its arrays in the kernel's table ``t`` (:func:`_step_packed`'s,
    records :data:`_TABLE`); ``k`` is the lane's index in ``t``."""
    a, e = _read_plant(t, _AT_PLANT), _read_env(t, _AT_ENV)
    ep, free = _read_episode(t, _AT_EPISODE), _read_free(t, _AT_FREE)
    return _start(k, full_history, consts, segments, x, a, e, ep, free)


class TurningCore(FeedRegulationCore):
    """The state and arithmetic of N turning episodes, shared by ``TurningEnv`` (one lane)
    and ``TurningVectorEnv`` (N lanes): the plant (:class:`TurningLanes`) and the reward,
    observation and episode end computed for all lanes by one compiled function, so that a
    lane of the vector env and the single env agree to the last bit."""

    #: What a scenario may be: an object of this class or one of these names.
    scenario_types = (TurningScenario, TURNING_SCENARIOS)
    #: The nominal parameters' class, its default set and the reward weights' class.
    option_types = (TurningParams, TurningParams.noh_kim_kim_1992, TurningReward)
    VIEWS = frozenset({*EF.__members__, "flags", "in_clipped", "clipped", "_args"})

    def __init__(
        self,
        owner: str,
        n: int,
        scenario: str | TurningScenario,
        *,
        params: TurningParams | None,
        spindle_rpm: float | None,
        reward: LimitReward | dict | None,
        max_episode_time_s: float,
        overrides: dict,
        actuation=None,
        power_sensor=None,
    ):
        self._set_regulation(owner, n, scenario, params, reward, max_episode_time_s, overrides)
        self._set_cnc(actuation, power_sensor)  # the spindle power: the load channel
        if spindle_rpm is not None:
            spindle_rpm = check_range(
                "spindle_rpm", spindle_rpm, *SPINDLE_RPM_RANGE, types=PY_NUMBER_TYPES
            )
        self.spindle_rpm_override = spindle_rpm
        self._gain = float(self.params.sensor_gain)
        self._fs = float(self.params.force_scale_N)
        self.command_map = ActionMap(0.0, self.params.command_max)
        self._set_regulation_spaces(_FORCE_OBS, SPINDLE_RPM_RANGE[1])
        self.lanes = TurningLanes(self.params, n)
        #: Every lane's scenario and true parameters (built when read, for lanes started
        #: together by :meth:`start_lanes`).
        self.scenarios = LaneObjects(n)
        # The per-lane floats and flags the kernel reads and writes, each set in one array
        # (one argument of the kernel) and named here by views of its columns.
        self.ef = np.zeros((n, len(EF)))
        self.eb = np.zeros((n, len(EB)), dtype=np.bool_)
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
        self._packed = PackedArgs()  # the kernel's arguments in one table (core.compiled.packed)
        #: The starts a vector env's blocks make (_start_pending; the draws sized for the
        #: first batch, grown with it).
        self._batch = TurningBatch(
            lane_index=np.arange(n, dtype=np.int64),
            pending=np.zeros(n + 1, dtype=np.int64),
            nums=np.zeros(len(BN)),
            rpm=np.zeros(n),
            v=np.zeros((n, 4)),
            segments=np.zeros((n, 4, 2)),
            counts=np.zeros(n, dtype=np.int64),
            ok=np.zeros(n, dtype=np.bool_),
        )
        #: The blocks of lanes the kernel steps at once (one thread unless a vector env
        #: asks for more).
        self.blocks = LaneBlocks(n)

    def bind_views(self) -> None:
        """Name the columns of ``ef`` (:data:`EF`) and ``eb`` (:data:`EB`)."""
        bind_columns(self, self.ef, EF)
        self.flags = self.eb[:, : EB.in_clipped]
        self.in_clipped = self.eb[:, EB.in_clipped]
        self.clipped = self.eb[:, EB.clipped]

    def set_action(self, lane: int, action: float, clipped: bool) -> None:
        ef = self.ef[lane]
        ef[_IN_ACTION] = action
        ef[_IN_COMMAND] = self.command_map.action_to_command(action)
        self.in_clipped[lane] = clipped

    def set_actions(self, actions: np.ndarray) -> None:
        m = self.command_map  # linear: one compiled pass clips and maps
        a = actions[:, 0]
        clip_unit_linear(a, self.in_action, self.in_clipped, self.in_command, m.mid, m.half)

    def outcome(self, lane: int) -> tuple[float, bool, bool]:
        terminated, truncated = self.eb[lane, _TERMINATED:_OVER].tolist()
        return float(self.ef[lane, _REWARD]), terminated, truncated

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
        noise = truth.sensor_gain * truth.noise_std_N
        vmax, brk = truth.max_feed_velocity_mm_s, truth.breakage_force_N
        x = np.array((rpm, limit, vmax, brk, noise, diameter, bound, power_W))
        table = self._packed(self._kernel_args())
        if not _start_packed(table, lane, full, lanes.lane_constants(truth), segments, x):
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
        bound, length = float(self.bound[lane]), float(self.length[lane])
        self.episode_info[lane] = (bound, length, sc.name, rpm, diameter)
        if self.power_sensor:
            self._sense_power([lane])

    def _start_batch(self, lanes: np.ndarray, factory) -> None:
        rpm, segments, counts, v = factory.draw_lanes(self.rngs.table, lanes)
        nums = self._batch_numbers.get(factory)
        if nums is None:
            nums = self._batch_numbers[factory] = _batch_numbers(self, factory)
        full = math.isfinite(nums[5])
        self.lanes.fit_segments(int(counts.max()))
        if self.blocks.one:
            ok = np.empty(lanes.size, dtype=np.bool_)
            table = self._packed(self._kernel_args())
            _start_drawn_lanes(table, lanes, 0, self.n, nums, rpm, v, segments, counts, ok)
        else:  # each block of lanes starts its own, on its thread
            ok = self._start_in_blocks(lanes, nums, rpm, v, segments, counts)
        ks = lanes.tolist()
        if not ok.all():
            for i in np.flatnonzero(~ok).tolist():  # left for zoh (never in the plant's ranges)
                self.lanes._load_matrices(ks[i], float(rpm[i]), full)
        draws = (rpm, segments, counts, v)
        actuation = factory.shop["actuation"]
        settle_batch(self, lanes, factory.build_lane, draws, actuation, factory.name)
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

    def batches(self, factory) -> bool:
        """Whether :meth:`start_lanes` may start ``factory``'s scenarios in one batch: a
        split's, without wear (whose score bound is integrated in Python) or a spindle
        speed set by the env, whose every true parameter set passes the checks
        ``start`` makes (those of the ranges' two ends, checked once)."""
        if not isinstance(factory, _SplitFactory) or factory.wear is not None:
            return False
        if self.spindle_rpm_override is not None:
            return False

        def check(sc) -> bool:
            truth = sc.true_params(self.params)
            return float(sc.force_limit_N) < truth.breakage_force_N

        return self._extremes_pass(factory, check)

    def _make_kernel_args(self) -> tuple:
        """The kernel's arguments: the fields of its records (:data:`_TABLE`) in order
        (``_kernel_args`` keeps them until the plant's arrays are replaced): one table
        serves the step and every start."""
        env = gather(
            TurningEnvArrays,
            self,
            gain=self._gain,
            fs=self._fs,
            max_t=self.max_episode_time_s,
            w=self._w,
            rng_table=self.rngs.table,
        )
        episodes = gather(TurningEpisodes, self)
        lanes = self.lanes
        return flatten(lanes.arrays(), env, episodes, lanes.speed_free, self._batch)

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
        self.power_sensor.update(self.obs, lanes, cutting, rpm, self.force_limit * v)

    def _run_blocks(self, op: int) -> None:
        """:func:`_step_packed`'s ``op`` on every block of lanes, on the blocks' threads
        (its tables always pack: every array holds the lanes on axis 0 or is shared)."""
        args = self._kernel_args()
        self.blocks.run(_step_flat, args, _STEP_AXES, op, packed=_step_packed, serve=_serve_step)

    def _start_in_blocks(self, lanes, nums, rpm, v, segments, counts) -> np.ndarray:
        """:func:`_start_drawn_lanes` for a batch, each block of lanes starting its own on
        its thread (:func:`_start_pending`): the same numbers as one call over the batch.
        Whether each lane's step matrix was made."""
        size = lanes.size
        width, points = v.shape[1], segments.shape[2]
        b = self._batch
        if width > b.v.shape[1] or points > b.segments.shape[2]:  # grow them
            n = self.n
            width_max, points_max = max(width, b.v.shape[1]), max(points, b.segments.shape[2])
            b = self._batch = b._replace(
                v=np.zeros((n, width_max)), segments=np.zeros((n, 4, points_max))
            )
            self._args = None  # the kernel's table holds them
        b.pending[0] = size
        b.pending[1 : size + 1] = lanes
        b.nums[:] = nums
        b.rpm[:size] = rpm
        b.v[:size, :width] = v
        b.segments[:size, :, :points] = segments
        b.counts[:size] = counts
        self._run_blocks(1)
        return b.ok[:size].copy()

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
            bound, length = float(self.bound[k]), float(self.length[k])
            rpm, diameter = float(self.spindle_set[k]), float(self.diameter[k])
            episode = self.episode_info[k] = (bound, length, self.names[k], rpm, diameter)
        bound, length, name, rpm, diameter = episode
        if k in self.power_lanes:  # drive and cutting power from the spindle's drive
            p_drive, p_cut = self.power[k].tolist()
            rpm = float(self.spindle[k])
        else:  # an ideal spindle delivers what the cut asks: cutting_power_W's arithmetic,
            # in its order, on Python floats (the same numbers as _info_rows)
            p_drive = p_cut = max(force, 0.0) * (rpm * (math.pi / 30.0)) * (diameter * 0.0005)
        feed_ok = not diverged  # a diverged lane shows no feed
        signals = {
            "force_N": force,
            "force_limit_N": ef[_FORCE_LIMIT],
            "cost": 1.0 if over else 0.0,
            "score_bound": bound,
            "measured": float(self.meas[k, 0]),
            "measured_counts": counts,
            "peak_force_N": peak,
            "feed_mm_per_rev": feed if feed_ok else 0.0,
            "feed_velocity_mm_s": vel if feed_ok else 0.0,
            "position_mm": pos if feed_ok else 0.0,
            "depth_mm": depth,
        }
        episode = {
            "spindle_rpm": rpm,
            "spindle_power_W": p_drive,
            "cutting_power_W": p_cut,
            "workpiece_length_mm": length,
            "scenario": name,
        }
        head = (float(lanes.lane_f[k, 5]), ef[_COMMAND], clipped)
        finish = float(lanes.out_finish[k])
        return self._info(k, head, (diverged, breakage, finished), signals, episode, finish)

    def info_arrays(self) -> dict:
        """The step info of every lane, as arrays (``machining_time_s`` with its mask): views
        of one table of the float keys (:func:`_info_rows`) and one copy of the flags."""
        c = spaced_rows(len(_INFO_F), self.n)
        a = self.lanes
        _info_rows(
            a.lane_f,
            self.ef,
            self.eb,
            a.out,
            a.out_finish,
            self.meas,
            self.bound,
            self.spindle,
            self.diameter,
            self.length,
            c,
        )
        for k in self.power_lanes:  # drive and cutting power from the spindle's drive
            c[14, k], c[15, k] = self.power[k]
        f = self.eb.copy()
        info = dict(zip(_INFO_F, c, strict=True))
        head = (info["t_s"], info["command"], f[:, 7])
        signals = {k: info[k] for k in _INFO_F[2:13]}
        episode = {k: info[k] for k in _INFO_F[13:17]}
        episode["scenario"] = self.names.array()
        finish = info["machining_time_s"]
        return self._info(None, head, (f[:, 0], f[:, 1], f[:, 2]), signals, episode, finish)
