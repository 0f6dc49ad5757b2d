"""The spindle drive's power signal as a load sensor (an env option, off by default).

A production CNC has no dynamometer: what every machine measures is the power its spindle
drive delivers, and that is what industrial adaptive feed controls regulate (Heidenhain's
AFC, software option 45 of the TNC controls, regulates the feed override on the spindle
power in percent of the spindle's rated power). :class:`PowerSensor` holds the settings of
that signal and :class:`PowerSensorLanes` computes it for N lanes at once, so that the
single env and every lane of the vector env do the same arithmetic. With the option on,
Turning-v0 and EndMilling-v0 show it in the observation's load channels:

- observation 0 and the history (4-6): the drive's power reading / ``power_scale_W``;
- observation 1: the power limit / ``power_scale_W``, either the shop's ``limit_W`` or, by
  default, the reading the drive would show in steady state at the scenario's process limit
  (the force or torque limit times the cutting speed, plus the idle losses).

The reading, for a true cutting power ``P_c`` (the process's ``info["cutting_power_W"]``
in turning, torque times angular speed in milling) at spindle speed ``n``:

1. **idle losses**: the drive delivers ``P_c + P_0 + k_n n`` (friction, fan and iron
   losses grow about linearly with the speed; the linear no-load law of spindle-power
   models such as Li & Kara, 2011, *An empirical model for predicting energy consumption of
   manufacturing processes: a case of turning process*, Proc. IMechE B 225);
2. **low-pass filter**: the drive smooths its active-power value with a first-order lag of
   time constant ``time_constant_s`` (drives smooth their power display this way, e.g.
   SINAMICS's smoothed active power r0032); the lag is integrated exactly for a power that
   varies linearly between two control samples;
3. **sample time**: the control reads the value every ``sample_time_s`` (a whole number of
   control periods) and holds it in between;
4. **quantisation**: the value is read in steps of ``quantum_W`` (a load display in tenths
   of a percent of the rated power, or a fixed-point bus word).

The defaults are chosen, not measured: of the order of a 2.2 kW lathe spindle (the
``shopfloor`` lathe's): ``P_0 = 150 W``, ``k_n = 0.1 W/rpm``, ``time_constant_s = 0.1``,
``sample_time_s = 0.1`` (every control period), ``quantum_W = 5``.

**Filter error.** For a drive power whose rate of change stays within ``R`` W/s the lag's
reading trails it by at most ``R * time_constant_s`` once the start has decayed (and by
``exp(-t / time_constant_s)`` of the initial difference before), plus half a quantum:
:meth:`PowerSensor.error_bound_W`. The tests recover the cutting power from the simulated
reading within it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from machining_envs.core.checks import check_range, resolve_settings

__all__ = ["PowerSensor", "PowerSensorLanes", "resolve_power_sensor", "POWER_INFO_KEYS"]

#: The info keys the option adds: the reading the controller saw and the limit it was shown.
POWER_INFO_KEYS = ("spindle_power_measured_W", "power_limit_W")


@dataclass(frozen=True)
class PowerSensor:
    """Settings of the spindle drive's power signal (see the module docstring)."""

    idle_W: float = 150.0
    """Speed-independent idle losses ``P_0``, W, in [0, 1e5]."""
    idle_W_per_rpm: float = 0.1
    """Idle losses per spindle rpm ``k_n``, W/rpm, in [0, 100]."""
    time_constant_s: float = 0.1
    """Time constant of the drive's first-order low-pass filter, s, in [0, 10] (0: none)."""
    sample_time_s: float | None = None
    """How often the control reads the value, s: a whole number of control periods, at
    most 100 of them (None: every control period)."""
    quantum_W: float = 5.0
    """Resolution of the reading, W, in [0, 1e4] (0: continuous)."""
    power_scale_W: float = 1000.0
    """Watts per unit of the power observations, in (0, 1e6]."""
    limit_W: float | None = None
    """The power limit the shop sets on the reading, W, in (0, 1e7] (None: the reading at
    the scenario's force or torque limit)."""

    def __post_init__(self) -> None:
        check_range("idle_W", self.idle_W, 0.0, 1e5)
        check_range("idle_W_per_rpm", self.idle_W_per_rpm, 0.0, 100.0)
        check_range("time_constant_s", self.time_constant_s, 0.0, 10.0)
        if self.sample_time_s is not None:
            check_range("sample_time_s", self.sample_time_s, 0.0, 1e3, lo_open=True)
        check_range("quantum_W", self.quantum_W, 0.0, 1e4)
        check_range("power_scale_W", self.power_scale_W, 0.0, 1e6, lo_open=True)
        if self.limit_W is not None:
            check_range("limit_W", self.limit_W, 0.0, 1e7, lo_open=True)

    def idle_power_W(self, spindle_rpm):
        """The drive's power with the tool in air at ``spindle_rpm``, W."""
        return self.idle_W + self.idle_W_per_rpm * np.asarray(spindle_rpm, dtype=np.float64)

    def error_bound_W(
        self, max_rate_W_per_s: float, initial_error_W: float = 0.0, t_s: float = math.inf
    ) -> float:
        """The largest difference between the reading and the drive power at time ``t_s``
        after the start, for a drive power changing by at most ``max_rate_W_per_s`` and an
        initial difference ``initial_error_W`` (see the module docstring)."""
        tau = self.time_constant_s
        decay = 0.0 if tau == 0.0 else math.exp(-t_s / tau) * abs(initial_error_W)
        return max_rate_W_per_s * tau + decay + self.quantum_W / 2.0


