"""The agent's action and the machine's command: :class:`ActionMap` (``Box(-1, 1)`` <-> a
physical command range) and the checks every env makes of an action."""

from __future__ import annotations

import math

import numpy as np

from machining_envs.core.checks import PY_NUMBER_TYPES, is_real

__all__ = [
    "ActionMap",
    "ActionMaps",
    "ACTION_MAPS",
    "check_action",
    "check_action_vector",
    "real_actions",
]


ACTION_MAPS = ("linear", "log")


class ActionMap:
    """Map between the agent's ``Box(-1, 1)`` action and a physical command range.

    ``scale="linear"``: the command is affine in the action. ``scale="log"``: it rises
    exponentially over ``decades`` decades,
    ``c = c_min + (c_max - c_min) (10^(k (a + 1) / 2) - 1) / (10^k - 1)``: action -1 is still
    ``c_min`` and +1 ``c_max``, but every step of ``2 / k`` in the action multiplies the
    command (above ``c_min``) by about ten, so a policy has the same relative resolution
    at every size of command.

    >>> m = ActionMap(0.0, 150.0, scale="log", decades=3.0)
    >>> round(m.action_to_command(-1.0), 9), round(m.action_to_command(1.0), 9)
    (0.0, 150.0)
    >>> round(float(m.command_to_action(m.action_to_command(0.25))), 12)
    0.25
    """

    def __init__(
        self, command_min: float, command_max: float, scale: str = "linear", decades: float = 3.0
    ):
        if not (
            math.isfinite(command_min) and math.isfinite(command_max) and command_max > command_min
        ):
            raise ValueError(
                f"command range must be finite with command_max > command_min, got "
                f"[{command_min}, {command_max}]"
            )
        if scale not in ACTION_MAPS:
            raise ValueError(f"action map scale must be one of {list(ACTION_MAPS)}, got {scale!r}")
        if not (is_real(decades, PY_NUMBER_TYPES) and 0.5 <= decades <= 6):
            raise ValueError(f"decades must be in [0.5, 6], got {decades!r}")
        self.command_min = float(command_min)
        self.command_max = float(command_max)
        self.scale = scale
        self.decades = float(decades)
        self._half = 0.5 * (self.command_max - self.command_min)
        self._mid = 0.5 * (self.command_max + self.command_min)
        self._span = self.command_max - self.command_min
        self._g = 10.0**self.decades - 1.0
        self._c = 0.5 * math.log(10.0) * self.decades

    @property
    def mid(self) -> float:
        """The command at action 0 of the linear map (``(command_min + command_max) / 2``)."""
        return self._mid

    @property
    def half(self) -> float:
        """Half the command range: the linear map's command per unit of action."""
        return self._half

    def constants(self) -> np.ndarray:
        """The map as a compiled kernel reads it: ``[is log, command_min, command range,
        k ln(10) / 2, 10^k - 1, mid, half]`` (``k`` the decades): the linear map is
        ``mid + half a``, the log map ``command_min + range expm1(c (a + 1)) / g``."""
        return np.array(
            [
                self.scale == "log",
                self.command_min,
                self._span,
                self._c,
                self._g,
                self._mid,
                self._half,
            ],
            dtype=np.float64,
        )

    def action_to_command(self, action):
        """Physical command for an action in [-1, 1] (array or scalar)."""
        if isinstance(action, float):  # the envs' step: plain floats, no array overhead
            if self.scale == "linear":
                return self._mid + self._half * action
            return self.command_min + self._span * math.expm1(self._c * (action + 1.0)) / self._g
        a = np.asarray(action, dtype=np.float64)
        if self.scale == "linear":
            return self._mid + self._half * a
        return self.command_min + self._span * np.expm1(self._c * (a + 1.0)) / self._g

    def command_to_action(self, command):
        """Action in [-1, 1] for a physical command (not clipped; on the log map a command
        below ``command_min`` gives an action below -1)."""
        c = np.asarray(command, dtype=np.float64)
        if self.scale == "linear":
            return (c - self._mid) / self._half
        x = np.maximum((c - self.command_min) * self._g / self._span, -1.0 + 1e-15)
        return np.log1p(x) / self._c - 1.0


