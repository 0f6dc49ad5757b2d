"""Fixed-gain PI force controller and the constant-feed baseline (turning).

Both are designed from the env's nominal parameters only (``from_env``), and read only the
observation: the measured force, the reference and the spindle speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.base import Agent, unwrap
from machining_envs.envs.turning import TurningEnv
from machining_envs.plants.turning import TurningParams

__all__ = ["FixedGainPI", "ConstantFeed", "TurningIO"]

_I = TurningEnv.OBS_INDEX


def _positive(name: str, value: float, hi: float = 1e9) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and 0 < value <= hi):
        raise ValueError(f"{name} must be in (0, {hi:g}], got {value!r}")
    return float(value)


@dataclass(frozen=True)
class TurningIO:
    """What a turning controller knows of the machine: its nominal calibration constants.

    Converts the normalised observation to ADC counts (the units of the paper's gains) and
    servo commands in DAC counts back to actions.
    """

    sensor_gain: float
    """Ke, counts per newton (eq. 10)."""
    force_scale_N: float
    """Newtons per unit of the force observations."""
    command_max: float
    """Largest servo command, counts; action -1 is U = 0, +1 is U = command_max."""
    sample_time_s: float
    params: TurningParams
    """The nominal plant, for model-based initial values."""

    @classmethod
    def from_env(cls, env) -> TurningIO:
        base = unwrap(env)
        if not isinstance(base, TurningEnv):
            raise TypeError(f"a turning controller needs a TurningEnv, got {type(base).__name__}")
        p = base.params
        return cls(p.sensor_gain, p.force_scale_N, p.command_max, p.sample_time_s, p)

    def force_counts(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Measured force and reference in counts, from a batch of observations."""
        k = self.sensor_gain * self.force_scale_N
        return k * obs[:, _I["measured"]], k * obs[:, _I["reference"]]

    def spindle_rpm(self, obs: np.ndarray) -> np.ndarray:
        return 1000.0 * obs[:, _I["spindle"]]

    def action(self, command: np.ndarray) -> np.ndarray:
        """Actions (n, 1) for servo commands (n,) in counts."""
        return (2.0 * command / self.command_max - 1.0)[:, None]


class FixedGainPI(Agent):
    r"""Fixed-gain PI force controller of Noh, Kim & Kim (1992), eq. (12)-(13).

    .. math:: C(z) = K_h + \frac{K_g}{1 - z^{-1}} = \frac{K_h (K_{gh} - z^{-1})}{1 - z^{-1}},
              \qquad K_{gh} = 1 + K_g / K_h

    run in velocity form on the force error in counts, ``E = Ke (Fr - Fm)``:
    ``U_k = U_{k-1} + Kh (Kgh E_k - E_{k-1})``, clipped to the servo's range (the clip is
    also the anti-windup). Sample time Ts = 0.1 s, the env's.

    Parameters
    ----------
    io : TurningIO
    kh : float
        Proportional gain Kh, command counts per force count (paper: 0.006, 0.02, 0.04).
    kgh : float
        Kgh = 1 + Kg/Kh (paper: 1.9, from Ziegler-Nichols then hand tuning).
    """

    state_size = 2  # [U_{k-1} (counts), E_{k-1} (counts)]
    obs_dim = 7

    def __init__(self, io: TurningIO, kh: float = 0.02, kgh: float = 1.9):
        self.io = io
        self.kh = _positive("kh", kh)
        self.kgh = _positive("kgh", kgh, 100.0)
        self.name = f"fixed PI Kh={kh:g}"

    @classmethod
    def from_env(cls, env, kh: float = 0.02, kgh: float = 1.9) -> FixedGainPI:
        return cls(TurningIO.from_env(env), kh, kgh)

    def _act(self, obs, state):
        fm, fr = self.io.force_counts(obs)
        e = fr - fm
        u = np.clip(state[:, 0] + self.kh * (self.kgh * e - state[:, 1]), 0.0, self.io.command_max)
        state[:, 0] = u
        state[:, 1] = e
        return self.io.action(u)


class ConstantFeed(Agent):
    """Industrial baseline: one feed per revolution for the whole cut, no force feedback.

    The feed is chosen, as a process planner would, so that the nominal force law gives the
    reference force at the deepest cut expected (``design_depth_mm``); shallower parts of
    the workpiece are then cut below the reference, wasting time. The command follows the
    spindle speed so that the feed per revolution stays constant: ``U = f n / (60 Ks Km)``.
    """

    state_size = 0
    obs_dim = 7

    def __init__(self, io: TurningIO, feed_mm_per_rev: float):
        self.io = io
        self.feed_mm_per_rev = _positive("feed_mm_per_rev", feed_mm_per_rev, 10.0)
        self.name = f"constant feed {feed_mm_per_rev:.3f} mm/rev"

    @classmethod
    def from_env(
        cls,
        env,
        feed_mm_per_rev: float | None = None,
        design_depth_mm: float = 3.0,
        force_ref_N: float | None = None,
    ) -> ConstantFeed:
        io = TurningIO.from_env(env)
        if feed_mm_per_rev is None:
            fr = force_ref_N if force_ref_N is not None else io.force_scale_N
            feed_mm_per_rev = io.params.feed_for_force(
                fr, _positive("design_depth_mm", design_depth_mm, 10.0)
            )
        return cls(io, feed_mm_per_rev)

    def _act(self, obs, state):
        p = self.io.params
        u = self.feed_mm_per_rev * self.io.spindle_rpm(obs) / (60.0 * p.servo_gain * p.gear_ratio)
        return self.io.action(np.clip(u, 0.0, self.io.command_max))
