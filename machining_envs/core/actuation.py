"""What a real CNC does to a feed command before the drives see it (off by default).

A controller on a shop-floor machine does not write the servo command directly: it sets the
feed override, which the control

- **delays** by its interpolator: the command issued at step ``k`` takes effect at step
  ``k + delay_steps`` (until then the command issued before the episode, 0, holds);
- **quantises**: the override moves in steps of ``quantum`` of the command range (1 % or
  10 % on common controls);
- **rate-limits**: the override changes by at most ``max_rate_per_s`` of the range per
  second, in whole quanta where it is quantised.

:class:`Actuation` holds the settings (checked); :class:`ActuationLanes` applies them to N
lanes at once, so the single env and every lane of the vector env do the same arithmetic.
The env's ``info["command"]`` is then the command the drives got. Not modelled: the
override's acceleration limit and the spindle power limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from machining_envs.core.checks import check_integer, check_range

__all__ = ["Actuation", "ActuationLanes", "resolve_actuation"]


@dataclass(frozen=True)
class Actuation:
    """CNC actuation settings (shares of the command range; 0 / inf / 0 switch one off)."""

    quantum: float = 0.0
    """Override step as a share of the command range (0: continuous), in [0, 0.5]."""
    max_rate_per_s: float = math.inf
    """Largest change of the command per second, as a share of its range (inf: none)."""
    delay_steps: int = 0
    """Control periods between a command and its effect, 0 to 50."""

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

    @property
    def active(self) -> bool:
        return self.quantum > 0 or math.isfinite(self.max_rate_per_s) or self.delay_steps > 0


def resolve_actuation(actuation) -> Actuation | None:
    """``None`` (off), a dict of :class:`Actuation` fields, or an ``Actuation``."""
    if actuation is None:
        return None
    if isinstance(actuation, dict):
        import dataclasses

        known = [f.name for f in dataclasses.fields(Actuation)]
        bad = sorted(set(actuation) - set(known))
        if bad:
            raise TypeError(f"actuation: unknown settings {bad}; allowed {known}")
        actuation = Actuation(**actuation)
    if not isinstance(actuation, Actuation):
        raise ValueError(
            f"actuation must be an Actuation, a dict or None, got {type(actuation).__name__}"
        )
    return actuation if actuation.active else None


class ActuationLanes:
    """The actuation state of N lanes: the interpolator's queue and the last applied command.

    Parameters
    ----------
    actuation : Actuation
    n : int
        Lanes.
    command_range : float
        Width of the command range (commands run from ``low`` to ``low + command_range``).
    low : float
        Lowest command (applied before the episode's first command arrives).
    sample_time_s : float
        The control period.
    """

    def __init__(self, actuation: Actuation, n: int, command_range: float, low: float,
                 sample_time_s: float):  # fmt: skip
        self.a = actuation
        self.low = float(low)
        self.q = actuation.quantum * command_range
        step = actuation.max_rate_per_s * command_range * sample_time_s
        if self.q > 0 and math.isfinite(step):
            if step < self.q:
                raise ValueError(
                    f"actuation: max_rate_per_s {actuation.max_rate_per_s:g} moves less than one "
                    f"quantum ({actuation.quantum:g}) per control period: the command could "
                    "never change"
                )
            step = math.floor(step / self.q) * self.q  # whole quanta: stays on the grid
        self.max_step = step
        self.queue = np.full((n, actuation.delay_steps + 1), self.low)
        self.last = np.full(n, self.low)

    def reset(self, lane: int) -> None:
        self.queue[lane] = self.low
        self.last[lane] = self.low

    def apply(self, commands: np.ndarray) -> np.ndarray:
        """The commands the drives get this step for the commands ``commands`` (n,) issued."""
        q = self.queue
        if q.shape[1] > 1:
            q[:, 1:] = q[:, :-1].copy()
        q[:, 0] = commands
        target = q[:, -1].copy()
        if self.q > 0:
            target = self.low + np.round((target - self.low) / self.q) * self.q
        if math.isfinite(self.max_step):
            target = self.last + np.clip(target - self.last, -self.max_step, self.max_step)
        self.last = target
        return target.copy()