def real_actions(action, env_name: str) -> np.ndarray:
    """``action`` as a float64 array if it is made of real numbers (Python or numpy ints and
    floats), else ``ValueError`` naming the env: strings, bytes, complex numbers, booleans
    and objects are refused, never converted (``"0.3"`` is not an action, and ``True`` is
    most likely a mistake)."""
    if isinstance(action, (str, bytes, bool, np.bool_, complex, dict, set)):
        raise ValueError(f"{env_name}: action must be real numbers, got {action!r:.60}")
    try:
        a = np.asarray(action)
    except (TypeError, ValueError):
        raise ValueError(f"{env_name}: action must be real numbers, got {action!r:.60}") from None
    if a.dtype.kind not in "iuf":
        raise ValueError(
            f"{env_name}: action must be real numbers, got {action!r:.60} (dtype {a.dtype})"
        )
    return a.astype(np.float64, copy=False)


def check_action(action, env_name: str) -> tuple[float, bool]:
    """Return the action as a float in [-1, 1] and whether it had to be clipped.

    Anything but real numbers raises ``ValueError`` naming the env (:func:`real_actions`);
    so do NaN and inf; a finite action outside the box is clipped (the caller counts it in
    ``info``).
    """
    if isinstance(action, np.ndarray) and action.shape == (1,) and action.dtype.kind == "f":
        v = float(action[0])
    else:
        a = real_actions(action, env_name).reshape(-1)
        if a.size != 1:
            raise ValueError(
                f"{env_name}: action must hold one value, got shape {np.shape(action)}"
            )
        v = float(a[0])
    if not math.isfinite(v):
        raise ValueError(f"{env_name}: action must be finite, got {v!r}")
    if v > 1.0:
        return 1.0, True
    if v < -1.0:
        return -1.0, True
    return v, False


def check_action_vector(action, n: int, env_name: str) -> tuple[list[float], bool]:
    """The action as ``n`` floats in [-1, 1] and whether any had to be clipped.

    Anything but real numbers (``real_actions``), NaN or inf raise ``ValueError`` naming
    the env and the values; a wrong size raises ``ValueError``; finite values outside the
    box are clipped (the caller counts them).
    """
    if isinstance(action, np.ndarray) and action.shape == (n,) and action.dtype.kind == "f":
        a = action
    else:
        a = real_actions(action, env_name).reshape(-1)
        if a.size != n:
            raise ValueError(
                f"{env_name}: action must hold {n} value(s), got shape {np.shape(action)}"
            )
    vals = a.tolist()
    clipped = False
    for i, v in enumerate(vals):
        if -1.0 <= v <= 1.0:  # the usual case: one test (false for NaN)
            continue
        if not math.isfinite(v):
            raise ValueError(f"{env_name}: action must be finite, got {a!r}")
        vals[i] = 1.0 if v > 1.0 else -1.0
        clipped = True
    return vals, clipped


class ActionMaps:
    """One linear :class:`ActionMap` per component of a vector action: component ``i`` of
    an action (the last axis) maps onto ``maps[i]``'s command range. ``command_min``,
    ``command_max``, ``mid`` and ``half`` are arrays, one entry per component.

    >>> m = ActionMaps(ActionMap(0.0, 10.0), ActionMap(-3.0, 3.0))
    >>> m.action_to_command([0.0, 0.5]).tolist(), m.command_to_action([10.0, -3.0]).tolist()
    ([5.0, 1.5], [1.0, -1.0])
    """

    scale = "linear"

    def __init__(self, *maps: ActionMap):
        if not maps or any(m.scale != "linear" for m in maps):
            raise ValueError("ActionMaps takes one or more linear ActionMap")
        self.maps = maps
        self.command_min = np.array([m.command_min for m in maps])
        self.command_max = np.array([m.command_max for m in maps])
        self.mid = np.array([m.mid for m in maps])
        self.half = np.array([m.half for m in maps])

    def action_to_command(self, action):
        """Physical commands for actions in [-1, 1] (their last axis the components)."""
        return self.mid + self.half * np.asarray(action, dtype=np.float64)

    def command_to_action(self, command):
        """Actions for physical commands (not clipped)."""
        return (np.asarray(command, dtype=np.float64) - self.mid) / self.half
