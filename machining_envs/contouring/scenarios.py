"""Named contouring scenarios: the paper's tests and the four splits of the benchmark.

A scenario fixes the path, the programmed feed, the load-torque steps the cutting puts on
the axes and the table's true inertias (as multiples of the nominal ones: the workpiece and
fixture on the table change them, and no controller is told). Pass a name or a
:class:`ContouringScenario` to ``env.reset(options={"scenario": ...})``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from machining_envs.contouring.paths import (
    PAPER_CORNER_FEED_MM_S,
    PAPER_FEED_MM_S,
    SEGMENT_COLUMNS,
    Path,
    smooth_table,
)
from machining_envs.contouring.plant import ContouringParams
from machining_envs.core.actuation import SHOPFLOOR_OVERRIDE, Actuation
from machining_envs.core.checks import (
    PY_NUMBER_TYPES,
    check_below,
    check_instance,
    check_overload_ratio,
    check_range,
    drawn_instance,
    is_real,
)
from machining_envs.core.env import resolve_scenario
from machining_envs.core.splits import (
    _split_key,
    lane_split_state,
    split_stream,
    stream_bounded,
    stream_double,
    stream_fill,
)

__all__ = [
    "ContouringScenario",
    "CONTOURING_SCENARIOS",
    "contouring_scenario",
    "PAPER_STEP_MM",
    "PAPER_LOAD_TORQUE_NM",
    "PAPER_LOAD_TIME_S",
    "FEED_RANGE_MM_S",
    "SHOPFLOOR_OVERRIDE",
    "check_feed",
]

#: Size of the step of the paper's step-response tests (Fig. 4-5), mm. The paper plots a
#: unit step of its linear model; the loop is linear as long as no command reaches the
#: drive's limit, and the H-infinity loop asks for 6.5 mm/s per um of step at its peak, so
#: 0.1 mm (65 mm/s) keeps both controllers linear; responses are shown normalised.
PAPER_STEP_MM = 0.1
#: Load torque of the disturbance tests, N m at the motor shaft. Not given in the paper:
#: 1 N m is about 630 N of feed force through the 10 mm lead (a heavy milling cut) and 20 %
#: of a 0.85 kW motor's rated 5.4 N m.
PAPER_LOAD_TORQUE_NM = 1.0
#: When the load torque steps on in the step test (after both loops have settled), s.
PAPER_LOAD_TIME_S = 0.15
#: Programmed feeds a scenario accepts, mm/s (``math.inf`` marks a step command).
FEED_RANGE_MM_S = (0.01, 1000.0)


#: The overload ceiling of a run, a multiple of its contour tolerance: 2. Past the
#: tolerance the part is out of tolerance at that spot, which a short excursion may leave
#: within what finishing removes; an error twice the tolerance is a gouge as deep as the
#: whole tolerance band beyond it, which inspection rejects however short it is.
OVERLOAD_RATIO = 2.0


@dataclass(frozen=True)
class ContouringScenario:
    """One contouring run: path, feed, load torques and the table's hidden inertias.

    Parameters
    ----------
    name : str
    path : Path
        The toolpath; the table starts at rest at its start.
    feed_mm_s : float
        Programmed feed along the path, mm/s (in ``FEED_RANGE_MM_S``), or ``math.inf`` for
        a step command: the set point jumps to the path's end at ``t = 0`` (Fig. 4-5).
    load_steps : tuple of (t_s, load_x_Nm, load_y_Nm)
        From time ``t_s`` on, the load torque on each axis's motor is the given value (N m,
        ``|T| <= 20``); times ascending. Empty: no load (the paper's design condition).
    inertia_scale : (float, float)
        True Jx, Jy as multiples of the nominal ones (0.5 to 2).
    dwell_s : float
        The run continues at least this long after the reference reaches the path's end
        (0 to 10 s), e.g. to watch a load step after a step response settles.
    actuation : Actuation or None
        The CNC's handling of the feed override for this run (ContouringFeed-v0 only,
        ``machining_envs.core.actuation``); None (default): the env's ``actuation`` option
        decides. Contouring-v0 commands the axes directly and refuses it.
    overload_ratio : float
        The overload ceiling, a multiple of the contour tolerance (1 to 10, default
        ``OVERLOAD_RATIO``): a run whose contour error passes it does not count, however
        short the excursion (``machining_envs.core.score``).
    """

    name: str
    path: Path
    feed_mm_s: float
    load_steps: tuple[tuple[float, float, float], ...] = ()
    inertia_scale: tuple[float, float] = (1.0, 1.0)
    dwell_s: float = 0.0
    actuation: Actuation | None = None
    overload_ratio: float = OVERLOAD_RATIO

    def __post_init__(self) -> None:
        check_overload_ratio(self.overload_ratio)
        check_instance("path", self.path, Path)
        if not (is_real(self.feed_mm_s, PY_NUMBER_TYPES) and self.feed_mm_s == math.inf):
            check_range("feed_mm_s", self.feed_mm_s, *FEED_RANGE_MM_S)
        try:
            steps = tuple((float(t), float(a), float(b)) for t, a, b in self.load_steps)
        except (TypeError, ValueError):
            raise ValueError(
                f"load_steps must be a sequence of (t_s, load_x_Nm, load_y_Nm), got {self.load_steps!r}"
            ) from None
        prev = -math.inf
        for t, a, b in steps:
            check_range("load_steps time", t, 0.0, 1e4)
            check_range("load_steps torque", a, -20.0, 20.0)
            check_range("load_steps torque", b, -20.0, 20.0)
            if t < prev:
                raise ValueError(f"load_steps times must ascend, got {self.load_steps!r}")
            prev = t
        object.__setattr__(self, "load_steps", steps)
        try:
            sx, sy = self.inertia_scale
        except (TypeError, ValueError):
            raise ValueError(
                f"inertia_scale must be a pair (x, y), got {self.inertia_scale!r}"
            ) from None
        object.__setattr__(
            self,
            "inertia_scale",
            (
                check_range("inertia_scale", sx, 0.5, 2.0),
                check_range("inertia_scale", sy, 0.5, 2.0),
            ),
        )
        check_range("dwell_s", self.dwell_s, 0.0, 10.0)
        check_instance("actuation", self.actuation, Actuation, optional=True)

    @property
    def is_step(self) -> bool:
        """True for a step command (``feed_mm_s = inf``)."""
        return self.feed_mm_s == math.inf

    @property
    def reference_time_s(self) -> float:
        """When the reference reaches the path's end, s (0 for a step)."""
        return 0.0 if self.is_step else self.path.length / self.feed_mm_s

    def true_params(self, nominal: ContouringParams) -> ContouringParams:
        """The table this run really has (hidden from controllers)."""
        return true_params_of(self.inertia_scale, nominal)


