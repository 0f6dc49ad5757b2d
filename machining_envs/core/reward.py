"""The reward as a component: the weights every env takes as ``reward=``, checked, and
:class:`LimitReward`, the one weights type of the regulation envs (Turning-v0,
EndMilling-v0, MicroDrilling-v0).

A user passes weights as the env's weights type, as a dict of some of its fields (the
others keep their defaults), or None (the defaults): :func:`resolve_reward`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from machining_envs.core.checks import PY_NUMBER_TYPES, is_real
from machining_envs.core.env import check_overrides

__all__ = ["LimitReward", "resolve_reward", "check_reward_weights"]


def check_reward_weights(reward) -> None:
    """``ValueError`` unless every field of the reward dataclass ``reward`` is a finite
    number >= 0, not a bool (the first that is not is named: ``"reward weight {name} must
    be a finite number >= 0, got {value!r}"``). Call it from the dataclass's
    ``__post_init__``.
    """
    for f in dataclasses.fields(reward):
        v = getattr(reward, f.name)
        if not (is_real(v, PY_NUMBER_TYPES) and math.isfinite(v) and v >= 0):
            raise ValueError(f"reward weight {f.name} must be a finite number >= 0, got {v!r}")


def resolve_reward(reward, reward_cls: type):
    """Reward weights from ``None`` (defaults), a dict of weights, or a ``reward_cls``.

    A dict's keys are field names; a name ``reward_cls.FORMER_NAMES`` lists (a field's
    name in recorded configurations) stands for its field."""
    if isinstance(reward, dict):
        former = getattr(reward_cls, "FORMER_NAMES", {})
        reward = {former.get(k, k): v for k, v in reward.items()}
        check_overrides(
            reward_cls.__name__, reward, [f.name for f in dataclasses.fields(reward_cls)]
        )
        reward = reward_cls(**reward)
    if reward is None:
        return reward_cls()
    if not isinstance(reward, reward_cls):
        raise ValueError(
            f"reward must be a {reward_cls.__name__} or a dict, got {type(reward).__name__}"
        )
    return reward


@dataclass(frozen=True)
class LimitReward:
    r"""Weights of the regulation envs' reward: cut fast while a measured load ``y`` (the
    cutting force of Turning-v0, the spindle torque of EndMilling-v0 and MicroDrilling-v0)
    stays under its limit ``L``.

    .. math::

        r = -w_t \left|\frac{y}{\theta L} - 1\right| - w_o \max\!\left(0, \frac{y}{L} - 1\right)
            + w_p \, p - w_b [\text{breakage}]

    with ``p`` the env's progress this step (its section Rewards: the distance fed as a
    share of the most the servo can feed, the feed velocity as a share of the top one, the
    hole deepened as a share of the nominal feed's). The fields are in the order of the
    weights array the compiled step reads (:meth:`weights`). An env takes them as
    ``reward=``: a ``LimitReward`` (``TurningReward``, ``MillingReward`` and
    ``DrillingReward`` name it in each process), a dict of some fields, which may say
    ``overforce`` or ``overtorque`` for ``overlimit`` (:attr:`FORMER_NAMES`), or None.
    """

    tracking: float = 1.0
    """w_t, weight of the load's distance to ``target`` x limit (relative)."""
    overlimit: float = 4.0
    """w_o, weight of the load above the limit (relative to the limit)."""
    target: float = 0.9
    """theta, the share of the limit ``L`` the tracking term pulls towards: the reward's own
    setpoint (the task has none; agents choose theirs)."""
    progress: float = 0.0
    """w_p, weight of the progress this step."""
    breakage: float = 50.0
    """w_b, one-off penalty when the tool breaks."""

    #: Former names of ``overlimit`` (Turning-v0's ``overforce``, the torque envs'
    #: ``overtorque``), which a dict of weights may still use.
    FORMER_NAMES: ClassVar[dict[str, str]] = {"overforce": "overlimit", "overtorque": "overlimit"}

    def __post_init__(self) -> None:
        check_reward_weights(self)
        if not 0.0 < self.target <= 2.0:
            raise ValueError(f"reward target must lie in (0, 2], got {self.target!r}")

    def weights(self) -> np.ndarray:
        """``[tracking, overlimit, target, progress, breakage]``: the fields in order, as the
        compiled step reads them."""
        return np.array([getattr(self, f.name) for f in dataclasses.fields(self)], dtype=np.float64)
