"""Named end-milling scenarios: Park & Yoon's workpieces and the four splits of the benchmark.

A scenario fixes what changes from one cut to the next and what a controller cannot see:
the workpiece's radial-depth profile, the spindle speed and the process torque limit (as
multiples of the nominal ones in ``MillingParams``) and the true process constants (as
multiples of the nominal torque coefficient and feed exponent). Pass a name or a scenario
object to ``env.reset(options={"scenario": ...})``.

Splits (``machining_envs.core.splits``): ``train`` and ``validation`` share one
distribution, each drawing through its own stream; ``test`` draws from the benchmark's
published ranges inside it; ``ood`` goes beyond both; ``wear`` (a tool that dulls within
the cut) and ``shopfloor`` (a real CNC's feed override) are the test distribution on a
less ideal machine (see ``MILLING_SCENARIOS``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from machining_envs.core.actuation import SHOPFLOOR_ACTUATION, Actuation
from machining_envs.core.checks import (
    check_instance,
    check_overload_ratio,
    check_ranged_fields,
    drawn_instance,
    ranged,
)
from machining_envs.core.env import resolve_scenario
from machining_envs.core.workpieces import (
    DepthProfile,
    SplitCuts,
)
from machining_envs.milling.plant import SPINDLE_RPM_RANGE, MillingParams, bisect_right

__all__ = [
    "MillingScenario",
    "MILLING_SCENARIOS",
    "milling_scenario",
    "PAPER_LENGTH_MM",
    "PAPER_STEP_DEPTHS_MM",
    "PAPER_TAPER_DEPTHS_MM",
    "PAPER_CONSTANT_FEED_MM_MIN",
    "paper_step_profile",
    "paper_taper_profile",
    "cut_area_mm2",
    "CutArea",
    "cut_area_at",
    "machining_time_bound",
]

#: Workpiece length L, mm (Park & Yoon §4: L = 40, cut in 200 samples).
PAPER_LENGTH_MM = 40.0
#: Radial depths of the step workpiece, three equal steps, mm (Fig. 4a).
PAPER_STEP_DEPTHS_MM = (1.0, 2.0, 3.0)
#: Radial depth of the taper workpiece at its start and end, mm (Fig. 4b: rising linearly to
#: the step's 3 mm). Table 1's metal removal rates imply a mean depth of 1.5 mm, i.e. a
#: taper from 0 (MRR = (L / T_m) w mean(d) with w = 32 mm).
PAPER_TAPER_DEPTHS_MM = (0.0, 3.0)
#: The constant feed velocities, mm/min, that Table 1's "without AC" rows imply through
#: eq. (20): L / T_m = 40 mm / 11.797 min (step) and 40 mm / 15.914 min (taper). The paper
#: does not say how they were chosen.
PAPER_CONSTANT_FEED_MM_MIN = {"paper_step": 40.0 / 11.797, "paper_taper": 40.0 / 15.914}


#: The overload ceiling of a cut, a multiple of its torque limit: 1.5, as in turning. The
#: end mill breaks at 4x the reference torque (``MillingParams.breakage_torque_Nmm``), the
#: limit's own margin; a torque 1.5x the limit spends a third of that margin at once and
#: loads the spindle past its rating, where a spindle-load monitor (the overload reaction
#: of an adaptive feed control) stops the program.
OVERLOAD_RATIO = 1.5


@dataclass(frozen=True)
class MillingScenario:
    """One end-milling cut: workpiece, spindle speed, torque limit and the hidden process truth.

    Parameters
    ----------
    name : str
    profile : DepthProfile
        Radial depth of cut along the workpiece; its length is the cut's length.
    spindle_scale : float
        Spindle speed as a multiple of the nominal ``MillingParams.spindle_rpm`` (0.25 to 4).
    torque_limit_scale : float
        Process torque limit (what the tool may take) as a multiple of the nominal
        ``MillingParams.torque_limit_Nmm``
        (0.25 to 4).
    torque_coefficient_scale : float
        True Ks (power law) or Kt (average force) as a multiple of the nominal (0.5 to 2):
        the material, tool or wear differ from what the controller was designed for.
    feed_exponent_scale : float
        True feed exponent m as a multiple of the nominal (0.5 to 2; power law only).
    noise_scale : float
        Multiple of the nominal sensor noise (0 to 10).
    wear_per_100mm : float
        Tool wear within the cut: the torque coefficient grows by this share per 100 mm
        (``MillingParams.wear_per_100mm``; 0 to 10, 0 a sharp tool).
    actuation : Actuation or None
        The CNC's actuation for this cut (``machining_envs.core.actuation``); None (default):
        the env's ``actuation`` option decides.
    overload_ratio : float
        The overload ceiling, a multiple of the torque limit (1 to 10, default
        ``OVERLOAD_RATIO``): an episode whose torque passes it does not count, however
        short the excursion (``machining_envs.core.score``).
    """

    name: str
    profile: DepthProfile
    spindle_scale: float = ranged(0.25, 4.0, default=1.0)
    torque_limit_scale: float = ranged(0.25, 4.0, default=1.0)
    torque_coefficient_scale: float = ranged(0.5, 2.0, default=1.0)
    feed_exponent_scale: float = ranged(0.5, 2.0, default=1.0)
    noise_scale: float = ranged(0.0, 10.0, default=1.0)
    wear_per_100mm: float = ranged(0.0, 10.0, default=0.0)
    actuation: Actuation | None = None
    overload_ratio: float = OVERLOAD_RATIO

    def __post_init__(self) -> None:
        check_overload_ratio(self.overload_ratio)
        check_instance("profile", self.profile, DepthProfile)
        check_ranged_fields(self)
        check_instance("actuation", self.actuation, Actuation, optional=True)

    def spindle_rpm(self, nominal: MillingParams) -> float:
        """Spindle speed of this cut, rpm (``ValueError`` outside ``SPINDLE_RPM_RANGE``)."""
        rpm = float(nominal.spindle_rpm * self.spindle_scale)
        lo, hi = SPINDLE_RPM_RANGE
        if not lo <= rpm <= hi:
            raise ValueError(
                f"spindle_scale {self.spindle_scale} gives {rpm:g} rpm, outside the "
                f"spindle_rpm range [{lo}, {hi}]"
            )
        return rpm

    def torque_limit_Nmm(self, nominal: MillingParams) -> float:
        """Process torque limit of this cut, N·mm."""
        return float(nominal.torque_limit_Nmm * self.torque_limit_scale)

    def true_params(self, nominal: MillingParams) -> MillingParams:
        """The plant parameters this cut really has (hidden from controllers)."""
        return nominal.replace(
            torque_coefficient_kgfmm=nominal.torque_coefficient_kgfmm
            * self.torque_coefficient_scale,
            tangential_coefficient_N_mm2=nominal.tangential_coefficient_N_mm2
            * self.torque_coefficient_scale,
            feed_exponent=nominal.feed_exponent * self.feed_exponent_scale,
            noise_std_Nmm=nominal.noise_std_Nmm * self.noise_scale,
            wear_per_100mm=self.wear_per_100mm,
        )


def paper_step_profile() -> DepthProfile:
    """Park & Yoon's step workpiece (Fig. 4a): 1, 2, 3 mm over three thirds of 40 mm."""
    return DepthProfile.steps(
        PAPER_STEP_DEPTHS_MM, PAPER_LENGTH_MM / len(PAPER_STEP_DEPTHS_MM), name="step 1-2-3 mm"
    )


