"""Turning controllers of Noh, Kim & Kim (1992): the fixed-gain PI (eq. 12-13), the
variable-gain (adaptive) PI after Masory & Koren (eq. 15-16) and the constant-feed baseline.

All are designed from the env's nominal parameters only (``from_env``), and read only the
observation: the measured force, the force limit and the spindle speed. Each regulates at
its ``setpoint``, a share of the observed limit (1.0, the paper's choice, by default), and
declares its free parameters in ``TUNABLE`` for ``agents.bench.tune``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from agents.base import Agent, check_positive, unwrap_as
from machining_envs.core.checks import PY_NUMBER_TYPES
from machining_envs.core.kernels import read_only
from machining_envs.turning.env import TurningEnv
from machining_envs.turning.plant import SPINDLE_RPM_RANGE, TurningParams

__all__ = ["FixedGainPI", "ConstantFeed", "TurningIO", "VariableGainPI"]

_I = TurningEnv.OBS_INDEX


#: The turning controllers' settings are Python numbers, and (unlike the other processes')
#: a bool passes as 0 or 1; kept so that no setting accepted before is refused.
_positive = functools.partial(check_positive, types=PY_NUMBER_TYPES)


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
        p = unwrap_as(env, TurningEnv, "a turning controller").params
        return cls(p.sensor_gain, p.force_scale_N, p.command_max, p.sample_time_s, p)

    def force_counts(self, obs: np.ndarray, setpoint: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Measured force and the set point (``setpoint`` x the limit) in counts, from a
        batch of observations."""
        k = self.sensor_gain * self.force_scale_N
        return k * obs[:, _I["measured"]], k * obs[:, _I["limit"]] * setpoint

    def limit_N(self, obs: np.ndarray) -> np.ndarray:
        """The force limit, N, from a batch of observations."""
        return self.force_scale_N * obs[:, _I["limit"]]

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
    setpoint : float
        Force regulated at, as a share of the observed limit (paper: 1.0), in (0, 1.5].
    """

    state_size = 2  # [U_{k-1} (counts), E_{k-1} (counts)]
    obs_dim = 7
    obs_index = _I
    #: Free parameters and their search ranges (low, high, log scale) for tuning.
    TUNABLE = {
        "kh": (0.002, 0.1, True),
        "kgh": (1.05, 5.0, True),
        "setpoint": (0.5, 1.0, False),
    }

    def __init__(self, io: TurningIO, kh: float = 0.02, kgh: float = 1.9, setpoint: float = 1.0):
        self.io = io
        self.kh = _positive("kh", kh)
        self.kgh = _positive("kgh", kgh, 100.0)
        self.setpoint = _positive("setpoint", setpoint, 1.5)
        self.name = f"fixed PI Kh={kh:.3g}"

    @classmethod
    def from_env(
        cls, env, kh: float = 0.02, kgh: float = 1.9, setpoint: float = 1.0
    ) -> FixedGainPI:
        return cls(TurningIO.from_env(env), kh, kgh, setpoint)

    def _act(self, obs, state):
        fm, fr = self.io.force_counts(obs, self.setpoint)
        e = fr - fm
        u = np.clip(state[:, 0] + self.kh * (self.kgh * e - state[:, 1]), 0.0, self.io.command_max)
        state[:, 0] = u
        state[:, 1] = e
        return self.io.action(u)


class ConstantFeed(Agent):
    """Industrial baseline: one feed per revolution for the whole cut, no force feedback.

    The feed is chosen, as a process planner would, so that the nominal force law gives
    ``setpoint`` x the force limit at the deepest cut expected (``design_depth_mm``):
    ``f = (setpoint L / (Kf a_design))^(1/p)`` (eq. 8), the limit ``L`` read from the
    observation. Shallower parts of the workpiece are then cut below the limit, wasting
    time; deeper ones pass it. The command follows the spindle speed so that the feed per
    revolution stays constant: ``U = f n / (60 Ks Km)``. Give ``feed_mm_per_rev`` to fix
    the feed instead.
    """

    state_size = 0
    obs_dim = 7
    obs_index = _I
    #: Free parameters and their search ranges (low, high, log scale) for tuning.
    TUNABLE = {"design_depth_mm": (0.5, 6.0, False), "setpoint": (0.5, 1.0, False)}

    def __init__(
        self,
        io: TurningIO,
        feed_mm_per_rev: float | None = None,
        design_depth_mm: float = 3.0,
        setpoint: float = 1.0,
    ):
        self.io = io
        self.design_depth_mm = _positive("design_depth_mm", design_depth_mm, 10.0)
        self.setpoint = _positive("setpoint", setpoint, 1.5)
        if feed_mm_per_rev is not None:
            self.feed_mm_per_rev = _positive("feed_mm_per_rev", feed_mm_per_rev, 10.0)
            self.name = f"constant feed {feed_mm_per_rev:.3f} mm/rev"
        else:
            self.feed_mm_per_rev = None
            self.name = f"constant feed, designed for {design_depth_mm:.2g} mm"

    @classmethod
    def from_env(
        cls,
        env,
        feed_mm_per_rev: float | None = None,
        design_depth_mm: float = 3.0,
        setpoint: float = 1.0,
    ) -> ConstantFeed:
        return cls(TurningIO.from_env(env), feed_mm_per_rev, design_depth_mm, setpoint)

    def _act(self, obs, state):
        p = self.io.params
        feed = self.feed_mm_per_rev
        if feed is None:
            feed = p.feed_for_force(self.setpoint * self.io.limit_N(obs), self.design_depth_mm)
        u = feed * self.io.spindle_rpm(obs) / (60.0 * p.servo_gain * p.gear_ratio)
        return self.io.action(np.clip(u, 0.0, self.io.command_max))


@functools.lru_cache(maxsize=512)
def _unit_plant(params: TurningParams, spindle_rpm: float) -> np.ndarray:
    """``[b1, b2, b3, a1, a2, a3]`` of the unit-gain discrete plant of eq. (14) at this speed
    (read-only: cached)."""
    numd, dend = params.discrete_open_loop(spindle_rpm)
    numd = np.pad(numd, (0, 4 - numd.size))
    dend = np.pad(dend, (0, 4 - dend.size))
    return read_only(np.concatenate([numd[1:4], dend[1:4]]))


class VariableGainPI(Agent):
    r"""PI controller whose gain holds the open-loop gain ``K = Kh Kp`` constant, eq. (15)-(16).

    .. math:: K_h = K / \hat K_p, \qquad \hat K_p = F_c / \hat U

    The paper estimates ``Kp = Fc / U``, which holds in steady state (eq. 16). Here ``U`` is
    replaced by ``U_hat``, the command passed through the paper's own unit-gain plant model
    (eq. 11 discretised as eq. 14 at the observed spindle speed): in steady state
    ``U_hat = U`` and the estimate is the paper's; during the start-up ramp and after a step
    it also accounts for the 2-4 samples the force lags the command, which the plain ratio
    does not (there ``Fc / U`` underestimates ``Kp`` several times over, ``Kh`` comes out
    too large and the first overshoot can break the tool at low spindle speed).
    The PI law is that of :class:`~agents.turning.FixedGainPI` with ``Kh`` recomputed every
    sample.

    Start-up guard: while ``U_hat`` is below ``min_command_fraction`` of the command range or
    the force below ``min_force_fraction`` of the set point, the ratio is 0/0-like, so the
    previous estimate is kept; the first comes from the nominal model, eq. (11) at the
    set-point force, the observed spindle speed and ``design_depth_mm``.

    Parameters
    ----------
    io : TurningIO
    k : float
        Designed open-loop gain K (paper: 0.5, inside the stable range 0 < K < 0.807).
    kgh : float
        Kgh = 1 + Kg/Kh (paper: 1.9).
    setpoint : float
        Force regulated at, as a share of the observed limit (paper: 1.0), in (0, 1.5].
    """

    #: Free parameters and their search ranges (low, high, log scale) for tuning.
    TUNABLE = {
        "k": (0.05, 0.8, True),
        "kgh": (1.05, 5.0, True),
        "setpoint": (0.5, 1.0, False),
    }
    # [E_{k-1}, Kp_hat, U_{k-1..k-3}, U_hat_{k-1..k-3}, b1..b3, a1..a3]
    state_size = 14
    obs_dim = 7
    obs_index = _I

    def __init__(
        self,
        io: TurningIO,
        k: float = 0.5,
        kgh: float = 1.9,
        design_depth_mm: float = 2.0,
        min_command_fraction: float = 0.01,
        min_force_fraction: float = 0.05,
        setpoint: float = 1.0,
    ):
        self.io = io
        self.setpoint = _positive("setpoint", setpoint, 1.5)
        self.k = _positive("k", k, 100.0)
        self.kgh = _positive("kgh", kgh, 100.0)
        self.design_depth_mm = _positive("design_depth_mm", design_depth_mm, 10.0)
        self.min_command = (
            _positive("min_command_fraction", min_command_fraction, 1.0) * io.command_max
        )
        self.min_force_fraction = _positive("min_force_fraction", min_force_fraction, 1.0)
        self.name = f"adaptive PI K={k:.3g}"

    @classmethod
    def from_env(
        cls, env, k: float = 0.5, kgh: float = 1.9, setpoint: float = 1.0, **kwargs
    ) -> VariableGainPI:
        return cls(TurningIO.from_env(env), k, kgh, setpoint=setpoint, **kwargs)

    def nominal_process_gain(self, spindle_rpm: np.ndarray, force_N: np.ndarray) -> np.ndarray:
        """Kp of eq. (11) for the nominal plant at the set-point force and the design depth."""
        p = self.io.params
        feed = p.feed_for_force(force_N, self.design_depth_mm)
        return p.process_gain(spindle_rpm, self.design_depth_mm, feed)

    def initial_state(self, n, obs):
        st = np.zeros((n, self.state_size))
        rpm = np.clip(self.io.spindle_rpm(obs), *SPINDLE_RPM_RANGE)
        fr_N = self.io.limit_N(obs) * self.setpoint
        fr_N = np.where(fr_N > 0, fr_N, self.io.force_scale_N)
        st[:, 1] = self.nominal_process_gain(rpm, fr_N)
        for i in range(n):  # the model at each env's spindle speed (cached per speed)
            st[i, 8:14] = _unit_plant(self.io.params, round(float(rpm[i]), 6))
        return st

    def _act(self, obs, state):
        fm, fr = self.io.force_counts(obs, self.setpoint)
        u_hist = state[:, 2:5]
        y_hist = state[:, 5:8]
        y = np.sum(state[:, 8:11] * u_hist, axis=1) - np.sum(state[:, 11:14] * y_hist, axis=1)
        ok = (y >= self.min_command) & (fm >= self.min_force_fraction * fr)
        kp_hat = np.where(ok, fm / np.where(ok, y, 1.0), state[:, 1])
        kh = self.k / kp_hat
        e = fr - fm
        u = np.clip(u_hist[:, 0] + kh * (self.kgh * e - state[:, 0]), 0.0, self.io.command_max)
        state[:, 0] = e
        state[:, 1] = kp_hat
        state[:, 3:5] = u_hist[:, 0:2].copy()
        state[:, 2] = u
        state[:, 6:8] = y_hist[:, 0:2].copy()
        state[:, 5] = y
        return self.io.action(u)
