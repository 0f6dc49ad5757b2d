"""Turning controllers of Noh, Kim & Kim (1992): the fixed-gain PI (eq. 12-13), the
variable-gain (adaptive) PI after Masory & Koren (eq. 15-16) and the constant-feed baseline.

All are designed from the env's nominal parameters only (``from_env``), and read only the
observation: the measured force, the force limit and the spindle speed. Each regulates at
its ``setpoint``, a share of the observed limit (1.0, the paper's choice, by default), and
declares its free parameters in ``TUNABLE`` for ``agents.bench.tune``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from agents.base import SETPOINT, CommandIO, ProcessController, Setting, unwrap_as
from machining_envs.core.checks import PY_NUMBER_TYPES, check_integer, check_range
from machining_envs.turning.env import TurningEnv
from machining_envs.turning.plant import SPINDLE_RPM_RANGE, TurningParams, unit_plant_coefficients

__all__ = [
    "FixedGainPI",
    "ConstantFeed",
    "TurningIO",
    "VariableGainPI",
    "DelayAwarePI",
    "delay_aware_gain",
]

_I = TurningEnv.OBS_INDEX
#: The smallest observed force limit, as a share of the nominal, that the model-based
#: initial values use; below it (a broken reading) they use the nominal limit.
MIN_LIMIT_SHARE = 1e-6


@dataclass(frozen=True)
class TurningIO(CommandIO):
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


class _TurningController(ProcessController):
    """What the turning controllers share: the observation they read and what they are
    designed from."""

    obs_dim = 7
    obs_index = _I
    io_type = TurningIO
    setting_types = PY_NUMBER_TYPES


class FixedGainPI(_TurningController):
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
    #: The settings after ``io``: default, accepted range, search range (``TUNABLE``).
    SETTINGS = {
        "kh": Setting(0.02, search=(0.002, 0.1, True)),
        "kgh": Setting(1.9, hi=100.0, search=(1.05, 5.0, True)),
        "setpoint": SETPOINT,
    }

    def _setup(self):
        self.name = f"fixed PI Kh={self.kh:.3g}"

    def _act(self, obs, state):
        fm, fr = self.io.force_counts(obs, self.setpoint)
        e = fr - fm
        u = np.clip(state[:, 0] + self.kh * (self.kgh * e - state[:, 1]), 0.0, self.io.command_max)
        state[:, 0] = u
        state[:, 1] = e
        return self.io.action(u)


class ConstantFeed(_TurningController):
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
    #: The settings after ``io``: default, accepted range, search range (``TUNABLE``).
    SETTINGS = {
        "feed_mm_per_rev": Setting(None, hi=10.0),
        "design_depth_mm": Setting(3.0, hi=10.0, search=(0.5, 6.0, False)),
        "setpoint": SETPOINT,
    }

    def _setup(self):
        if self.feed_mm_per_rev is not None:
            self.name = f"constant feed {self.feed_mm_per_rev:.3f} mm/rev"
        else:
            self.name = f"constant feed, designed for {self.design_depth_mm:.2g} mm"

    def _act(self, obs, state):
        p = self.io.params
        feed = self.feed_mm_per_rev
        if feed is None:  # (a limit observed below 0 asks for no feed, not a NaN one)
            force_N = np.maximum(self.setpoint * self.io.limit_N(obs), 0.0)
            feed = p.feed_for_force(force_N, self.design_depth_mm)
        u = feed * self.io.spindle_rpm(obs) / (60.0 * p.servo_gain * p.gear_ratio)
        return self.io.action(np.clip(u, 0.0, self.io.command_max))


class VariableGainPI(_TurningController):
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

    #: The settings after ``io``: default, accepted range, search range (``TUNABLE``).
    SETTINGS = {
        "k": Setting(0.5, hi=100.0, search=(0.05, 0.8, True)),
        "kgh": FixedGainPI.SETTINGS["kgh"],
        "design_depth_mm": Setting(2.0, hi=10.0),
        "min_command_fraction": Setting(0.01, hi=1.0),
        "min_force_fraction": Setting(0.05, hi=1.0),
        "setpoint": SETPOINT,
    }
    # [E_{k-1}, Kp_hat, U_{k-1..k-3}, U_hat_{k-1..k-3}, b1..b3, a1..a3]
    state_size = 14

    def _setup(self):
        self.min_command = self.min_command_fraction * self.io.command_max
        self.name = f"adaptive PI K={self.k:.3g}"

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
        # No usable limit (0, below it, or so small that the model's gain, which grows as
        # the force's power 1 - 1/p, overflows): the nominal one.
        usable = fr_N > MIN_LIMIT_SHARE * self.io.force_scale_N
        fr_N = np.where(usable, fr_N, self.io.force_scale_N)
        st[:, 1] = self.nominal_process_gain(rpm, fr_N)
        for i in range(n):  # the model at each env's spindle speed (cached per speed)
            st[i, 8:14] = unit_plant_coefficients(self.io.params, round(float(rpm[i]), 6))
        return st

    def _open_loop_gain(self, state: np.ndarray):
        """The open-loop gain K the law holds (``k``; a subclass may set it per episode)."""
        return self.k

    def _act(self, obs, state):
        fm, fr = self.io.force_counts(obs, self.setpoint)
        u_hist = state[:, 2:5]
        y_hist = state[:, 5:8]
        y = np.sum(state[:, 8:11] * u_hist, axis=1) - np.sum(state[:, 11:14] * y_hist, axis=1)
        ok = (y >= self.min_command) & (fm >= self.min_force_fraction * fr) & (fr > 0.0)
        kp_new = fm / np.where(ok, y, 1.0)
        gain = self._open_loop_gain(state)
        # An estimate of 0 (a force of 0 at a limit of 0) or one so small that K / Kp_hat
        # overflows is no estimate: the previous one is kept.
        with np.errstate(divide="ignore", over="ignore"):
            ok &= (kp_new > 0.0) & np.isfinite(gain / np.where(ok, kp_new, 1.0))
        kp_hat = np.where(ok, kp_new, state[:, 1])
        kh = gain / kp_hat
        e = fr - fm
        u = np.clip(u_hist[:, 0] + kh * (self.kgh * e - state[:, 0]), 0.0, self.io.command_max)
        state[:, 0] = e
        state[:, 1] = kp_hat
        state[:, 3:5] = u_hist[:, 0:2].copy()
        state[:, 2] = u
        state[:, 6:8] = y_hist[:, 0:2].copy()
        state[:, 5] = y
        return self.io.action(u)


@functools.lru_cache(maxsize=256)
def delay_aware_gain(
    params: TurningParams,
    spindle_rpm: float,
    kgh: float,
    delay_steps: int,
    phase_margin_deg: float,
    k_max: float = 0.8,
) -> float:
    r"""The open-loop gain ``K`` of the adaptive PI that leaves ``phase_margin_deg`` of phase
    margin on a machine that delays the command by ``delay_steps`` periods.

    The adaptive PI holds ``Kh Kp`` at ``K`` (eq. 15), so its loop at any depth is

    .. math:: L(z) = p K \frac{K_{gh} - z^{-1}}{1 - z^{-1}} P_1(z) z^{-d}

    with :math:`P_1` the paper's unit-gain plant at the spindle speed (eq. 14) and ``p`` the
    feed exponent (the force's tangent gain is ``p`` times the secant gain the PI
    estimates). The margin falls as ``K`` grows; the largest ``K`` in ``(0, k_max]`` whose
    margin (python-control's ``stability_margins``) is at least ``phase_margin_deg`` is found
    by bisection. Cached per argument set.
    """
    import control

    numd, dend = params.discrete_open_loop(spindle_rpm)
    ts = params.sample_time_s
    plant = control.tf(np.asarray(numd, float), np.asarray(dend, float), ts)
    pi = control.tf([kgh, -1.0], [1.0, -1.0], ts)
    delay = control.tf([1.0], [1.0] + [0.0] * delay_steps, ts)
    base = params.feed_exponent * pi * plant * delay

    def margin(k: float) -> float:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _, pm, *_ = control.stability_margins(k * base)
        closed = control.poles(control.feedback(k * base, 1))
        if not np.all(np.abs(closed) < 1.0):
            return -math.inf
        return float(pm) if math.isfinite(pm) else math.inf

    if margin(k_max) >= phase_margin_deg:
        return k_max
    lo, hi = 0.0, k_max
    for _ in range(16):  # K to k_max / 2**16 (about 1e-5)
        mid = 0.5 * (lo + hi)
        if mid > 0 and margin(mid) >= phase_margin_deg:
            lo = mid
        else:
            hi = mid
    return max(lo, 1e-4)


class DelayAwarePI(VariableGainPI):
    """The adaptive PI of :class:`VariableGainPI` with its gain derived with the CNC's delay
    in the loop (:func:`delay_aware_gain`).

    On a machine whose control delays the feed command by ``delay_steps`` periods (the
    interpolator delay of ``machining_envs.core.actuation``), the paper's open-loop gain
    (K = 0.5, chosen for a loop without delay) leaves little phase margin. Here ``K`` is
    worked out for each episode's spindle speed as the largest gain that keeps
    ``phase_margin_deg`` of phase margin with the delay in the loop; the rest is the
    adaptive PI. ``agents.eval.margins.loop_margins(agent, point, delay_steps=d)`` reads the
    gain, phase and delay margins of the result at an operating point.

    Parameters
    ----------
    io : TurningIO
    delay_steps : int
        Control periods of command delay designed for, 0 to 50.
    phase_margin_deg : float
        The design's phase margin, degrees, in [10, 89].
    kgh, setpoint, ...
        As for :class:`VariableGainPI`.
    """

    #: The settings after ``io``: the delay and phase margin designed for (checked below)
    #: instead of VariableGainPI's K, the rest as VariableGainPI's.
    SETTINGS = {
        "delay_steps": Setting(2, hi=None),
        "phase_margin_deg": Setting(45.0, hi=None, search=(20.0, 80.0, False)),
        "kgh": VariableGainPI.SETTINGS["kgh"],
        "setpoint": SETPOINT,
        **{k: v for k, v in VariableGainPI.SETTINGS.items() if k not in ("k", "kgh", "setpoint")},
    }

    def _setup(self):
        self.k = VariableGainPI.SETTINGS["k"].default  # (unused: K is designed per episode)
        super()._setup()
        self.delay_steps = check_integer("delay_steps", self.delay_steps, 0, 50)
        self.phase_margin_deg = check_range("phase_margin_deg", self.phase_margin_deg, 10.0, 89.0)
        self.name = f"delay-aware PI PM={self.phase_margin_deg:.0f}°, delay {self.delay_steps}"
        # [adaptive PI's state, K of the episode]
        self.state_size = VariableGainPI.state_size + 1

    @classmethod
    def from_env(cls, env, delay_steps: int | None = None, *args, **kwargs) -> DelayAwarePI:
        """The design for ``env``, with the settings above; ``delay_steps`` by default the
        delay of the env's ``actuation`` option (0 without one)."""
        base = unwrap_as(env, TurningEnv, "a turning controller")
        if delay_steps is None:
            act = getattr(base, "actuation", None)
            delay_steps = 0 if act is None else int(act.delay_steps)
        return cls(TurningIO.from_env(env), delay_steps, *args, **kwargs)

    def gain_at(self, spindle_rpm: float) -> float:
        """The open-loop gain K designed for ``spindle_rpm``."""
        rpm = float(np.clip(spindle_rpm, *SPINDLE_RPM_RANGE))
        return delay_aware_gain(
            self.io.params, round(rpm, 3), self.kgh, self.delay_steps, self.phase_margin_deg
        )

    def initial_state(self, n, obs):
        st = super().initial_state(n, obs)  # state_size wide: the last column is K
        rpm = self.io.spindle_rpm(obs)
        st[:, -1] = [self.gain_at(r) for r in rpm.tolist()]
        return st

    def _open_loop_gain(self, state: np.ndarray) -> np.ndarray:
        return state[:, -1]  # the episode's K, designed at its spindle speed