def paper_taper_profile() -> DepthProfile:
    """Park & Yoon's taper workpiece (Fig. 4b): 0 to 3 mm linearly over 40 mm."""
    lo, hi = PAPER_TAPER_DEPTHS_MM
    return DepthProfile.taper(lo, hi, PAPER_LENGTH_MM, name="taper 0-3 mm")


class CutArea:
    """Area under a radial-depth profile from 0 to ``x`` (clipped to the workpiece), mm².

    Times the axial depth it is the volume removed when the tool has reached ``x``. Exact
    for the piecewise-linear profile (trapezoids between its edges); the areas up to each
    edge are summed once (``cumulative``), so a call costs one bisection
    (:func:`cut_area_at`, which the envs' compiled step calls too).
    """

    def __init__(self, profile: DepthProfile):
        self.edges, self.d0, self.slope = edges, d0, slope = profile.segment_table()
        acc = [0.0]
        for i in range(len(d0)):
            w = edges[i + 1] - edges[i]
            acc.append(acc[-1] + w * (d0[i] + 0.5 * slope[i] * w))
        self.cumulative = acc
        self._arrays = None

    @property
    def total(self) -> float:
        return self.cumulative[-1]

    def __call__(self, x_mm: float) -> float:
        if self._arrays is None:
            rows = (np.array([v]) for v in (self.edges, self.d0, self.slope, self.cumulative))
            self._arrays = (*rows, 0, len(self.d0))
        return cut_area_at(float(x_mm), *self._arrays)


