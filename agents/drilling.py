"""Micro-drilling baselines: no control (constant voltage or feed) and PD on the torque error.

Every drilling controller is built with ``from_env(env)`` from the env's nominal parameters
(:class:`DrillingIO`) and reads only the observation: the measured torque and spindle
frequency, the reference, the drill's position and the previous command.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.base import Agent, unwrap
from machining_envs.envs.micro_drilling import MicroDrillingEnv
from machining_envs.plants.drilling import DrillingParams

__all__ = ["DrillingIO", "NoControl", "PD"]

_I = MicroDrillingEnv.OBS_INDEX
_OBS_DIM = 12


def _positive(name: str, value, hi: float = 1e9) -> float:
    if not (
        isinstance(value, (int, float))
        and not isinstance(value, bool)
        and math.isfinite(value)
        and 0 < value <= hi
    ):
        raise ValueError(f"{name} must be in (0, {hi:g}], got {value!r}")
    return float(value)


def _in_range(name: str, value, lo: float, hi: float) -> float:
    if not (
        isinstance(value, (int, float))
        and not isinstance(value, bool)
        and math.isfinite(value)
        and lo <= value <= hi
    ):
        raise ValueError(f"{name} must be in [{lo:g}, {hi:g}], got {value!r}")
    return float(value)


@dataclass(frozen=True)
class DrillingIO:
    """What a drilling controller knows of the machine: its nominal constants and the maps.

    Converts the normalised observation to physical units and commands back to actions.
    """

    params: DrillingParams
    """The nominal plant (what the controller is designed from)."""
    control: str
    """``"voltage"`` or ``"feed"``: what the action commands."""
    command_min: float
    command_max: float
    speed_scale_hz: float
    length_scale_mm: float

    @classmethod
    def from_env(cls, env) -> DrillingIO:
        base = unwrap(env)
        if not isinstance(base, MicroDrillingEnv):
            raise TypeError(
                f"a drilling controller needs a MicroDrillingEnv, got {type(base).__name__}"
            )
        m = base.command_map
        return cls(
            base.params,
            base.control,
            m.command_min,
            m.command_max,
            base.SPEED_SCALE_HZ,
            base.LENGTH_SCALE_MM,
        )

    def require(self, control: str, who: str) -> None:
        if self.control != control:
            raise ValueError(f"{who} needs the env's control={control!r}, got {self.control!r}")

    @property
    def sample_time_s(self) -> float:
        return self.params.sample_time_s

    def torque(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Measured torque and reference, N·mm."""
        s = self.params.torque_scale_Nmm
        return s * obs[:, _I["measured"]], s * obs[:, _I["reference"]]

    def speed_hz(self, obs: np.ndarray) -> np.ndarray:
        """Measured spindle frequency, Hz."""
        return self.speed_scale_hz * obs[:, _I["spindle"]]

    def lengths_mm(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Drill point position, hole depth and target depth, mm."""
        s = self.length_scale_mm
        return s * obs[:, _I["position"]], s * obs[:, _I["depth"]], s * obs[:, _I["target"]]

    def diameter_mm(self, obs: np.ndarray) -> np.ndarray:
        """Drill diameter, mm."""
        return obs[:, _I["diameter"]].astype(np.float64)

    def previous_command(self, obs: np.ndarray) -> np.ndarray:
        """The command applied over the last sample (V or mm/s)."""
        a = obs[:, _I["prev_action"]]
        return self.command_min + 0.5 * (a + 1.0) * (self.command_max - self.command_min)

    def action(self, command: np.ndarray) -> np.ndarray:
        """Actions (n, 1) for commands (n,)."""
        span = self.command_max - self.command_min
        return (2.0 * (command - self.command_min) / span - 1.0)[:, None]


class NoControl(Agent):
    """The paper's uncontrolled run: the nominal voltage (545 Hz) and the nominal feed, held.

    With ``control="voltage"`` it holds ``voltage`` (default ``nominal_voltage``); with
    ``control="feed"`` it holds the nominal feed velocity (the voltage is then the env's
    nominal one): the same cut.
    """

    state_size = 0
    obs_dim = _OBS_DIM

    def __init__(self, io: DrillingIO, voltage: float | None = None):
        self.io = io
        p = io.params
        if io.control == "voltage":
            u = p.nominal_voltage if voltage is None else voltage
            self.command = _in_range("voltage", u, 0.0, p.voltage_max)
        else:
            if voltage is not None:
                raise ValueError("voltage applies to control='voltage' only")
            self.command = p.feed_velocity_mm_s
        self.name = "no control"

    @classmethod
    def from_env(cls, env, voltage: float | None = None) -> NoControl:
        return cls(DrillingIO.from_env(env), voltage)

    def _act(self, obs, state):
        return self.io.action(np.full(obs.shape[0], self.command))


class PD(Agent):
    r"""PD control of the torque by the valve voltage (the paper's Fig. 15).

    .. math::

        u_k = u_0 + K_p \left(e_k + T_d \frac{e^f_k - e^f_{k-1}}{T_s}\right),
        \qquad e_k = T_{m,k} - T_r, \qquad K_p = \frac{L\, n\, u_0}{T_r}

    clipped to ``[min_voltage, voltage_max]``. A torque above the reference opens the valve
    and speeds the spindle up, which thins the chip per revolution (eq. 20); ``e^f`` is the
    error through a first-order filter of time constant ``Td / N`` (the usual limit on the
    derivative's noise gain). The proportional gain is scaled to the drill: ``L`` is the loop
    gain at the nominal point, since ``dT/du = -T n^{-1} / u_0`` there (torque ``k4/omega``,
    unloaded speed ``~ u^{1/n}``). The paper gives no gains: ``L = 3`` puts the loop's
    crossover at about 12 rad/s, the bandwidth ``lambda`` of the sliding-mode design, so the
    two are compared at equal speed of response; there the linearised loop (valve, loaded
    spindle, sensor, half a sample of delay) has about 96 degrees of phase margin and a gain
    margin of 5.5 (``tests/test_drilling_agents.py``). A PD has no integral action: it
    leaves ``1/(1+L)``, a quarter, of a slow torque rise as steady error.

    ``min_voltage`` (default: the nominal voltage) makes it a speed-up-only regulator, as
    in the paper's runs, where the spindle speeds up from 545 Hz as the chips raise the
    torque (Fig. 16): slowing the spindle below the planned speed would only thicken the
    chip.

    Parameters
    ----------
    io : DrillingIO
    loop_gain : float
        L, dimensionless (see above).
    derivative_time_s : float
        Td, s.
    derivative_filter : float
        N, the derivative's high-frequency gain limit.
    min_voltage : float or None
        Lowest voltage commanded, V (default nominal).
    """

    state_size = 2  # [filtered error e^f_{k-1} (N·mm), started (0/1)]
    obs_dim = _OBS_DIM

    def __init__(
        self,
        io: DrillingIO,
        loop_gain: float = 3.0,
        derivative_time_s: float = 0.02,
        derivative_filter: float = 5.0,
        min_voltage: float | None = None,
    ):
        io.require("voltage", "PD")
        self.io = io
        p = io.params
        self.loop_gain = _positive("loop_gain", loop_gain, 1e3)
        self.derivative_time_s = _in_range("derivative_time_s", derivative_time_s, 0.0, 10.0)
        self.derivative_filter = _positive("derivative_filter", derivative_filter, 1e3)
        lo = p.nominal_voltage if min_voltage is None else min_voltage
        self.min_voltage = _in_range("min_voltage", lo, 0.0, p.voltage_max)
        self.u0 = p.nominal_voltage
        ts = p.sample_time_s
        tf = self.derivative_time_s / self.derivative_filter
        self._alpha = 1.0 - math.exp(-ts / tf) if tf > 0 else 1.0
        self.name = f"PD L={loop_gain:g}"

    @classmethod
    def from_env(cls, env, **kwargs) -> PD:
        return cls(DrillingIO.from_env(env), **kwargs)

    def initial_state(self, n, obs):
        st = np.zeros((n, self.state_size))
        return st

    def _act(self, obs, state):
        io = self.io
        p = io.params
        tm, tr = io.torque(obs)
        tr = np.maximum(tr, 1e-9)
        e = tm - tr
        first = state[:, 1] == 0.0
        ef_prev = np.where(first, e, state[:, 0])
        ef = ef_prev + self._alpha * (e - ef_prev)
        kp = self.loop_gain * p.spindle_friction_exponent * self.u0 / tr
        de = (ef - ef_prev) / p.sample_time_s
        u = self.u0 + kp * (e + self.derivative_time_s * de)
        u = np.clip(u, self.min_voltage, p.voltage_max)
        state[:, 0] = ef
        state[:, 1] = 1.0
        return io.action(u)