def true_params_of(inertia_scale, nominal: ContouringParams) -> ContouringParams:
    """The table with the inertias ``nominal``'s times ``inertia_scale`` (a scenario's
    :meth:`ContouringScenario.true_params`)."""
    sx, sy = inertia_scale
    if sx == 1.0 and sy == 1.0:
        return nominal
    return nominal.replace(
        inertia_x_kgm2=nominal.inertia_x_kgm2 * sx, inertia_y_kgm2=nominal.inertia_y_kgm2 * sy
    )


def _step(load: bool) -> Callable[[np.random.Generator], ContouringScenario]:
    def make(rng: np.random.Generator) -> ContouringScenario:
        loads = ((PAPER_LOAD_TIME_S, PAPER_LOAD_TORQUE_NM, 0.0),) if load else ()
        return ContouringScenario(
            "paper_step_load" if load else "paper_step",
            Path.line((0.0, 0.0), (PAPER_STEP_MM, 0.0), name="step X"),
            math.inf,
            loads,
            dwell_s=0.4 if load else 0.1,
        )

    return make


def _paper(name: str, path: Callable[[], Path], feed: float, loads=()):
    def make(rng: np.random.Generator) -> ContouringScenario:
        return ContouringScenario(name, path(), feed, loads)

    return make


class _PathRanges(NamedTuple):
    """A split's ranges (the ends of each draw)."""

    #: Number of segments of the path.
    segments: tuple[int, int]
    #: Length of its lines, mm.
    line: tuple[float, float]
    #: Radius of its arcs, mm.
    radius: tuple[float, float]
    #: Sweep of its arcs, degrees.
    sweep: tuple[float, float]
    #: Programmed feed, mm/s (drawn log-uniform).
    feed: tuple[float, float]
    #: Scale of each axis's inertia (drawn log-uniform).
    inertia: tuple[float, float]
    #: Largest load torque of a load step, N m, on either axis.
    load_max: float