@numba.njit(cache=True)
def cut_area_at(x, edges, d0, slope, cumulative, k, nseg):
    """Area (mm²) from 0 to ``x`` under the profile in row ``k`` of the arrays (``nseg``
    segments: ``edges[k, : nseg + 1]``, start depths ``d0[k]``, slopes ``slope[k]``;
    ``cumulative[k, i]`` the area up to edge ``i``), clipped to the workpiece. ``x`` must
    not be NaN."""
    if x <= 0.0:
        return 0.0
    if x >= edges[k, nseg]:
        return cumulative[k, nseg]
    i = bisect_right(edges, k, nseg + 1, x) - 1
    w = x - edges[k, i]
    return cumulative[k, i] + w * (d0[k, i] + 0.5 * slope[k, i] * w)


def cut_area_mm2(profile: DepthProfile, x_mm: float) -> float:
    """Area under the radial-depth profile from 0 to ``x_mm``, mm² (see :class:`CutArea`)."""
    return CutArea(profile)(float(x_mm))


def _fixed(name: str, profile: Callable[[], DepthProfile]):
    def make(rng: np.random.Generator) -> MillingScenario:
        return MillingScenario(name, profile())

    return make


class _SplitRanges(NamedTuple):
    """A split's ranges (the ends of each uniform draw)."""

    #: Radial depth of the workpiece's segments, mm.
    depth: tuple[float, float]
    #: Number of segments.
    segments: tuple[int, int]
    #: Spindle speed as a multiple of the nominal (drawn log-uniform).
    spindle: tuple[float, float]
    #: Torque limit as a multiple of the nominal reference torque (drawn log-uniform).
    ref: tuple[float, float]
    #: Spreads of Ks and of m: each drawn uniform within ``1 -+ spread``.
    truth: tuple[float, float]


class _SplitFactory(SplitCuts):
    """The factory of a split's scenarios: ``factory(rng)`` draws one from the env's
    generator. The workpiece, then uniform in ``[low, high)`` each in order: the log
    spindle and limit scales, Ks, m, the noise scale and (with wear) the wear rate;
    :class:`~machining_envs.core.workpieces.SplitCuts` draws them. :meth:`draw_lanes` and
    :meth:`build_lane` give a vector env's lanes the same objects ``factory(rng)`` gives."""

    def __init__(
        self,
        name: str,
        ranges: _SplitRanges,
        wear: tuple[float, float] | None = None,
        actuation: Actuation | None = None,
    ) -> None:
        depth, segments, spindle, ref, (ks, m) = ranges
        lows = [float(np.log(spindle[0])), float(np.log(ref[0])), 1.0 - ks, 1.0 - m, 0.5]
        highs = [float(np.log(spindle[1])), float(np.log(ref[1])), 1.0 + ks, 1.0 + m, 2.0]
        super().__init__(name, depth, segments, (5.0, 12.0), lows, highs, wear)
        #: The log spindle and limit scales' ranges, as arrays (``draw_lanes``'s users).
        self.log_lows, self.log_spans = np.array(self.lows[:2]), np.array(self.spans[:2])
        self.actuation = actuation
        # Every drawn field lies between these two scenarios' (checked here, once): the
        # factory builds its scenarios without checking them again.
        prof = DepthProfile.steps((depth[0],), 1.0)
        self.extremes = tuple(
            MillingScenario(
                name,
                prof,
                spindle[end],
                ref[end],
                1.0 + (2 * end - 1) * ks,
                1.0 + (2 * end - 1) * m,
                2.0 if end else 0.5,
                wear[end] if wear is not None else 0.0,
                actuation=actuation,
            )
            for end in (0, 1)
        )

    def __call__(self, env_rng: np.random.Generator) -> MillingScenario:
        _, prof, v = self.drawn(env_rng)
        return self._scenario(prof, v)

    def draw_lanes(self, table, lanes: np.ndarray) -> tuple:
        """The numbers of :meth:`__call__` for every lane in ``lanes`` in one compiled call
        (:meth:`lanes_drawn`): ``(segments, segment counts, uniforms)``; :meth:`build_lane`
        turns a lane's into its scenario."""
        _, segments, counts, v = self.lanes_drawn(table, lanes)
        return segments, counts, v

    def build_lane(self, segments: np.ndarray, counts: np.ndarray, v: np.ndarray, i: int):
        """The scenario of lane ``i`` of the lanes' numbers from :meth:`draw_lanes` (their
        segments, segment counts and uniforms)."""
        return self._scenario(self.lane_profile(segments, counts, i), v[i].tolist())

    def _scenario(self, profile: DepthProfile, v: list[float]) -> MillingScenario:
        u = self.in_ranges(v)
        return drawn_instance(
            MillingScenario,
            {
                "name": self.name,
                "profile": profile,
                "spindle_scale": float(np.exp(u[0])),
                "torque_limit_scale": float(np.exp(u[1])),
                "torque_coefficient_scale": u[2],
                "feed_exponent_scale": u[3],
                "noise_scale": u[4],
                "wear_per_100mm": u[5] if self.wear is not None else 0.0,
                "actuation": self.actuation,
            },
        )


