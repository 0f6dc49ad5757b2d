"""Wrappers for training learned controllers on the machining envs.

:class:`IncrementalAction` turns an env's absolute action into a change of it: the agent
outputs ``delta`` in [-1, 1] and the env receives ``clip(a_prev + max_step * delta, -1, 1)``,
where ``a_prev`` is the action now applied, read from the observation's ``prev_action``
field. A policy that outputs zero holds the command, so the wrapped env is an integrating
plant: a policy that is zero where the error is zero regulates without steady-state error,
whatever the hidden process gain, which an absolute policy can only approximate. Because the
new action depends only on the observation and the agent's output,
:meth:`IncrementalAction.absolute_action` applies the same map outside the wrapper (a
policy trained on the wrapped env runs on the plain env; see ``agents.rl.PolicyAgent``).

>>> import gymnasium as gym, numpy as np
>>> import machining_envs
>>> from machining_envs.wrappers import IncrementalAction
>>> env = IncrementalAction(gym.make("machining_envs/EndMilling-v0"), max_step=0.25)
>>> obs, _ = env.reset(seed=0)
>>> float(obs[2])                      # the previous action: -1, feed at rest
-1.0
>>> obs, *_ = env.step(np.array([1.0], dtype=np.float32))
>>> float(obs[2])                      # one step up by max_step
-0.75
"""

from __future__ import annotations

import math
from typing import NamedTuple

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from machining_envs.core.checks import is_integer, is_real

__all__ = ["IncrementalAction", "ActionIncrement"]


class ActionIncrement(NamedTuple):
    """What :class:`IncrementalAction` does, as data: enough to apply it outside the wrapper
    (``agents.rl.PolicyAgent``) and to record it with a trained policy (``_asdict()``)."""

    max_step: float
    prev_action_index: int
    hide_action: bool = False
    #: Further observation indices the agent sees as 0 (``IncrementalAction``'s
    #: ``hide_fields``).
    hidden: tuple[int, ...] = ()

    def check(self, n_obs: int | None = None) -> ActionIncrement:
        """``self`` if its fields can be applied (``max_step`` in (0, 2], an index of the
        observation's ``n_obs`` fields, ``hide_action`` a bool); else ``ValueError`` naming
        the field."""
        step, index = self.max_step, self.prev_action_index
        if not (is_real(step) and math.isfinite(step) and 0.0 < step <= 2.0):
            raise ValueError(f"max_step must be a number in (0, 2], got {step!r}")
        hi = "n_obs - 1" if n_obs is None else n_obs - 1
        if not (is_integer(index) and 0 <= index and (n_obs is None or index < n_obs)):
            raise ValueError(f"prev_action_index must be an integer in [0, {hi}], got {index!r}")
        if not isinstance(self.hide_action, (bool, np.bool_)):
            raise ValueError(f"hide_action must be True or False, got {self.hide_action!r}")
        if not isinstance(self.hidden, (tuple, list)) or not all(
            is_integer(i) and 0 <= i and (n_obs is None or i < n_obs) for i in self.hidden
        ):
            raise ValueError(f"hidden must be a list of integers in [0, {hi}], got {self.hidden!r}")
        return self

    @classmethod
    def from_record(cls, record: dict) -> ActionIncrement:
        """The increment recorded as ``_asdict()`` (a run's ``config.json``), checked."""
        return cls(**{**record, "hidden": tuple(record.get("hidden", ()))}).check()

    def policy_observation(self, obs) -> np.ndarray:
        """What the agent sees of ``obs``."""
        return IncrementalAction.policy_observation(
            obs, self.prev_action_index, self.hide_action, self.hidden
        )

    def absolute_action(self, obs, delta) -> np.ndarray:
        """The env's action for the agent's output ``delta`` given the raw ``obs``."""
        return IncrementalAction.absolute_action(obs, delta, self.max_step, self.prev_action_index)


def _field_index(env, field) -> int:
    """The observation index of ``field`` (a name in ``env.OBS_INDEX`` or an index)."""
    if is_integer(field):
        return int(field)
    names = sorted(k for k in getattr(env, "OBS_INDEX", {}) if k not in ("prev_action", "history"))
    if field not in names:
        raise ValueError(
            f"hide_fields: {field!r} is not a field of {type(env).__name__}'s observation; "
            f"one of {names} or an index (the applied action: hide_action)"
        )
    return int(env.OBS_INDEX[field])


