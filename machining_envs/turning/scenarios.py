"""Named scenarios: the papers' experiments, a training distribution, a held-out test set.

A scenario fixes what changes from one cut to the next and what a controller cannot see:
the workpiece's depth profile, the spindle speed, the reference, and the true process
constants (as scale factors on the nominal parameters). Pass a name or a scenario object to
``env.reset(options={"scenario": ...})``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from machining_envs.core.env import resolve_scenario
from machining_envs.core.workpieces import DepthProfile
from machining_envs.turning.plant import SPINDLE_RPM_RANGE, TurningParams, _check

__all__ = [
    "TurningScenario",
    "TURNING_SCENARIOS",
    "turning_scenario",
    "PAPER_STEP_SEGMENT_MM",
]

#: Length of each plateau of the paper's 1 -> 2 -> 3 mm bar, mm. Not given in the paper;
#: 15 mm keeps every plateau longer than the start-up and step transients of all five
#: experiments (3 s at 700 rpm on the 1 mm plateau, 36 s at 245 rpm on the 3 mm one).
PAPER_STEP_SEGMENT_MM = 15.0


@dataclass(frozen=True)
class TurningScenario:
    """One turning cut: workpiece, spindle speed, reference and the hidden process truth.

    Parameters
    ----------
    name : str
    profile : DepthProfile
        Depth of cut along the workpiece; its length is the cut's length.
    spindle_rpm : float
        Spindle speed, rpm, constant over the cut (range ``SPINDLE_RPM_RANGE``).
    force_ref_N : float
        Reference cutting force, N (the paper's 1 kN by default).
    force_coefficient_scale, feed_exponent_scale : float
        True Kf and p as multiples of the nominal ones (0.5 to 2): the tool, material or
        wear differ from what the controller was designed for.
    noise_scale : float
        Multiple of the nominal sensor noise (0 to 10).
    """

    name: str
    profile: DepthProfile
    spindle_rpm: float
    force_ref_N: float = 1000.0
    force_coefficient_scale: float = 1.0
    feed_exponent_scale: float = 1.0
    noise_scale: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.profile, DepthProfile):
            raise ValueError(f"profile must be a DepthProfile, got {type(self.profile).__name__}")
        _check("spindle_rpm", self.spindle_rpm, *SPINDLE_RPM_RANGE)
        _check("force_ref_N", self.force_ref_N, 1.0, 1e5)
        _check("force_coefficient_scale", self.force_coefficient_scale, 0.5, 2.0)
        _check("feed_exponent_scale", self.feed_exponent_scale, 0.5, 2.0)
        _check("noise_scale", self.noise_scale, 0.0, 10.0)

    def true_params(self, nominal: TurningParams) -> TurningParams:
        """The plant parameters this cut really has (hidden from controllers)."""
        return nominal.replace(
            force_coefficient=nominal.force_coefficient * self.force_coefficient_scale,
            feed_exponent=nominal.feed_exponent * self.feed_exponent_scale,
            noise_std_N=nominal.noise_std_N * self.noise_scale,
        )


def _paper(rpm: float) -> Callable[[np.random.Generator], TurningScenario]:
    def make(rng: np.random.Generator) -> TurningScenario:
        prof = DepthProfile.steps((1.0, 2.0, 3.0), PAPER_STEP_SEGMENT_MM, name="step 1-2-3 mm")
        return TurningScenario(f"paper_{rpm:g}", prof, float(rpm))

    return make


def _taper(rng: np.random.Generator) -> TurningScenario:
    prof = DepthProfile.taper(1.0, 3.0, 3 * PAPER_STEP_SEGMENT_MM, name="taper 1-3 mm")
    return TurningScenario("taper_405", prof, 405.0)


def _step_range(rng: np.random.Generator) -> TurningScenario:
    prof = DepthProfile.steps((1.0, 2.0, 3.0), PAPER_STEP_SEGMENT_MM, name="step 1-2-3 mm")
    return TurningScenario("step_range", prof, float(np.exp(rng.uniform(np.log(245), np.log(700)))))


def _random(
    name: str, rpm: tuple[float, float], depth: tuple[float, float], segments: tuple[int, int]
):
    def make(rng: np.random.Generator) -> TurningScenario:
        spindle = float(np.exp(rng.uniform(np.log(rpm[0]), np.log(rpm[1]))))
        prof = DepthProfile.random(rng, depth, segments, (4.0, 12.0), 0.3, name=f"{name} profile")
        kf, p, noise = rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2), rng.uniform(0.5, 2.0)
        return TurningScenario(name, prof, spindle, 1000.0, float(kf), float(p), float(noise))

    return make


#: name -> factory drawing a scenario from the env's generator. ``train``: spindle speed
#: log-uniform over the paper's 245-700 rpm, 2-5 random plateaus and tapers of 0.5-3 mm,
#: Kf and p within +-20 % of nominal, noise 0.5-2x. ``test`` (held out): wider, 200-800 rpm,
#: 0.5-3.5 mm, 2-6 segments, so a policy is judged partly outside what it trained on.
TURNING_SCENARIOS: dict[str, Callable[[np.random.Generator], TurningScenario]] = {
    "paper_245": _paper(245),
    "paper_405": _paper(405),
    "paper_700": _paper(700),
    "taper_405": _taper,
    "step_range": _step_range,
    "train": _random("train", (245.0, 700.0), (0.5, 3.0), (2, 5)),
    "test": _random("test", (200.0, 800.0), (0.5, 3.5), (2, 6)),
}


def turning_scenario(spec, rng: np.random.Generator) -> TurningScenario:
    """Resolve a scenario name or object; unknown names raise ``ValueError``."""
    return resolve_scenario(spec, rng, TurningScenario, TURNING_SCENARIOS)