#: The ranges of the training distribution, which ``validation`` shares.
#:
#: The nominal point is Park & Yoon's (docs/PLANTS.md, ``MillingParams``): 400 rpm, the
#: 3600 N·mm reference torque, Ks = 118 kgf·mm and m = 0.3999 from their regression, radial
#: depths 1-3 mm on the paper's workpieces. The spread around it is chosen, not identified,
#: to cover what a user of one machining centre meets: a spindle speed picked for another
#: tool or material (two thirds to 1.6x the nominal), a tougher or softer work material or
#: a worn or fresh tool (Ks within +-30 %), and cuts a little deeper than the
#: paper's 3 mm (to 3.5 mm). A learned policy holds only over the speeds and loads it
#: trained on, and the classical agents are tuned on these ranges too, so they are as wide
#: as the operating points the benchmark is checked at (policies trained on 0.8-1.25x the
#: speed lost minutes per cut at 1.5x; docs/performance.md). The feed exponent m keeps its
#: +-20 %: the feed at the limit goes as (limit / (Ks d^l))^(1/m), so a smaller m stretches
#: the slowest cuts most: at +-30 % one training cut in twenty would need more than the
#: 1200 s episode for its physical floor alone (at +-20 %, one in eighty).
_TRAINING_RANGES = _SplitRanges(
    depth=(0.5, 3.5), segments=(2, 5), spindle=(0.67, 1.6), ref=(0.8, 1.25), truth=(0.3, 0.2)
)

#: The benchmark's ranges, which ``test``, ``wear`` and ``shopfloor`` draw from: the
#: published benchmark's distribution (depth 0.5-3 mm, spindle and limit 0.8-1.25x, Ks and m
#: within +-20 %), inside the training ranges. They stay as published so that the
#: benchmark's tables compare across versions; what lies beyond them is checked on ``ood``.
_BENCHMARK_RANGES = _SplitRanges(
    depth=(0.5, 3.0), segments=(2, 5), spindle=(0.8, 1.25), ref=(0.8, 1.25), truth=(0.2, 0.2)
)

#: The ``ood`` ranges: strictly wider than the training ranges in every field (depth to
#: 4 mm, up to 6 segments, spindle 0.6-1.8x, limit 0.7-1.4x, Ks within +-40 %, m within
#: +-25 %), so every ``ood`` cut may lie beyond what was trained and tuned on.
_OOD_RANGES = _SplitRanges(
    depth=(0.4, 4.0), segments=(2, 6), spindle=(0.6, 1.8), ref=(0.7, 1.4), truth=(0.4, 0.25)
)

