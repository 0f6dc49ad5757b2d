"""Named micro-drilling scenarios: the paper's holes and the four splits of the benchmark.

A scenario fixes the drill, the hole, the process torque limit and what a controller
cannot see: the true cutting constant of this drill and material, how strongly chips pack
in the flutes, how irregular that is, and the sensor noise (as scale factors on the
nominal parameters). Pass a name or an object to ``env.reset(options={"scenario": ...})``.

Splits (``machining_envs.core.splits``): ``train``, ``validation`` and ``test`` share one
distribution, each drawing through its own stream; ``ood`` goes beyond it; ``wear`` is
the training distribution with a drill that dulls within the hole (see
``DRILLING_SCENARIOS``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from machining_envs.core.checks import (
    check_overload_ratio,
    check_range,
    check_ranged_fields,
    drawn_instance,
    ranged,
)
from machining_envs.core.env import resolve_scenario
from machining_envs.core.splits import split_stream
from machining_envs.drilling.plant import DIAMETER_RANGE_MM, DrillingParams

__all__ = [
    "DrillingScenario",
    "DRILLING_SCENARIOS",
    "drilling_scenario",
    "PAPER_DIAMETERS_MM",
    "PAPER_ASPECT_RATIO",
]

#: The drill diameters of the paper's experiments, mm (Fig. 18-21).
PAPER_DIAMETERS_MM = (0.5, 0.6, 0.7, 0.8)
#: Hole depth over diameter of the paper's holes: "aspect ratio larger than 10" (abstract).
PAPER_ASPECT_RATIO = 10.0


#: The overload ceiling of a hole, a multiple of its torque limit: 1.5. A micro drill
#: breaks by static torsion at 3.9-6.2x the chip-free torque (``DrillingParams.
#: breakage_coeff_N_per_mm2``), but far lower by fatigue and chip clogging, which load
#: peaks drive; 1.5x the limit is the torque a torque-monitored drilling cycle treats as a
#: clogged hole and retracts from, so a hole that passes it does not count.
OVERLOAD_RATIO = 1.5


@dataclass(frozen=True)
class DrillingScenario:
    """One hole: drill, depth, torque limit and the hidden process truth.

    Parameters
    ----------
    name : str
    diameter_mm : float
        Drill diameter, mm (``DIAMETER_RANGE_MM``); known to the controller.
    aspect_ratio : float
        Hole depth over diameter (1 to 20); the hole is finished at ``aspect_ratio * D``.
    torque_limit_Nmm : float or None
        Process torque limit, N·mm: what the drill may take. ``None``: the nominal chip-free
        torque of this drill at the nominal voltage's 545 Hz and the nominal feed, from the
        nominal parameters (what a process planner would set; the paper's reference),
        times ``torque_limit_scale``.
    cutting_scale : float
        True effective shear stress as a multiple of the nominal (0.5 to 2): drill wear,
        material batch.
    chip_scale : float
        True chip friction ``g0`` as a multiple of the nominal (0 to 5): how badly chips
        pack in this hole.
    fluctuation_scale : float
        Multiple of the nominal chip and cutting fluctuations (0 to 3).
    noise_scale : float
        Multiple of the nominal sensor noises (0 to 10).
    torque_limit_scale : float
        Multiple of the nominal chip-free torque that is the limit when
        ``torque_limit_Nmm`` is None (0.25 to 4).
    wear_per_mm : float
        Drill wear within the hole: the chip-free cutting torque grows by this share per mm
        drilled (``DrillingParams.wear_per_mm``; 0 to 10, 0 a sharp drill).
    overload_ratio : float
        The overload ceiling, a multiple of the torque limit (1 to 10, default
        ``OVERLOAD_RATIO``): a hole whose torque passes it does not count, however short
        the excursion (``machining_envs.core.score``).
    """

    name: str
    diameter_mm: float = ranged(*DIAMETER_RANGE_MM)
    aspect_ratio: float = ranged(1.0, 20.0, default=PAPER_ASPECT_RATIO)
    torque_limit_Nmm: float | None = None
    cutting_scale: float = ranged(0.5, 2.0, default=1.0)
    chip_scale: float = ranged(0.0, 5.0, default=1.0)
    fluctuation_scale: float = ranged(0.0, 3.0, default=1.0)
    noise_scale: float = ranged(0.0, 10.0, default=1.0)
    torque_limit_scale: float = ranged(0.25, 4.0, default=1.0)
    wear_per_mm: float = ranged(0.0, 10.0, default=0.0)
    overload_ratio: float = OVERLOAD_RATIO

    def __post_init__(self) -> None:
        check_overload_ratio(self.overload_ratio)
        check_ranged_fields(self)
        if self.torque_limit_Nmm is not None:
            check_range("torque_limit_Nmm", self.torque_limit_Nmm, 1e-4, 100.0)

    @property
    def target_depth_mm(self) -> float:
        """Depth at which the hole is finished, mm."""
        return self.aspect_ratio * self.diameter_mm

    def limit_Nmm(self, nominal: DrillingParams) -> float:
        """The process torque limit of this hole, N·mm: ``torque_limit_Nmm``, or the
        nominal chip-free torque of the drill (from the nominal parameters) times
        ``torque_limit_scale``."""
        if self.torque_limit_Nmm is not None:
            return float(self.torque_limit_Nmm)
        base = nominal.nominal_torque_Nmm(self.diameter_mm)
        return base if self.torque_limit_scale == 1.0 else base * self.torque_limit_scale

    def true_params(self, nominal: DrillingParams) -> DrillingParams:
        """The plant parameters this hole really has (hidden from controllers)."""
        f = self.fluctuation_scale
        n = self.noise_scale
        return nominal.replace(
            shear_stress_MPa=nominal.shear_stress_MPa * self.cutting_scale,
            chip_friction=nominal.chip_friction * self.chip_scale,
            chip_fluctuation=nominal.chip_fluctuation * f,
            cutting_fluctuation=nominal.cutting_fluctuation * f,
            torque_noise_Nmm=nominal.torque_noise_Nmm * n,
            thrust_noise_N=nominal.thrust_noise_N * n,
            speed_noise_hz=nominal.speed_noise_hz * n,
            wear_per_mm=self.wear_per_mm,
        )


def _paper(d: float) -> Callable[[np.random.Generator], DrillingScenario]:
    def make(rng: np.random.Generator) -> DrillingScenario:
        return DrillingScenario(f"paper_{d:g}", d)

    return make


def _random(
    name: str,
    aspect: tuple[float, float],
    cutting: tuple[float, float],
    chips: tuple[float, float],
    fluct: tuple[float, float],
    noise: tuple[float, float],
    limit: tuple[float, float] = (1.0, 1.0),
    wear: tuple[float, float] | None = None,
):
    # Every drawn field lies between these two scenarios' (checked here, once): make()
    # builds its scenarios without checking them again.
    for end in (0, 1):
        DrillingScenario(
            name,
            0.5 + 0.3 * end,
            aspect[end],
            None,
            cutting[end],
            chips[end],
            fluct[end],
            noise[end],
            torque_limit_scale=limit[end],
            wear_per_mm=wear[end] if wear else 0.0,
        )

    def make(env_rng: np.random.Generator) -> DrillingScenario:
        rng = split_stream(env_rng, name)
        u = rng.random(6).tolist()
        d = 0.5 + 0.3 * u[0]
        ar = aspect[0] + (aspect[1] - aspect[0]) * u[1]
        cs = cutting[0] + (cutting[1] - cutting[0]) * u[2]
        ch = math.exp(math.log(chips[0]) + (math.log(chips[1]) - math.log(chips[0])) * u[3])
        fl = fluct[0] + (fluct[1] - fluct[0]) * u[4]
        ns = noise[0] + (noise[1] - noise[0]) * u[5]
        scale = 1.0 if limit == (1.0, 1.0) else float(rng.uniform(*limit))
        w = float(rng.uniform(*wear)) if wear is not None else 0.0  # drawn last
        return drawn_instance(
            DrillingScenario,
            {
                "name": name,
                "diameter_mm": d,
                "aspect_ratio": ar,
                "torque_limit_Nmm": None,
                "cutting_scale": cs,
                "chip_scale": ch,
                "fluctuation_scale": fl,
                "noise_scale": ns,
                "torque_limit_scale": scale,
                "wear_per_mm": w,
            },
        )

    return make


#: The ranges of the training distribution (aspect ratio, cutting constant, chip friction,
#: fluctuation and noise scales), which ``wear`` shares.
_TRAINING_RANGES = ((6.0, 12.0), (0.85, 1.15), (0.6, 1.6), (0.5, 1.5), (0.5, 2.0))

#: name -> factory drawing a scenario from the env's generator.
#:
#: - ``paper_0.5`` ... ``paper_0.8``: Table 1 (545 Hz, 0.32 mm/s, SS40) with the paper's
#:   drills, aspect ratio 10, nominal chips; only the fluctuations and noise vary by seed.
#: - ``train``, ``validation``, ``test``: diameter uniform 0.5-0.8 mm, aspect ratio 6-12,
#:   cutting constant +-15 %, chip friction 0.6-1.6x (log-uniform), fluctuation 0.5-1.5x,
#:   noise 0.5-2x; the torque limit is the drill's nominal chip-free torque.
#: - ``ood`` (wider): aspect ratio 8-14, cutting constant +-20 %, chip friction 0.5-2x,
#:   fluctuation 0.5-2x, noise 0.5-3x, torque limit 0.8-1.2x the nominal.
#: - ``wear``: the training ranges with a drill that dulls along the hole: the chip-free
#:   torque grows by 3-10 % per mm drilled (+9 % to +96 % at the bottom of the shallowest
#:   and deepest holes). Chosen, not identified: at the top of the range a 0.8 mm drill's
#:   chip-free torque grows by 80 % over a hole of aspect ratio 10, about half of what the
#:   chip friction of a nominal hole adds there (+150 %, Fig. 12), and pecking does not
#:   clear it. A drill this close to the end of its life is what a controller tuned on
#:   sharp drills meets on the shop floor.
DRILLING_SCENARIOS: dict[str, Callable[[np.random.Generator], DrillingScenario]] = {
    **{f"paper_{d:g}": _paper(d) for d in PAPER_DIAMETERS_MM},
    **{split: _random(split, *_TRAINING_RANGES) for split in ("train", "validation", "test")},
    "ood": _random("ood", (8.0, 14.0), (0.8, 1.2), (0.5, 2.0), (0.5, 2.0), (0.5, 3.0), (0.8, 1.2)),
    "wear": _random("wear", *_TRAINING_RANGES, wear=(0.03, 0.10)),
}


def drilling_scenario(spec, rng: np.random.Generator) -> DrillingScenario:
    """Resolve a scenario name or object; unknown names raise ``ValueError``."""
    return resolve_scenario(spec, rng, DrillingScenario, DRILLING_SCENARIOS)