def resolve_power_sensor(power_sensor) -> PowerSensor | None:
    """``None`` / ``False`` (off), ``True`` (the defaults), a dict of :class:`PowerSensor`
    fields, or a ``PowerSensor``."""
    if power_sensor is None or power_sensor is False:
        return None
    if power_sensor is True:
        return PowerSensor()
    return resolve_settings("power_sensor", power_sensor, PowerSensor)


class PowerSensorLanes:
    """The power signal of N lanes: the filter's state, the held reading and its history.

    Parameters
    ----------
    sensor : PowerSensor
    n : int
        Lanes.
    control_period_s : float
        The env's control period (the time between two calls of :meth:`step`).
    history : int
        Past readings the observation shows (its entries ``4 ..``).
    """

    def __init__(self, sensor: PowerSensor, n: int, control_period_s: float, history: int = 3):
        self.sensor = sensor
        ts = float(control_period_s)
        self.ts = ts
        every = sensor.sample_time_s
        m = 1 if every is None else every / ts
        if every is not None and (abs(m - round(m)) > 1e-6 or not 1 <= round(m) <= 100):
            raise ValueError(
                f"power_sensor: sample_time_s must be a whole number (1 to 100) of the env's "
                f"control period {ts:g} s, got {every!r}"
            )
        self.every = int(round(m))
        tau = sensor.time_constant_s
        self.a = math.exp(-ts / tau) if tau > 0 else 0.0
        # y' = (u - y) / tau with u linear over the period: y1 = a y0 + u1 - a u0 - c (u1 - u0)
        self.c = (tau / ts) * (1.0 - self.a) if tau > 0 else 0.0
        self.y = np.zeros(n)  # the filter's output, W
        self.u = np.zeros(n)  # the drive power at the last sample, W
        self.reading = np.zeros((n, 1 + history))  # now, one, two, ... reads ago (held), W
        self.limit = np.zeros(n)  # the limit shown, W
        self.count = np.zeros(n, dtype=np.int64)  # control periods since the last read

    def _quantise(self, y: np.ndarray) -> np.ndarray:
        q = self.sensor.quantum_W
        return np.round(y / q) * q if q > 0 else y

    def _limit(self, limit_cut_W: np.ndarray, rpm: np.ndarray) -> np.ndarray:
        s = self.sensor
        if s.limit_W is not None:
            return np.full(np.shape(rpm), float(s.limit_W))
        return limit_cut_W + s.idle_power_W(rpm)

    def start(self, lanes, obs: np.ndarray, cutting_W, rpm, limit_cut_W) -> None:
        """Lanes ``lanes`` start an episode: the drive has been running at their first
        drive power (steady filter); their observations ``obs[lanes]`` show it.
        ``cutting_W``, ``rpm`` and ``limit_cut_W`` are every lane's (n,) arrays."""
        lanes = np.asarray(lanes, dtype=np.int64).reshape(-1)
        u = self._drive(cutting_W, rpm)[lanes]
        self.u[lanes] = u
        self.y[lanes] = u
        self.reading[lanes] = self._quantise(u)[:, None]
        self.count[lanes] = 0
        self.limit[lanes] = self._limit(
            np.asarray(limit_cut_W, dtype=np.float64), np.asarray(rpm, dtype=np.float64)
        )[lanes]
        self._write(obs, lanes)

    def update(self, obs: np.ndarray, lanes, cutting_W, rpm, limit_cut_W) -> None:
        """:meth:`start` for ``lanes`` that start an episode, or (``lanes`` None) a
        :meth:`step` of every lane: what the envs call after their own start or step."""
        if lanes is None:
            self.step(obs, cutting_W, rpm, limit_cut_W)
        else:
            self.start(lanes, obs, cutting_W, rpm, limit_cut_W)

    def step(self, obs: np.ndarray, cutting_W, rpm, limit_cut_W) -> None:
        """Every lane advances one control period to the drive power of this sample; the
        observations ``obs`` (n, obs_dim) show the readings."""
        u = self._drive(cutting_W, rpm)
        self.y = self.a * self.y + u - self.a * self.u - self.c * (u - self.u)
        self.u = u
        self.count += 1
        read = self.count >= self.every
        self.count[read] = 0
        r = self.reading
        r[:, 1:] = r[:, :-1].copy()
        r[:, 0] = np.where(read, self._quantise(self.y), r[:, 0])
        self.limit = self._limit(
            np.asarray(limit_cut_W, dtype=np.float64), np.asarray(rpm, dtype=np.float64)
        )
        self._write(obs, slice(None))

    def _drive(self, cutting_W, rpm) -> np.ndarray:
        """The drive power, W: the cutting power (never below 0; NaN is 0) plus the idle
        losses."""
        p = np.nan_to_num(np.asarray(cutting_W, dtype=np.float64), nan=0.0, posinf=0.0)
        rpm = np.nan_to_num(np.asarray(rpm, dtype=np.float64), nan=0.0, posinf=0.0)
        return np.maximum(p, 0.0) + self.sensor.idle_power_W(rpm)

    def _write(self, obs: np.ndarray, lanes) -> None:
        scale = self.sensor.power_scale_W
        r = np.clip(self.reading[lanes] / scale, -1.0, 10.0)
        obs[lanes, 0] = r[:, 0]
        obs[lanes, 1] = np.clip(self.limit[lanes] / scale, 0.0, 10.0)
        h = min(r.shape[1] - 1, obs.shape[1] - 4)
        obs[lanes, 4 : 4 + h] = r[:, 1 : 1 + h]

    def lane_info(self, k: int) -> dict:
        """The keys :data:`POWER_INFO_KEYS` of lane ``k``."""
        return {
            "spindle_power_measured_W": float(self.reading[k, 0]),
            "power_limit_W": float(self.limit[k]),
        }

    def info_arrays(self) -> dict:
        """The keys :data:`POWER_INFO_KEYS` of every lane (new arrays)."""
        return {
            "spindle_power_measured_W": self.reading[:, 0].copy(),
            "power_limit_W": self.limit.copy(),
        }