#: name -> factory drawing a scenario from the env's generator.
#:
#: - ``paper_step``, ``paper_taper``: Park & Yoon's workpieces (Fig. 4) at the nominal
#:   400 rpm and torque limit, exact nominal process.
#: - ``train``, ``validation``: 2-5 random plateaus and tapers of 0.5-3.5 mm radial depth,
#:   5-12 mm each; spindle 0.67-1.6x nominal, torque limit 0.8-1.25x, Ks within +-30 %, m
#:   within +-20 %, noise 0.5-2x (``_TRAINING_RANGES``).
#: - ``test``: the benchmark's published ranges (``_BENCHMARK_RANGES``), inside the
#:   training ranges: depth 0.5-3 mm, spindle and limit 0.8-1.25x, Ks and m within +-20 %.
#: - ``ood``: wider, 0.4-4 mm, 2-6 segments, spindle 0.6-1.8x, limit 0.7-1.4x, Ks and m
#:   within +-40 % and +-25 % (``_OOD_RANGES``).
#: - ``wear``: the benchmark's ranges with a tool that dulls along the cut: the torque
#:   coefficient grows by 50-150 % per 100 mm (up to +90 % at the end of the longest, 60 mm,
#:   workpiece). Chosen, not identified: end mills wear faster per length than the turning
#:   insert (each tooth cuts a share of the time, hot, interrupted), and a controller tuned
#:   on a sharp tool must meet a clearly duller one within one workpiece.
#: - ``shopfloor``: the benchmark's ranges on a real CNC: the feed override in 1 % steps,
#:   rate- and acceleration-limited, two periods of interpolator delay
#:   (``machining_envs.core.actuation.SHOPFLOOR_ACTUATION``, as in Turning-v0). No spindle
#:   power limit: at the papers' 400 rpm even the tool's breakage torque (15 N m) asks for
#:   about 1 kW at 1.6x the speed, far below a machining centre's spindle (5-15 kW), so
#:   a limit could not bind.
MILLING_SCENARIOS: dict[str, Callable[[np.random.Generator], MillingScenario]] = {
    "paper_step": _fixed("paper_step", paper_step_profile),
    "paper_taper": _fixed("paper_taper", paper_taper_profile),
    **{split: _SplitFactory(split, _TRAINING_RANGES) for split in ("train", "validation")},
    "test": _SplitFactory("test", _BENCHMARK_RANGES),
    "ood": _SplitFactory("ood", _OOD_RANGES),
    "wear": _SplitFactory("wear", _BENCHMARK_RANGES, wear=(0.5, 1.5)),
    "shopfloor": _SplitFactory("shopfloor", _BENCHMARK_RANGES, actuation=SHOPFLOOR_ACTUATION),
}


def milling_scenario(spec, rng: np.random.Generator) -> MillingScenario:
    """Resolve a scenario name or object; unknown names raise ``ValueError``."""
    return resolve_scenario(spec, rng, MillingScenario, MILLING_SCENARIOS)


def machining_time_bound(
    scenario: MillingScenario, truth: MillingParams, spindle_rpm: float
) -> float:
    r"""The physical floor of the cut's machining time, s: the time to mill the whole
    workpiece with the torque exactly at the limit everywhere, within the feed drive's top
    speed.

    With the true torque law ``T = c(d) f_t^e`` (``MillingParams.torque_gain``,
    ``c(d) = c_1 d^l``: the power law of eq. 8, or the average-force model with ``l = e = 1``),
    the limit ``L``, ``N`` teeth at ``n`` rpm, the feed per tooth at the limit is
    ``f_t* = (L / c(d))^(1/e)`` and the feed velocity ``v = min(V_max, f_t* N n / 60)``
    (eq. 6); the floor is ``\int dx / v(x)`` over the workpiece
    (``DepthProfile.traverse_time_s``). The torque lags the feed (eq. 10) and the drive
    needs time to accelerate, so no controller that keeps the limit cuts faster; the 2 %
    of steps over the limit an episode may take could beat it by about that much.
    """
    e = truth.torque_feed_exponent
    l_exp = truth.depth_exponent if truth.force_model == "power_law" else 1.0
    c = bound_coefficient(
        float(truth.torque_gain(1.0)),
        float(e),
        float(scenario.torque_limit_Nmm(truth)),
        float(truth.n_teeth),
        float(spindle_rpm),
    )
    # With wear, c (1 + w x) in f_t*: the integrand gains (1 + w x)^(1/e).
    return scenario.profile.worn_traverse_time_s(
        c, l_exp / e, truth.max_feed_velocity_mm_s, truth.wear_per_100mm / 100.0, 1.0 / e
    )


@numba.njit(cache=True)
def bound_coefficient(c1, e, limit, n_teeth, spindle_rpm):
    """``c`` of :func:`machining_time_bound`'s integrand ``c d(x)^(l / e)`` (s/mm): the
    inverse of the feed velocity at the limit ``L`` on a depth of 1 mm,
    ``60 / (N n) (c_1 / L)^(1/e)`` (``c_1`` the torque law's gain at 1 mm)."""
    return 60.0 / (n_teeth * spindle_rpm) * (c1 / limit) ** (1.0 / e)
