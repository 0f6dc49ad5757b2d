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

import numpy as np

from machining_envs.contouring.paths import PAPER_CORNER_FEED_MM_S, PAPER_FEED_MM_S, Path
from machining_envs.contouring.plant import ContouringParams
from machining_envs.core.actuation import Actuation
from machining_envs.core.checks import check_below, check_range, drawn_instance
from machining_envs.core.env import resolve_scenario
from machining_envs.core.splits import split_stream

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
    """

    name: str
    path: Path
    feed_mm_s: float
    load_steps: tuple[tuple[float, float, float], ...] = ()
    inertia_scale: tuple[float, float] = (1.0, 1.0)
    dwell_s: float = 0.0
    actuation: Actuation | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.path, Path):
            raise ValueError(f"path must be a Path, got {type(self.path).__name__}")
        if not (isinstance(self.feed_mm_s, (int, float)) and self.feed_mm_s == math.inf):
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
        if self.actuation is not None and not isinstance(self.actuation, Actuation):
            raise ValueError(
                f"actuation must be an Actuation or None, got {type(self.actuation).__name__}"
            )

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
        sx, sy = self.inertia_scale
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


#: The feed-override handling of the ``shopfloor`` scenarios of ContouringFeed-v0, as shares
#: of the default override range [0, 2]: 1 % steps of the programmed feed, at most 5x the
#: programmed feed per second (0.2 s from rest to it) and 120x per second squared, two
#: decisions (20 ms) of delay. Chosen, not measured: a CNC applies the override through its
#: feed planner, which limits how fast the path speed may change; these limits bind on the
#: paths' corners, where an ideal override would brake within one decision.
SHOPFLOOR_OVERRIDE = Actuation(quantum=0.005, max_rate_per_s=2.5, delay_steps=2,
                               max_accel_per_s2=60.0)  # fmt: skip


def _random(
    name: str,
    segments: tuple[int, int],
    line: tuple[float, float],
    radius: tuple[float, float],
    sweep: tuple[float, float],
    feed: tuple[float, float],
    inertia: tuple[float, float],
    load_max: float,
    actuation: Actuation | None = None,
):
    # The log-uniform draws' bounds, as numpy computes them, once.
    log_feed = (np.log(feed[0]), np.log(feed[1]))
    log_inertia = (np.log(inertia[0]), np.log(inertia[1]))
    # Every drawn field lies between these two scenarios' (checked here, once): make()
    # builds its scenarios without checking them again.
    for end in (0, 1):
        ContouringScenario(
            name, Path.line((0.0, 0.0), (1.0, 0.0)), feed[end], ((0.0, load_max, -load_max),),
            (inertia[end], inertia[end]), actuation=actuation,
        )  # fmt: skip

    def make(env_rng: np.random.Generator) -> ContouringScenario:
        rng = split_stream(env_rng, name)
        path = Path.random_smooth(
            rng,
            n_segments=segments,
            line_mm=line,
            radius_mm=radius,
            sweep_deg=sweep,
            name=f"{name} path",
        )
        f = float(np.exp(rng.uniform(*log_feed)))
        sx, sy = np.exp(rng.uniform(*log_inertia, 2)).tolist()
        loads = ()
        if rng.random() < 0.5:
            t = float(rng.uniform(0.0, path.length / f))
            a, b = rng.uniform(-load_max, load_max, 2).tolist()
            loads = ((t, a, b),)
        return drawn_instance(
            ContouringScenario,
            {
                "name": name,
                "path": path,
                "feed_mm_s": f,
                "load_steps": loads,
                "inertia_scale": (sx, sy),
                "dwell_s": 0.0,
                "actuation": actuation,
            },
        )

    return make


#: The ranges of the training distribution (segments, line length, radius, sweep, feed,
#: inertia scale, largest load): see ``CONTOURING_SCENARIOS``.
_TRAINING_RANGES = ((3, 5), (5.0, 20.0), (3.0, 30.0), (30.0, 180.0), (20.0, 60.0), (0.8, 1.25), 1.5)

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
    **{split: _random(split, *_TRAINING_RANGES) for split in ("train", "validation", "test")},
    "ood": _random(
        "ood", (3, 6), (3.0, 20.0), (2.0, 40.0), (20.0, 240.0), (15.0, 90.0), (0.7, 1.4), 2.0
    ),
    "shopfloor": _random("shopfloor", *_TRAINING_RANGES, actuation=SHOPFLOOR_OVERRIDE),
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
