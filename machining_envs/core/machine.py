"""The user's machine, described once in a small YAML file.

A CNC's command path and spindle are what separate the papers' ideal plants from the
machine a controller is deployed on. :func:`load_machine` reads them from a file such as::

    name: my_lathe
    actuation:            # machining_envs.core.actuation.Actuation
      delay_steps: 2      # control periods of interpolator delay
      quantum: 0.01       # override step, share of the range (1 %)
      max_rate_per_s: 0.5
      max_accel_per_s2: 2.0
    spindle_power_W: 2200 # rated spindle power (Turning-v0: the spindle slows above it)
    power_sensor: true    # optional: the drive's power as the load channel
                          # (true, or the fields of machining_envs.core.sensors.PowerSensor)
    feed_override:        # optional: ContouringFeed-v0's override handling (the fields of
      delay_steps: 2      # Actuation, as shares of the override range [0, 2]; default:
      quantum: 0.005      # the actuation above)

and :meth:`Machine.env_kwargs` turns the description into the options of an env
(``gym.make(env_id, **machine.env_kwargs(env_id))``), which ``machining-bench tune
--machine`` and ``train --machine`` pass to every env they make.

**The training side.** Tuning and training run on the ``train`` split's workpieces (checked
on ``validation``) with the machine as described: the training-side distribution of the
actuation is the description itself. The held-out ``shopfloor`` split (its own workpiece
stream, the library's reference shop-floor machine, :data:`SHOPFLOOR_MACHINE`) is never
used for either. :meth:`Machine.spread` gives the variants around the description (delay
one period either side, rate and acceleration limits 0.8x and 1.25x) that a robustness
check may run the tuned or trained agent on.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

from machining_envs.core.actuation import (
    SHOPFLOOR_ACTUATION,
    SHOPFLOOR_OVERRIDE,
    Actuation,
    resolve_actuation,
)
from machining_envs.core.checks import check_range
from machining_envs.core.sensors import PowerSensor, resolve_power_sensor

__all__ = ["Machine", "load_machine", "SHOPFLOOR_MACHINE"]

#: The keys a machine file may hold.
_KEYS = ("name", "actuation", "spindle_power_W", "power_sensor", "feed_override")


@dataclass(frozen=True)
class Machine:
    """A CNC: its command path, its spindle and (optionally) its load signal."""

    name: str = "machine"
    actuation: Actuation | None = None
    """The feed override's delay, quantum, rate and acceleration limits (None: ideal)."""
    spindle_power_W: float | None = None
    """Rated spindle power, W, in (0, 1e7] (None: unlimited). Turning-v0 slows the spindle
    above it; EndMilling-v0 and ContouringFeed-v0 have no spindle-power model."""
    power_sensor: PowerSensor | None = None
    """The drive's power signal as the load channel (Turning-v0, EndMilling-v0)."""
    feed_override: Actuation | None = None
    """ContouringFeed-v0's feed-override handling, as shares of the env's override range
    ``[0, override_max]`` (its decisions are 10 ms, not the 0.1 s of the cutting envs);
    None: ``actuation``."""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"machine name must be a non-empty string, got {self.name!r}")
        object.__setattr__(self, "actuation", resolve_actuation(self.actuation))
        object.__setattr__(self, "power_sensor", resolve_power_sensor(self.power_sensor))
        object.__setattr__(self, "feed_override", resolve_actuation(self.feed_override))
        if self.spindle_power_W is not None:
            check_range("spindle_power_W", self.spindle_power_W, 0.0, 1e7, lo_open=True)

    def env_kwargs(self, env_id: str) -> dict:
        """The env options that put ``env_id``'s plant on this machine, as plain values
        (JSON-friendly: a training run records them). Options an env does not have are
        left out (the spindle power outside Turning-v0, the power sensor outside Turning-v0
        and EndMilling-v0)."""
        kw: dict = {}
        act = self.actuation
        if env_id.endswith("/ContouringFeed-v0") and self.feed_override is not None:
            act = self.feed_override
        if act is not None:
            kw["actuation"] = dataclasses.asdict(act)
        turning = env_id.endswith("/Turning-v0")
        if self.spindle_power_W is not None and turning:
            kw["spindle_power_W"] = float(self.spindle_power_W)
        if self.power_sensor is not None and (turning or env_id.endswith("/EndMilling-v0")):
            kw["power_sensor"] = dataclasses.asdict(self.power_sensor)
        return kw

    def as_dict(self) -> dict:
        """The description as a machine file holds it (JSON-friendly)."""
        return {
            "name": self.name,
            "actuation": None if self.actuation is None else dataclasses.asdict(self.actuation),
            "spindle_power_W": self.spindle_power_W,
            "power_sensor": (
                None if self.power_sensor is None else dataclasses.asdict(self.power_sensor)
            ),
            "feed_override": (
                None if self.feed_override is None else dataclasses.asdict(self.feed_override)
            ),
        }

    def spread(self) -> list[Actuation]:
        """The actuation variants around the description: delay one period less (not below
        0) and more, the rate and acceleration limits 0.8x and 1.25x (module docstring)."""
        a = self.actuation or Actuation()
        out = []
        for dd in (-1, 0, 1):
            for f in (0.8, 1.25):
                d = max(0, a.delay_steps + dd)
                rate = a.max_rate_per_s * f if math.isfinite(a.max_rate_per_s) else math.inf
                acc = a.max_accel_per_s2 * f if math.isfinite(a.max_accel_per_s2) else math.inf
                out.append(
                    dataclasses.replace(a, delay_steps=d, max_rate_per_s=rate, max_accel_per_s2=acc)
                )
        return out


#: The machine of the held-out ``shopfloor`` split, as a file would describe it.
SHOPFLOOR_MACHINE = Machine(
    "shopfloor", SHOPFLOOR_ACTUATION, 2200.0, feed_override=SHOPFLOOR_OVERRIDE
)


def load_machine(path) -> Machine:
    """The :class:`Machine` a YAML file describes (module docstring). ``ValueError`` naming
    the file and the key for an unknown key or a value out of range."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"machine file {path} does not exist") from None
    except yaml.YAMLError as e:
        raise ValueError(f"machine file {path}: not valid YAML: {e}") from None
    if not isinstance(data, dict):
        raise ValueError(f"machine file {path}: must hold a mapping of {list(_KEYS)}")
    bad = sorted(set(data) - set(_KEYS))
    if bad:
        raise ValueError(f"machine file {path}: unknown keys {bad}; allowed {list(_KEYS)}")
    try:
        return Machine(
            name=str(data.get("name", path.stem)),
            actuation=data.get("actuation"),
            spindle_power_W=data.get("spindle_power_W"),
            power_sensor=data.get("power_sensor"),
            feed_override=data.get("feed_override"),
        )
    except (TypeError, ValueError) as e:
        raise ValueError(f"machine file {path}: {e}") from None