class _RandomPaths:
    """The factory of a split's random scenarios: a tangent-continuous chain of lines and
    arcs (:meth:`Path.random_smooth`), a log-uniform feed, log-uniform inertia scales and,
    in half the runs, one load step at a random time, all drawn from the split's stream of
    the env's generator. A vector env draws the numbers of many lanes at once
    (:meth:`draw_lanes`, compiled) and builds a lane's scenario only when it is read
    (:meth:`build_lane`): the same scenarios, the same numbers."""

    def __init__(self, name: str, ranges: _PathRanges, actuation: Actuation | None = None) -> None:
        segments, line, radius, sweep, feed, inertia, load_max = ranges
        self.name = name
        self.segments, self.line, self.radius, self.sweep = segments, line, radius, sweep
        self.feed, self.inertia, self.load_max, self.actuation = feed, inertia, load_max, actuation
        # The log-uniform draws' bounds, as numpy computes them, once.
        self.log_feed = (float(np.log(feed[0])), float(np.log(feed[1])))
        self.log_inertia = (float(np.log(inertia[0])), float(np.log(inertia[1])))
        # What draw_lanes hands its compiled draw besides the generators and lanes, made once.
        self._draw_args = (
            _split_key(name),
            segments[0],
            segments[1],
            np.array(line),
            np.array(radius),
            np.array(sweep),
            _LINE_PROBABILITY,
            np.array(self.log_feed),
            np.array(self.log_inertia),
            float(load_max),
        )
        # Every drawn field lies between these two scenarios' (checked here, once): the
        # factory builds its scenarios without checking them again.
        self.extremes = tuple(
            ContouringScenario(
                name,
                Path.line((0.0, 0.0), (1.0, 0.0)),
                feed[end],
                ((0.0, load_max, -load_max),),
                (inertia[end], inertia[end]),
                actuation=actuation,
            )
            for end in (0, 1)
        )

    def __call__(self, env_rng: np.random.Generator) -> ContouringScenario:
        rng = split_stream(env_rng, self.name)
        path = Path.random_smooth(
            rng,
            n_segments=self.segments,
            line_mm=self.line,
            radius_mm=self.radius,
            sweep_deg=self.sweep,
            name=f"{self.name} path",
        )
        f = float(np.exp(rng.uniform(*self.log_feed)))
        sx, sy = np.exp(rng.uniform(*self.log_inertia, 2)).tolist()
        loads = ()
        if rng.random() < 0.5:
            t = float(rng.uniform(0.0, path.length / f))
            a, b = rng.uniform(-self.load_max, self.load_max, 2).tolist()
            loads = ((t, a, b),)
        return self._scenario(path, f, (sx, sy), loads)

    def _scenario(self, path: Path, f: float, scale: tuple, loads: tuple) -> ContouringScenario:
        return drawn_instance(
            ContouringScenario,
            {
                "name": self.name,
                "path": path,
                "feed_mm_s": f,
                "load_steps": loads,
                "inertia_scale": scale,
                "dwell_s": 0.0,
                "actuation": self.actuation,
            },
        )

    def draw_lanes(self, table, lanes: np.ndarray) -> DrawnPaths:
        """The numbers of :meth:`__call__` for every lane in ``lanes``, each drawn from the
        split's stream of its generator in ``table`` (``LaneGenerators.table``) in one
        compiled call, every generator left where ``__call__`` leaves it; the feeds and
        inertia scales are numpy's ``exp`` of the drawn exponents, as there."""
        ints, floats, tabs, draws = _draw_smooth_lanes(table, lanes, *self._draw_args)
        feed = np.exp(floats[:, _D_FEED])
        scale = np.exp(floats[:, _D_SX : _D_SY + 1])
        return DrawnPaths(ints, floats, tabs, draws, feed, scale)

    def build_lane(self, drawn: DrawnPaths, i: int) -> ContouringScenario:
        """The scenario of lane ``i`` of the lanes' numbers from :meth:`draw_lanes`."""
        n = int(drawn.ints[i, 0])
        path = Path._smooth(
            drawn.draws[i, :, :n].tolist(),
            float(drawn.floats[i, _D_HEADING]),
            self.line,
            self.radius,
            self.sweep,
            _LINE_PROBABILITY,
            (0.0, 0.0),
            f"{self.name} path",
        )
        loads = ()
        if drawn.ints[i, 1]:
            length, u, a, b = drawn.floats[i, [_D_LENGTH, _D_T, _D_A, _D_B]].tolist()
            loads = ((load_time(length, float(drawn.feed[i]), u), a, b),)
        return self._scenario(path, float(drawn.feed[i]), tuple(drawn.scale[i].tolist()), loads)


