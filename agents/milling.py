r"""End-milling controllers of Park & Yoon (1986): integral torque control, fixed or adaptive.

All three are built from the env's nominal parameters only (``from_env``) and read only the
observation: the measured torque, the torque limit and the spindle speed. Torques are handled
in sensor counts, ``Tc = Ke T`` (eq. 9), the units of the paper's gains.

- :class:`FixedGainIntegral`: eq. (1)-(4), ``U = Kc W``, ``W(i) = W(i-1) + Ts E(i)``.
- :class:`IntegralACC`: the same law with ``Kc`` set on line by the Koren-Masory
  variable-gain estimator, eq. (12)-(19).
- :class:`MillingConstantFeed`: no torque feedback; one programmed feed (the "without AC"
  rows of Table 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agents.base import (
    SETPOINT,
    CommandIO,
    ProcessController,
    Setting,
    check_positive,
    tunable,
    unwrap_as,
)
from machining_envs.core.actions import ActionMap
from machining_envs.milling.env import EndMillingEnv
from machining_envs.milling.plant import SPINDLE_RPM_RANGE, MillingParams
from machining_envs.milling.scenarios import PAPER_CONSTANT_FEED_MM_MIN

__all__ = ["MillingIO", "FixedGainIntegral", "IntegralACC", "MillingConstantFeed"]

_I = EndMillingEnv.OBS_INDEX
#: The smallest observed torque limit, as a share of the nominal, that the controllers'
#: model-based values use; below it (a broken reading) they use the nominal limit.
MIN_LIMIT_SHARE = 1e-6


@dataclass(frozen=True)
class MillingIO(CommandIO):
    """What a milling controller knows of the machine: its nominal calibration constants.

    Converts the normalised observation to sensor counts (the units of the paper's gains)
    and commands in counts back to actions.
    """

    sensor_gain: float
    """Ke, counts per N·mm (eq. 9)."""
    torque_scale_Nmm: float
    """N·mm per unit of the limit observation (the nominal torque limit)."""
    command_max: float
    """Largest command, counts; action -1 is U = 0, +1 is U = command_max."""
    sample_time_s: float
    params: MillingParams
    """The nominal plant, for model-based initial values."""
    command_map: ActionMap | None = None
    """The env's action map (its ``command_map``); None: affine over [0, command_max]."""

    @classmethod
    def from_env(cls, env) -> MillingIO:
        base = unwrap_as(env, EndMillingEnv, "a milling controller")
        p = base.params
        return cls(
            p.sensor_gain, p.torque_limit_Nmm, p.command_max, p.sample_time_s, p, base.command_map
        )

    def torque_counts(
        self, obs: np.ndarray, setpoint: float = 1.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """Measured torque Tc and the set point Tr = ``setpoint`` x the limit, in counts, from
        a batch of observations (the torques are observed as multiples of the limit)."""
        lim = self.sensor_gain * self.torque_scale_Nmm * obs[:, _I["limit"]]
        return lim * obs[:, _I["measured"]], lim * setpoint

    def spindle_rpm(self, obs: np.ndarray) -> np.ndarray:
        return np.clip(1000.0 * obs[:, _I["spindle"]], *SPINDLE_RPM_RANGE)

    def limit_Nmm(self, obs: np.ndarray) -> np.ndarray:
        """The torque limit, N·mm, from a batch of observations; the nominal where none is
        usable (0, below it, or under ``MIN_LIMIT_SHARE`` of the nominal, where the
        model's gain, which grows as the torque's power ``1 - 1/e``, would overflow)."""
        lim = self.torque_scale_Nmm * obs[:, _I["limit"]]
        return np.where(lim > MIN_LIMIT_SHARE * self.torque_scale_Nmm, lim, self.torque_scale_Nmm)


class _MillingController(ProcessController):
    """What the end-milling controllers share: the observation they read and what they are
    designed from."""

    obs_dim = 7
    obs_index = _I
    io_type = MillingIO


class FixedGainIntegral(_MillingController):
    r"""Integral torque controller of Park & Yoon (1986), eq. (1)-(4), with a fixed gain.

    .. math:: E(i) = T_r - T_c(i),\quad W(i) = W(i-1) + T_s E(i),\quad U(i) = K_c W(i)

    ``U`` is clipped to the command range; when it is, ``W`` is reset to ``U / Kc`` (the
    paper's own ``W = U / Kc``), which is also the anti-windup. Because the process gain
    ``Tc / U`` grows with the radial depth, a ``Kc`` that is well damped on a shallow cut
    rings or goes unstable on a deep one (Fig. 5).

    Parameters
    ----------
    io : MillingIO
    kc : float
        Controller gain Kc, counts of command per (count of torque x s) (paper: 0.2).
    setpoint : float
        Torque regulated at, as a share of the observed limit (paper: 1.0), in (0, 1.5].
    """

    state_size = 1  # [W]
    #: The settings after ``io``: default, accepted range, search range (``TUNABLE``).
    SETTINGS = {"kc": Setting(0.2, hi=1e6, search=(0.02, 2.0, True)), "setpoint": SETPOINT}

    def _setup(self):
        self.name = f"fixed integral Kc={self.kc:.3g}"

    def _act(self, obs, state):
        tc, tr = self.io.torque_counts(obs, self.setpoint)
        w = state[:, 0] + self.io.sample_time_s * (tr - tc)
        u = np.clip(self.kc * w, 0.0, self.io.command_max)
        state[:, 0] = u / self.kc
        return self.io.action(u)


class IntegralACC(_MillingController):
    r"""Integral ACC with the Koren-Masory variable-gain estimator (Park & Yoon eq. 12-19).

    Every sample, with ``U`` the command that was held while ``Tc`` was produced:

    .. math::

        E_m &= T_c - U K_m, & K_m &\leftarrow K_m + C_1 E_m \quad \text{(eq. 14-15)} \\
        E_c &= T_s K - K_c K_m, & K_c &\leftarrow K_c + C_2 E_c \quad \text{(eq. 18-19)}

    then the integral law of :class:`FixedGainIntegral` with the new ``Kc``. ``Km``
    tracks the process gain ``Kp = Tc / U`` without a division (eq. 12-13) and ``Kc``
    keeps the open-loop gain ``Kc Km / Ts`` at the designed ``K`` (eq. 16-17), so the loop
    does not stiffen as the radial depth grows. (The paper writes eq. 14 with ``U(i)``, the
    command computed at sample ``i``; the command that produced ``Tc(i)`` is the causal
    reading, and the two agree in steady state.)

    Design, from the nominal plant only: ``K`` defaults to the gain at which the paper's
    ``Kc = 0.2`` is already the adapted value at ``design_depth_mm`` (1 mm, the first step
    of the paper's workpiece): ``K = 0.2 Km / Ts`` with ``Km`` the nominal ``Tc / U`` there
    at the reference torque. The discrete loop gain is then ``m K Ts^2 = 0.43`` at every
    depth, a gain margin of 3.5. Each episode starts from ``Km`` = the nominal process
    gain at ``design_depth_mm``, the observed spindle speed and set point, and ``Kc`` at
    its matching value ``Ts K / Km``.

    Guards against the estimator's "overflow" the paper warns about (§4): the gains are
    held while the measured torque is below ``min_torque_fraction`` of the set point or no
    feed is commanded (cutting air gives ``Tc = 0``, which would drive ``Km`` to 0 and
    ``Kc`` without bound), and while the command is held at the top of its range
    (anti-windup: the estimator is frozen while the feed saturates); ``Km`` is kept above 0.1 % of its initial value and ``Kc``
    within 0.1 % to 1000 times its initial value.

    Parameters
    ----------
    io : MillingIO
    k : float or None
        Designed open-loop gain K (eq. 16), 1/s; ``None`` for the default design above.
    c1, c2 : float
        Estimator gains C1, C2 (paper: 0.001 both).
    kc_design : float
        The Kc that K is designed around (paper: 0.2).
    design_depth_mm : float
        Radial depth at which ``kc_design`` is the adapted gain.
    min_torque_fraction : float
        Below this share of the set point the estimator is held.
    setpoint : float
        Torque regulated at, as a share of the observed limit (paper: 1.0), in (0, 1.5].
    """

    state_size = 6  # [W, Km, Kc, U held, Km at start, Kc at start]
    #: The settings after ``io``: default, accepted range, search range (``TUNABLE``).
    SETTINGS = {
        "k": Setting(None),
        "c1": Setting(1e-3, hi=10.0, search=(1e-4, 1e-2, True)),
        "c2": Setting(1e-3, hi=10.0),
        "kc_design": Setting(0.2, hi=1e6, search=(0.02, 1.0, True)),
        "design_depth_mm": Setting(1.0, hi=100.0),
        "min_torque_fraction": Setting(0.2, hi=1.0),
        "setpoint": SETPOINT,
    }
    #: Free parameters and their search ranges, in the order tuning draws them.
    TUNABLE = tunable(SETTINGS, "kc_design", "c1", "setpoint")

    def _setup(self):
        if self.k is None:  # the default design
            km = float(self.io.params.process_gain(self.design_depth_mm))
            self.k = check_positive("k", self.kc_design * km / self.io.sample_time_s, 1e9)
        self.name = f"integral ACC K={self.k:.3g}"

    @classmethod
    def from_env(
        cls,
        env,
        k: float | None = None,
        kc_design: float = 0.2,
        c1: float = 1e-3,
        setpoint: float = 1.0,
        **kwargs,
    ) -> IntegralACC:
        return cls(
            MillingIO.from_env(env), k, c1=c1, kc_design=kc_design, setpoint=setpoint, **kwargs
        )

    def nominal_process_gain(self, spindle_rpm: np.ndarray, torque_Nmm: np.ndarray):
        """Nominal ``Tc / U`` at ``design_depth_mm`` for these speeds and set-point torques."""
        return self.io.params.process_gain(self.design_depth_mm, torque_Nmm, spindle_rpm)

    def initial_state(self, n, obs):
        st = np.zeros((n, self.state_size))
        torque = self.io.limit_Nmm(obs) * self.setpoint
        km = self.nominal_process_gain(self.io.spindle_rpm(obs), torque)
        st[:, 1] = st[:, 4] = km
        st[:, 2] = st[:, 5] = self.io.sample_time_s * self.k / km
        return st

    def _act(self, obs, state):
        ts = self.io.sample_time_s
        tc, tr = self.io.torque_counts(obs, self.setpoint)
        w, km, kc, u_held = state[:, 0], state[:, 1], state[:, 2], state[:, 3]
        km0, kc0 = state[:, 4], state[:, 5]
        # Held while the command is at either end of its range (anti-windup: a clipped
        # command says nothing new about the process gain), or while cutting air.
        adapt = (
            (tc >= self.min_torque_fraction * tr) & (u_held > 0.0) & (u_held < self.io.command_max)
        )
        km_new = np.maximum(km + self.c1 * (tc - u_held * km), 1e-3 * km0)  # eq. 14-15
        kc_new = np.clip(kc + self.c2 * (ts * self.k - kc * km), 1e-3 * kc0, 1e3 * kc0)  # 18-19
        km = np.where(adapt, km_new, km)
        kc = np.where(adapt, kc_new, kc)
        w = w + ts * (tr - tc)  # eq. 1, 3
        u = np.clip(kc * w, 0.0, self.io.command_max)  # eq. 2-4
        state[:, 0] = u / kc
        state[:, 1] = km
        state[:, 2] = kc
        state[:, 3] = u
        return self.io.action(u)


class MillingConstantFeed(_MillingController):
    """Baseline without AC: one programmed feed velocity for the whole cut.

    By default the feed is chosen, as a process planner would, so that the nominal torque
    law gives ``setpoint`` x the observed torque limit at the deepest cut expected
    (``design_depth_mm``) at the nominal spindle speed; shallower parts are then cut below
    the limit, wasting time. :meth:`paper` gives the feeds of Table 1's "without AC" rows.
    The command is ``U = Vf / Kn`` with the nominal servo gain (eq. 5), at most the largest.
    """

    state_size = 0
    #: The settings after ``io``: default, accepted range, search range (``TUNABLE``).
    SETTINGS = {
        "feed_mm_per_min": Setting(None, hi=1e5),
        "design_depth_mm": Setting(3.0, hi=100.0, search=(0.5, 4.0, False)),
        "setpoint": SETPOINT,
    }

    def _setup(self):
        io = self.io
        if self.feed_mm_per_min is None:
            self.command = None
            self.name = f"constant feed, designed for {self.design_depth_mm:.2g} mm"
            return
        self.command = self.feed_mm_per_min / 60.0 / io.params.servo_gain
        if self.command > io.command_max:
            raise ValueError(
                f"feed_mm_per_min must be at most {60.0 * io.params.max_feed_velocity_mm_s:g} "
                f"(the servo's top feed), got {self.feed_mm_per_min!r}"
            )
        self.name = f"constant feed {self.feed_mm_per_min:.3g} mm/min"

    @classmethod
    def paper(cls, env, workpiece: str) -> MillingConstantFeed:
        """The constant feed of Table 1's "without AC" row for ``"paper_step"`` or
        ``"paper_taper"`` (3.39 and 2.51 mm/min)."""
        if workpiece not in PAPER_CONSTANT_FEED_MM_MIN:
            raise ValueError(
                f"workpiece must be one of {sorted(PAPER_CONSTANT_FEED_MM_MIN)}, got {workpiece!r}"
            )
        return cls(MillingIO.from_env(env), PAPER_CONSTANT_FEED_MM_MIN[workpiece])

    def _act(self, obs, state):
        if self.command is not None:
            return self.io.action(np.full(obs.shape[0], self.command))
        p = self.io.params
        ft = p.feed_per_tooth_for_torque(
            self.setpoint * self.io.limit_Nmm(obs), self.design_depth_mm
        )
        feed_mm_per_min = 60.0 * p.feed_velocity_for_feed(ft)
        command = np.minimum(feed_mm_per_min / 60.0 / p.servo_gain, self.io.command_max)
        return self.io.action(command)
