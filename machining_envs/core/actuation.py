"""What a real CNC does to a feed command before the drives see it (off by default).

A controller on a shop-floor machine does not write the servo command directly: it sets the
feed override, which the control

- **delays** by its interpolator: the command issued at step ``k`` takes effect at step
  ``k + delay_steps`` (until then the command issued before the episode, 0, holds);
- **quantises**: the override moves in steps of ``quantum`` of the command range (1 % or
  10 % on common controls);
- **rate-limits**: the override changes by at most ``max_rate_per_s`` of the range per
  second, in whole quanta where it is quantised;
- **acceleration-limits**: the override's rate changes by at most ``max_accel_per_s2`` of
  the range per second squared, and the ramp brakes in time to stop on the target (no
  overshoot from the limit itself); in whole quanta where it is quantised.

:class:`Actuation` holds the settings (checked); :class:`ActuationLanes` applies them to N
lanes at once, so the single env and every lane of the vector env do the same arithmetic.
The env's ``info["command"]`` is then the command the drives got. The spindle power limit
is a property of the plant, not of the command path: see
``TurningParams.spindle_power_W``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from machining_envs.core.checks import check_integer, check_range, resolve_settings

__all__ = [
    "Actuation",
    "ActuationLanes",
    "resolve_actuation",
    "configure_lane",
    "SHOPFLOOR_ACTUATION",
]


@dataclass(frozen=True)
class Actuation:
    """CNC actuation settings (shares of the command range; 0 / inf / 0 switch one off)."""

    quantum: float = 0.0
    """Override step as a share of the command range (0: continuous), in [0, 0.5]."""
    max_rate_per_s: float = math.inf
    """Largest change of the command per second, as a share of its range (inf: none)."""
    delay_steps: int = 0
    """Control periods between a command and its effect, 0 to 50."""
    max_accel_per_s2: float = math.inf
    """Largest change of the command's rate per second squared, as a share of its range
    (inf: none)."""

    def __post_init__(self) -> None:
        check_range("quantum", self.quantum, 0.0, 0.5)
        if self.quantum > 0 and abs(1.0 / self.quantum - round(1.0 / self.quantum)) > 1e-9:
            raise ValueError(
                f"quantum must divide the command range (1 / quantum an integer: 0.01, 0.1, "
                f"0.25, ...), got {self.quantum!r}"
            )
        if self.max_rate_per_s != math.inf:  # inf: no rate limit
            check_range("max_rate_per_s", self.max_rate_per_s, 0.0, 1e6, lo_open=True)
        check_integer("delay_steps", self.delay_steps, 0, 50)
        if self.max_accel_per_s2 != math.inf:  # inf: no acceleration limit
            check_range("max_accel_per_s2", self.max_accel_per_s2, 0.0, 1e9, lo_open=True)

    @property
    def active(self) -> bool:
        return (
            self.quantum > 0
            or math.isfinite(self.max_rate_per_s)
            or math.isfinite(self.max_accel_per_s2)
            or self.delay_steps > 0
        )


#: The actuation of the ``shopfloor`` scenarios (Turning-v0, EndMilling-v0): the feed
#: override in 1 % steps, at most 50 % of its range per second and 200 % per second squared
#: (0.25 s from rest to full rate), two control periods (0.2 s at both envs' 10 Hz) of
#: interpolator delay. Chosen, not measured: of the order of a production control's override
#: handling, strict enough that a design for an ideal actuator notices.
SHOPFLOOR_ACTUATION = Actuation(
    quantum=0.01, max_rate_per_s=0.5, delay_steps=2, max_accel_per_s2=2.0
)


#: The feed-override handling of the ``shopfloor`` scenarios of ContouringFeed-v0
#: (``machining_envs.contouring.scenarios``), as shares
#: of the default override range [0, 2]: 1 % steps of the programmed feed, at most 5x the
#: programmed feed per second (0.2 s from rest to it) and 120x per second squared, two
#: decisions (20 ms) of delay. Chosen, not measured: a CNC applies the override through its
#: feed planner, which limits how fast the path speed may change; these limits bind on the
#: paths' corners, where an ideal override would brake within one decision.
SHOPFLOOR_OVERRIDE = Actuation(
    quantum=0.005, max_rate_per_s=2.5, delay_steps=2, max_accel_per_s2=60.0
)


def resolve_actuation(actuation) -> Actuation | None:
    """``None`` (off), a dict of :class:`Actuation` fields, or an ``Actuation``."""
    if actuation is None:
        return None
    actuation = resolve_settings("actuation", actuation, Actuation)
    return actuation if actuation.active else None


def configure_lane(act_lanes, lane: int, scenario_actuation, env_actuation, make):
    """The lanes' actuation once ``lane`` starts an episode: the scenario's own settings win
    over the env's option (None: ideal); ``make()`` builds the :class:`ActuationLanes` the
    first time a lane needs them (until then every command passes unchanged)."""
    act = scenario_actuation if scenario_actuation is not None else env_actuation
    if act is not None and act_lanes is None:
        act_lanes = make()
    if act_lanes is not None:
        act_lanes.configure(lane, act)
    return act_lanes


class ActuationLanes:
    """The actuation state of N lanes: the interpolator's queue and the last applied command.

    Each lane has its own settings (:meth:`configure`; a scenario may bring its own, see the
    ``shopfloor`` scenarios), so the single env and every lane of the vector env run the
    same arithmetic on the same settings.

    Parameters
    ----------
    n : int
        Lanes.
    command_range : float
        Width of the command range (commands run from ``low`` to ``low + command_range``).
    low : float
        Lowest command (applied before the episode's first command arrives).
    sample_time_s : float
        The control period.
    actuation : Actuation or None
        The settings every lane starts with (None: ideal, the command passes unchanged).
    """

    def __init__(
        self,
        n: int,
        command_range: float,
        low: float,
        sample_time_s: float,
        actuation: Actuation | None = None,
    ):
        self.range = float(command_range)
        self.low = float(low)
        self.ts = float(sample_time_s)
        self.q = np.zeros(n)
        self.max_step = np.full(n, math.inf)
        self.max_dstep = np.full(n, math.inf)
        self.delay = np.zeros(n, dtype=np.int64)
        self.queue = np.full((n, 1), self.low)
        self.last = np.full(n, self.low)
        self.rate = np.zeros(n)
        self._lanes = np.arange(n)
        for k in range(n):
            self.configure(k, actuation)

    def configure(self, lane: int, actuation: Actuation | None) -> None:
        """Give ``lane`` the settings ``actuation`` (None: ideal) and reset it."""
        a = actuation if actuation is not None else Actuation()
        q = a.quantum * self.range
        step = a.max_rate_per_s * self.range * self.ts
        # A limit that is a whole number of quanta up to rounding (0.3 / 0.1 s) counts as one.
        if q > 0 and math.isfinite(step):
            if step < q * (1.0 - 1e-9):
                raise ValueError(
                    f"actuation: max_rate_per_s {a.max_rate_per_s:g} moves less than one "
                    f"quantum ({a.quantum:g}) per control period: the command could never change"
                )
            step = math.floor(step / q + 1e-9) * q  # whole quanta: stays on the grid
        dv = a.max_accel_per_s2 * self.range * self.ts**2
        if q > 0 and math.isfinite(dv):
            if dv < q * (1.0 - 1e-9):
                raise ValueError(
                    f"actuation: max_accel_per_s2 {a.max_accel_per_s2:g} changes the rate by "
                    f"less than one quantum ({a.quantum:g}) per control period: the command "
                    "could never move"
                )
            dv = math.floor(dv / q + 1e-9) * q
        self.q[lane] = q
        self.max_step[lane] = step
        #: Largest change of the per-period step between two periods (inf: none).
        self.max_dstep[lane] = dv
        self.delay[lane] = a.delay_steps
        if a.delay_steps + 1 > self.queue.shape[1]:
            grow = a.delay_steps + 1 - self.queue.shape[1]
            self.queue = np.pad(self.queue, ((0, 0), (0, grow)), constant_values=self.low)
        # What apply() needs of the settings, worked out here and not every step.
        self._grid = self.q > 0
        self._safe_q = np.where(self._grid, self.q, 1.0)
        self._limited = np.isfinite(self.max_step) | np.isfinite(self.max_dstep)
        self._acc = np.flatnonzero(np.isfinite(self.max_dstep))
        self._any_grid = bool(self._grid.any())
        self._any_limited = bool(self._limited.any())
        self.reset(lane)

    def reset(self, lane: int) -> None:
        self.queue[lane] = self.low
        self.last[lane] = self.low
        self.rate[lane] = 0.0

    def apply(self, commands: np.ndarray) -> np.ndarray:
        """The commands the drives get this step for the commands ``commands`` (n,) issued."""
        queue = self.queue
        if queue.shape[1] > 1:
            queue[:, 1:] = queue[:, :-1].copy()
        queue[:, 0] = commands
        target = queue[self._lanes, self.delay]
        grid, safe = self._grid, self._safe_q
        if self._any_grid:
            target = np.where(grid, self.low + np.round((target - self.low) / safe) * safe, target)
        if self._any_limited:
            step = target - self.last
            acc = self._acc
            if acc.size:
                # Brake in time: with the step shrinking by at most dv a period, the steps
                # v, v - dv, ..., v - K dv (v = (K + r) dv, 0 <= r < 1) cover
                # (K + 1) dv (K / 2 + r), which must not pass the distance d still to go.
                dv = self.max_dstep[acc]
                x = np.abs(step[acc]) / dv
                kk = np.floor((np.sqrt(1.0 + 8.0 * x) - 1.0) / 2.0)
                v_brake = (kk + np.clip(x / (kk + 1.0) - kk / 2.0, 0.0, 1.0)) * dv
                g, sq = grid[acc], safe[acc]
                v_brake = np.where(g, np.floor(v_brake / sq + 1e-9) * sq, v_brake)
                s = np.sign(step[acc]) * np.minimum(np.abs(step[acc]), v_brake)
                r = self.rate[acc]
                step[acc] = np.clip(s, r - dv, r + dv)
            step = np.clip(step, -self.max_step, self.max_step)
            if self._any_grid:
                step = np.where(grid, np.round(step / safe) * safe, step)  # no rounding dust
            target = np.where(self._limited, self.last + step, target)
        self.rate = target - self.last
        self.last = target
        return target.copy()