#: ``Path.random_smooth``'s default share of lines, which the split scenarios keep.
_LINE_PROBABILITY = 0.4
#: Columns of :func:`_draw_smooth_lanes`' floats: the first heading, the path's length,
#: start and end, the exponents of the feed and of the inertia scales, the load's raw
#: uniform for its time and its two torques.
_D_HEADING, _D_LENGTH, _D_X0, _D_Y0, _D_XE, _D_YE = range(6)
_D_FEED, _D_SX, _D_SY, _D_T, _D_A, _D_B = range(6, 12)


class DrawnPaths(NamedTuple):
    """The numbers of many lanes' split scenarios (:meth:`_RandomPaths.draw_lanes`):
    ``ints[i]`` = (segments, whether a load step); ``floats[i]``, columns ``_D_*``;
    ``tabs[i, :segments]``, each path's table (``Path.table``); ``draws[i, :, :segments]``,
    its segments' uniform numbers; the feeds and inertia scales. A load step's time is
    :func:`load_time` of the lane's numbers."""

    ints: np.ndarray
    floats: np.ndarray
    tabs: np.ndarray
    draws: np.ndarray
    feed: np.ndarray
    scale: np.ndarray


@numba.njit(cache=True)
def load_time(length, feed, u):
    """The time of a drawn load step: ``uniform(0, length / feed)`` from its uniform ``u``,
    in numpy's arithmetic (``low + (high - low) u``), as :meth:`_RandomPaths.__call__`
    draws it; compiled, for a batch's compiled start and a lane's scenario alike."""
    return 0.0 + (length / feed - 0.0) * u


@numba.njit(cache=True)
def _draw_smooth_lanes(
    table,
    lanes,
    key,
    seg_lo,
    seg_hi,
    line,
    radius,
    sweep,
    line_probability,
    log_feed,
    log_inertia,
    load_max,
):
    """:meth:`_RandomPaths.draw_lanes`' compiled part: each lane's stream
    (``lane_split_state``) and, in :meth:`_RandomPaths.__call__`'s order, the draws of
    ``random_smooth`` (the number of segments, their uniforms, the first heading), of the
    feed's and inertias' exponents (``low + (high - low) u``) and of the load step; each
    path's table by :func:`~machining_envs.contouring.paths.smooth_table`."""
    n_lanes = lanes.size
    ints = np.zeros((n_lanes, 2), dtype=np.int64)
    floats = np.zeros((n_lanes, 12))
    tabs = np.zeros((n_lanes, seg_hi, SEGMENT_COLUMNS))
    draws = np.zeros((n_lanes, 5, seg_hi))
    state = np.empty(6, dtype=np.uint64)
    u = np.empty(5 * seg_hi)
    two = np.empty(2)
    for i in range(n_lanes):
        lane_split_state(table, lanes[i], key, state)
        n = seg_lo + stream_bounded(state, seg_hi - seg_lo)
        stream_fill(state, u[: 5 * n])
        for r in range(5):
            for k in range(n):
                draws[i, r, k] = u[r * n + k]
        f = floats[i]
        f[_D_HEADING] = -math.pi + (math.pi - -math.pi) * stream_double(state)
        f[_D_LENGTH], f[_D_X0], f[_D_Y0], f[_D_XE], f[_D_YE] = smooth_table(
            draws[i], n, f[_D_HEADING], line, radius, sweep, line_probability, tabs[i]
        )
        f[_D_FEED] = log_feed[0] + (log_feed[1] - log_feed[0]) * stream_double(state)
        stream_fill(state, two)
        f[_D_SX] = log_inertia[0] + (log_inertia[1] - log_inertia[0]) * two[0]
        f[_D_SY] = log_inertia[0] + (log_inertia[1] - log_inertia[0]) * two[1]
        ints[i, 0] = n
        if stream_double(state) < 0.5:
            ints[i, 1] = 1
            f[_D_T] = stream_double(state)
            stream_fill(state, two)
            f[_D_A] = -load_max + (load_max - -load_max) * two[0]
            f[_D_B] = -load_max + (load_max - -load_max) * two[1]
    return ints, floats, tabs, draws


