"""Constant feed override: the baseline of ``ContouringFeed-v0``.

A process planner's choice: one override for every path, the largest that keeps the contour
error within the tolerance on the training paths. :func:`calibrate_constant_override` finds
it by bisection over rollouts; :data:`BASELINE_OVERRIDE` holds the values it gives for the
env's defaults (regenerate with ``python -m agents.feed``).
"""

from __future__ import annotations

import functools
import math

import gymnasium as gym
import numpy as np

from agents.base import Agent, unwrap
from machining_envs.envs.contouring_feed import DEFAULT_TOLERANCE_MM, ContouringFeedEnv

__all__ = [
    "ConstantOverride",
    "calibrate_constant_override",
    "BASELINE_OVERRIDE",
    "CALIBRATION_SEEDS",
]

#: Training paths the baseline is calibrated on: ``train`` scenarios drawn with these seeds.
CALIBRATION_SEEDS = tuple(range(200))

#: servo -> the largest constant override keeping the default tolerance on every path of
#: ``CALIBRATION_SEEDS`` (default parameters, tolerance and decision interval), rounded down
#: to 0.01. Regenerate: ``python -m agents.feed``.
BASELINE_OVERRIDE = {"pi": 0.08, "hinf": 0.37}


def _max_error(env, scenario, override: float) -> float:
    base = unwrap(env)
    action = np.array([base.command_to_action(override)], dtype=np.float32)
    env.reset(seed=0, options={"scenario": scenario})
    peak = 0.0
    while True:
        _, _, term, trunc, info = env.step(action)
        peak = max(peak, info["peak_contour_error_mm"])
        if peak > base.tolerance_mm or term or trunc:
            return peak


def calibrate_constant_override(
    env_kwargs: dict | None = None,
    seeds=CALIBRATION_SEEDS,
    resolution: float = 0.01,
    verbose: bool = False,
) -> float:
    """Largest override (a multiple of ``resolution``) whose runs keep the env's tolerance
    on the ``train`` paths drawn with ``seeds``.

    Paths are taken in turn: each is run at the best override so far, and bisected below it
    when it breaks the tolerance. A run stops as soon as its contour error passes the
    tolerance, so failing candidates are cheap.
    """
    env = gym.make("machining_envs/ContouringFeed-v0", **(env_kwargs or {}))
    try:
        base = unwrap(env)
        seeds = list(seeds)
        scenarios = []
        for s in seeds:
            base.reset(seed=int(s), options={"scenario": "train"})
            scenarios.append(base.scenario)
        hi = base.override_max
        for k, sc in enumerate(scenarios):
            if _max_error(env, sc, hi) <= base.tolerance_mm:
                continue
            lo_ok, hi_bad = 0.0, hi
            while hi_bad - lo_ok > resolution:
                mid = 0.5 * (lo_ok + hi_bad)
                if _max_error(env, sc, mid) <= base.tolerance_mm:
                    lo_ok = mid
                else:
                    hi_bad = mid
            hi = math.floor(lo_ok / resolution + 1e-9) * resolution
            if verbose:
                print(f"path {k} (seed {seeds[k]}): override <= {hi:.2f}", flush=True)
        return float(hi)
    finally:
        env.close()


@functools.lru_cache(maxsize=16)
def _calibrated(servo: str, tolerance: float, params, decision: float, omax: float) -> float:
    kwargs = {
        "servo": servo,
        "tolerance_mm": tolerance,
        "params": params,
        "decision_interval_s": decision,
        "override_max": omax,
    }
    return calibrate_constant_override(kwargs)


class ConstantOverride(Agent):
    """The same feed override all along every path (no feedback).

    ``from_env`` takes the override from :data:`BASELINE_OVERRIDE` when the env has the
    default parameters, tolerance and decision interval, and calibrates it on the training
    paths otherwise (once per setting and process; a few minutes).
    """

    state_size = 0
    obs_dim = 16

    def __init__(self, override: float, override_max: float):
        if not (isinstance(override, (int, float)) and math.isfinite(override)):
            raise ValueError(f"override must be a finite number, got {override!r}")
        if not 0.0 < override <= override_max:
            raise ValueError(f"override must be in (0, {override_max}], got {override!r}")
        self.override = float(override)
        self.override_max = float(override_max)
        self.name = f"constant override {override:.2f}"

    @classmethod
    def from_env(cls, env, override: float | None = None) -> ConstantOverride:
        base = unwrap(env)
        if not isinstance(base, ContouringFeedEnv):
            raise TypeError(
                f"ConstantOverride needs a ContouringFeedEnv, got {type(base).__name__}"
            )
        if override is None:
            default = (
                base.tolerance_mm == DEFAULT_TOLERANCE_MM[base.servo]
                and base.params == type(base.params)()
                and base.decision_interval_s == 0.01
                and base.override_max == 2.0
            )
            if default and BASELINE_OVERRIDE[base.servo] > 0:
                override = BASELINE_OVERRIDE[base.servo]
            else:
                override = _calibrated(
                    base.servo,
                    base.tolerance_mm,
                    base.params,
                    base.decision_interval_s,
                    base.override_max,
                )
        return cls(override, base.override_max)

    def _act(self, obs, state):
        a = 2.0 * self.override / self.override_max - 1.0
        return np.full((obs.shape[0], 1), a)


if __name__ == "__main__":  # pragma: no cover - regenerates BASELINE_OVERRIDE
    for servo in ("pi", "hinf"):
        print(servo, calibrate_constant_override({"servo": servo}, verbose=True))