class IncrementalAction(gym.Wrapper):
    """The agent's action is a change of the env's action, at most ``max_step`` per step.

    Parameters
    ----------
    env : gymnasium.Env
        An env with a one-dimensional ``Box(-1, 1)`` action and ``OBS_INDEX["prev_action"]``
        (Turning-v0, EndMilling-v0, MicroDrilling-v0).
    max_step : float
        Largest change of the env's action per step, in (0, 2].
    hide_action : bool
        If True, the agent's observation carries 0 in place of the action now applied (the
        wrapper still reads it from the env): the agent can then only act on the measured
        signals, so where its output is zero cannot depend on the command level, and the
        loop settles where the measured signals say it should (``policy_observation``).
    hide_fields : sequence of str or int
        Further observation fields the agent sees as 0, by their names in the env's
        ``OBS_INDEX`` (``"limit"``, ``"spindle"``, ...) or by index. A policy that sees
        neither the limit nor the spindle speed acts on the load measured as a share of the
        limit alone, so it cannot read a limit or speed outside its training ranges as
        something it never met (``agents/rl/configs/ppo_load_only.yml``).
    """

    def __init__(
        self,
        env: gym.Env,
        max_step: float = 0.25,
        hide_action: bool = False,
        hide_fields=(),
    ):
        super().__init__(env)
        ActionIncrement(max_step, 0, False).check()  # max_step, before the env's checks
        base = env.unwrapped
        index = getattr(base, "OBS_INDEX", {}).get("prev_action")
        space = env.action_space
        if index is None or not (
            isinstance(space, spaces.Box)
            and space.shape == (1,)
            and np.all(space.low == -1.0)
            and np.all(space.high == 1.0)
        ):
            raise ValueError(
                f"IncrementalAction needs an env with a Box(-1, 1, (1,)) action and an "
                f"OBS_INDEX['prev_action'] field; {type(base).__name__} has not"
            )
        if isinstance(hide_fields, str):
            raise ValueError(f"hide_fields must be a list of field names, got {hide_fields!r}")
        hidden = tuple(_field_index(base, f) for f in hide_fields)
        self.increment = ActionIncrement(float(max_step), int(index), hide_action, hidden).check(
            env.observation_space.shape[0]
        )
        self._obs: np.ndarray | None = None

    @staticmethod
    def absolute_action(obs, delta, max_step: float, prev_action_index: int) -> np.ndarray:
        """The env's action for agent output ``delta`` given observation(s) ``obs``.

        Works on one observation ``(n_obs,)`` with ``delta`` of shape ``(1,)``, or on a batch
        ``(n, n_obs)`` with ``(n, 1)``. Non-finite ``delta`` raises ``ValueError``.
        """
        d = np.asarray(delta, dtype=np.float64)
        if not np.all(np.isfinite(d)):
            raise ValueError(f"IncrementalAction: action must be finite, got {delta!r}")
        prev = np.asarray(obs)[..., prev_action_index : prev_action_index + 1].astype(np.float64)
        return np.clip(prev + max_step * np.clip(d, -1.0, 1.0), -1.0, 1.0).astype(np.float32)

    @staticmethod
    def policy_observation(obs, prev_action_index: int, hide_action: bool, hidden=()) -> np.ndarray:
        """What the agent sees of observation(s) ``obs``: a copy with the applied action
        zeroed if ``hide_action`` and the fields ``hidden`` zeroed, else ``obs`` itself."""
        zeroed = [*([prev_action_index] if hide_action else []), *hidden]
        if not zeroed:
            return obs
        out = np.array(obs, dtype=np.float32, copy=True)
        out[..., zeroed] = 0.0
        return out

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self._obs = obs
        return self.increment.policy_observation(obs), info

    def step(self, action):
        if self._obs is None:
            raise RuntimeError("IncrementalAction: call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(
            self.increment.absolute_action(self._obs, action)
        )
        self._obs = obs
        return self.increment.policy_observation(obs), reward, terminated, truncated, info