#: The ranges of the training distribution (segments, line length, radius, sweep, feed,
#: inertia scale, largest load): see ``CONTOURING_SCENARIOS``.
_TRAINING_RANGES = _PathRanges(
    (3, 5), (5.0, 20.0), (3.0, 30.0), (30.0, 180.0), (20.0, 60.0), (0.8, 1.25), 1.5
)

#: name -> factory drawing a scenario from the env's generator. The paper's tests:
#: ``paper_step`` / ``paper_step_load`` (Fig. 4-5: a 0.1 mm X step; with a 1 N m load step at
#: 0.15 s), ``paper_corner`` (Fig. 6, 5 mm/s), ``paper_circle`` (Fig. 7, R 10 mm at 50 mm/s),
#: ``paper_involute`` (Fig. 8, R 50 mm at 50 mm/s) and ``paper_circle_load`` (the circle with
#: 1 N m on both axes from 0.5 s). ``train``, ``validation``, ``test`` (one distribution,
#: separate streams): 3-5 random tangent-continuous lines (5-20 mm) and arcs (radius 3-30
#: mm, 30-180 degrees), feed log-uniform 20-60 mm/s, inertias log-uniform x0.8-1.25, half
#: the runs with one load step of up to 1.5 N m per axis at a random time. ``ood`` (wider):
#: 3-6 segments, lines 3-20 mm, radius 2-40 mm, 20-240 degrees, feed 15-90 mm/s, inertias
#: x0.7-1.4, loads up to 2 N m. ``shopfloor`` (ContouringFeed-v0 only): the training ranges
#: with a real CNC's override handling (``SHOPFLOOR_OVERRIDE``).
CONTOURING_SCENARIOS: dict[str, Callable[[np.random.Generator], ContouringScenario]] = {
    "paper_step": _step(False),
    "paper_step_load": _step(True),
    "paper_corner": _paper("paper_corner", Path.paper_corner, PAPER_CORNER_FEED_MM_S),
    "paper_circle": _paper("paper_circle", Path.paper_circle, PAPER_FEED_MM_S),
    "paper_involute": _paper("paper_involute", Path.paper_involute, PAPER_FEED_MM_S),
    "paper_circle_load": _paper(
        "paper_circle_load",
        Path.paper_circle,
        PAPER_FEED_MM_S,
        ((0.5, PAPER_LOAD_TORQUE_NM, PAPER_LOAD_TORQUE_NM),),
    ),
    **{split: _RandomPaths(split, _TRAINING_RANGES) for split in ("train", "validation", "test")},
    "ood": _RandomPaths(
        "ood",
        _PathRanges((3, 6), (3.0, 20.0), (2.0, 40.0), (20.0, 240.0), (15.0, 90.0), (0.7, 1.4), 2.0),
    ),
    "shopfloor": _RandomPaths("shopfloor", _TRAINING_RANGES, actuation=SHOPFLOOR_OVERRIDE),
}


def check_feed(scenario: ContouringScenario, params: ContouringParams) -> None:
    """``ValueError`` if the scenario's programmed feed is above the drives' top speed
    (``params.command_max_mm_s``: ``motor_max_rpm`` through ``screw_lead_mm``). A CNC
    never programs a feed its axes cannot reach; a step command (``feed_mm_s = inf``) is
    the one deliberate exception, the paper's step-response test."""
    if scenario.is_step:
        return
    check_below(
        f"scenario {scenario.name!r}: feed_mm_s",
        scenario.feed_mm_s,
        "the drives' top speed (motor_max_rpm / 60 x screw_lead_mm, mm/s)",
        params.command_max_mm_s,
        "the axes could not follow the path at that feed",
        strict=False,
    )


def contouring_scenario(spec, rng: np.random.Generator) -> ContouringScenario:
    """Resolve a scenario name or object; unknown names raise ``ValueError``."""
    return resolve_scenario(spec, rng, ContouringScenario, CONTOURING_SCENARIOS)
