"""Residual setpoint policies: a learned supervisor over a tuned classical regulator.

The classical regulators of the force- and torque-holding envs (the adaptive PI of
Turning-v0, for one) regulate at ``setpoint`` x the process limit. In this formulation the
policy does not command the feed: each step its action ``a`` in [-1, 1] sets the
regulator's setpoint, ``clip(centre + span * a, lo, hi)``, where ``centre`` is the
regulator's own (tuned) setpoint; the regulator then computes the command as it always does,
so its integrator and its gain estimate see the command the machine gets. A policy that
outputs 0 is the tuned regulator, exactly: learning starts from the classical agent and may
only move its setpoint within ``span``.

Three pieces share one definition (:class:`ResidualSpec`): :class:`SetpointResidual`, a
gymnasium wrapper (rl-zoo3's ``env_wrapper``, ``DummyVecEnv``), :class:`VecSetpointResidual`
for SB3 vector envs (the native batched ones), and :class:`ResidualAgent`, which replays a
trained policy over its regulator behind the agent protocol (``agents.rl.load_policy``
returns one for a run trained so).
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import NamedTuple

import gymnasium as gym
import numpy as np

from agents.base import Agent
from agents.rl.files import read_json_object

__all__ = ["ResidualSpec", "SetpointResidual", "VecSetpointResidual", "ResidualAgent"]

TUNED_FILE = Path(__file__).resolve().parents[1] / "bench" / "tuned.json"
WRAPPER = "agents.rl.residual.SetpointResidual"


class ResidualSpec(NamedTuple):
    """The regulator under the policy and the setpoint range the policy may use.

    ``base``: import path of the regulator's class (an ``agents.base.Agent`` with
    ``from_env``); ``params``: its settings, or ``"tuned"`` for the env's entry in
    ``agents/bench/tuned.json``; ``knob``: the tunable setting the policy moves (default
    ``setpoint``; ``override_cap`` for the contouring look-ahead planner); ``span``: it moves
    at most this much from the regulator's own value (at most ``hi - lo``); ``lo``, ``hi``: it never leaves
    ``[lo, hi]``. ``mode="add"`` instead adds the policy's correction, ``span`` x action, to
    every component of the regulator's action (the contouring servo: a correction on top of
    the H-infinity loop); ``knob``, ``lo`` and ``hi`` are then unused. Several knobs: ``knob``
    a list of names, ``span``, ``lo`` and ``hi`` each a number for all or a list of one per
    knob; the policy's action has one component per knob.
    """

    base: str
    params: dict | str = "tuned"
    span: float | list = 0.2
    lo: float | list = 0.3
    hi: float | list = 1.0
    knob: str | list = "setpoint"
    mode: str = "knob"

    def knobs(self) -> list[tuple[str, float, float, float]]:
        """``(name, span, lo, hi)`` of each knob the policy moves (one unless ``knob`` is a
        list); ``ValueError`` when a list's length is not the number of knobs."""
        names = [self.knob] if isinstance(self.knob, str) else list(self.knob)
        cols = []
        for field in ("span", "lo", "hi"):
            v = getattr(self, field)
            v = list(v) if isinstance(v, (list, tuple)) else [v] * len(names)
            if len(v) != len(names):
                raise ValueError(
                    f"{field} must be a number or a list of {len(names)} (one per knob), "
                    f"got {getattr(self, field)!r}"
                )
            cols.append(v)
        return list(zip(names, *cols, strict=True))

    def checked(self) -> ResidualSpec:
        """This spec if its values are usable (``ValueError`` naming the field otherwise)."""
        if not isinstance(self.base, str) or "." not in self.base:
            raise ValueError(f"base must be an import path 'module.Class', got {self.base!r}")
        if not (self.params == "tuned" or isinstance(self.params, dict)):
            raise ValueError(f"params must be a mapping or 'tuned', got {self.params!r}")
        if self.mode not in ("knob", "add"):
            raise ValueError(f"mode must be 'knob' or 'add', got {self.mode!r}")
        if not self.knob or not all(isinstance(k, str) for k in np.atleast_1d(self.knob)):
            raise ValueError(f"knob must be a setting's name or a list of names, got {self.knob!r}")
        cls = self.base_class()
        if not hasattr(cls, "from_env"):
            raise ValueError(f"base {self.base} is not an agent class with from_env")
        for knob, span, lo, hi in self.knobs():
            for name, v in (("span", span), ("lo", lo), ("hi", hi)):
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                    raise ValueError(f"{name} must be a finite number, got {v!r}")
            if not 0.0 < lo < hi <= 10.0:
                raise ValueError(f"lo and hi must satisfy 0 < lo < hi <= 10, got {lo}, {hi}")
            # a knob moves at most across [lo, hi]; a correction at most across the action box
            top, what = (2.0, "the action range") if self.mode == "add" else (hi - lo, "hi - lo")
            if not 0.0 < span <= top:
                raise ValueError(f"span must be in (0, {top:g}] ({what}), got {span!r}")
            if self.mode == "knob" and knob not in getattr(cls, "TUNABLE", {}):
                raise ValueError(f"base {self.base} has no tunable {knob!r} to supervise")
        if self.mode == "add" and not isinstance(self.knob, str):
            raise ValueError("mode 'add' takes no list of knobs")
        return self

    def base_class(self):
        module, _, name = self.base.rpartition(".")
        try:
            return getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError):
            raise ValueError(f"base: cannot import {self.base!r}") from None

    def settings(self, env_id: str | None) -> dict:
        """The regulator's settings: ``params``, or its tuned entry for ``env_id``."""
        if isinstance(self.params, dict):
            return dict(self.params)
        name = self.base.rpartition(".")[2]
        data = read_json_object(TUNED_FILE, "tuned settings file") if TUNED_FILE.is_file() else {}
        envs = data.get("envs", {})
        entry = envs.get(env_id, {}) if isinstance(envs, dict) else None
        entry = entry.get(name) if isinstance(entry, dict) else None
        if entry is None:
            raise ValueError(
                f"params='tuned': {TUNED_FILE} has no {name} entry for {env_id!r} "
                "(run `machining-bench tune`, or give params)"
            )
        params = entry.get("params") if isinstance(entry, dict) else None
        if not isinstance(params, dict) or not all(isinstance(k, str) for k in params):
            raise ValueError(
                f"{TUNED_FILE}: envs.{env_id}.{name}.params must be an object of settings, "
                f"got {params!r:.60}"
            )
        return dict(params)

    def make_base(self, env, env_id: str | None = None):
        """The regulator for ``env`` (its id from ``env.spec`` unless given)."""
        if env_id is None:
            spec = getattr(env, "spec", None) or getattr(env.unwrapped, "spec", None)
            env_id = spec.id if spec is not None else None
        base = self.base_class().from_env(env, **self.settings(env_id))
        if self.mode == "add":
            return base
        for knob, _, lo, hi in self.knobs():
            value = getattr(base, knob)
            if not lo <= value <= hi:
                raise ValueError(
                    f"the regulator's {knob} {value:.3g} is outside [lo, hi] = [{lo}, {hi}]"
                )
        return base

    def setpoints(self, base, action, knobs=None) -> np.ndarray:
        """The knob's value in each lane for the policy's actions ``(n, 1)`` (or ``(1,)``);
        with several knobs, ``(n, knobs)``, a column per knob. ``knobs``: :meth:`knobs`,
        where the caller holds it (the wrappers find it once)."""
        knobs = self.knobs() if knobs is None else knobs
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(-1, len(knobs)), -1.0, 1.0)
        cols = [
            np.clip(getattr(base, knob) + span * a[:, j], lo, hi)
            for j, (knob, span, lo, hi) in enumerate(knobs)
        ]
        return cols[0] if len(cols) == 1 else np.stack(cols, axis=1)

    def action_dim(self, env_action_dim: int) -> int:
        """Components of the policy's action: one knob, or one correction per env action."""
        return env_action_dim if self.mode == "add" else len(self.knobs())

    def act(self, base, obs: np.ndarray, state: np.ndarray, action, knobs=None) -> np.ndarray:
        """The regulator's command for the batch ``obs`` at the policy's setpoints (or with
        its correction added); ``state`` is updated in place (the regulator's own state).
        ``knobs``: as for :meth:`setpoints`."""
        obs = np.asarray(obs, dtype=np.float64)
        if self.mode == "add":
            u = np.clip(base._act(obs, state), -1.0, 1.0).astype(np.float32)
            a = np.clip(np.asarray(action, dtype=np.float64).reshape(u.shape), -1.0, 1.0)
            return np.clip(u.astype(np.float64) + self.span * a, -1.0, 1.0).astype(np.float32)
        knobs = self.knobs() if knobs is None else knobs
        names = [k for k, *_ in knobs]
        centres = [getattr(base, k) for k in names]
        values = self.setpoints(base, action, knobs).reshape(len(obs), len(names))
        for j, k in enumerate(names):
            setattr(base, k, values[:, j])
        try:
            u = base._act(np.asarray(obs, dtype=np.float64), state)
        finally:
            for k, c in zip(names, centres, strict=True):
                setattr(base, k, c)
        return np.clip(u, -1.0, 1.0).astype(np.float32).reshape(len(obs), -1)


def _action_space(n: int) -> gym.spaces.Box:
    return gym.spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)


class SetpointResidual(gym.Wrapper):
    """The env with the policy setting the regulator's setpoint (see the module doc).

    Parameters are :class:`ResidualSpec`'s. ``info["setpoint"]`` is the knob's value used (a
    list, a value per knob, with several).
    """

    def __init__(
        self, env, base: str, params="tuned", span=0.2, lo=0.3, hi=1.0, knob="setpoint", mode="knob"
    ):
        super().__init__(env)
        self.residual = ResidualSpec(base, params, span, lo, hi, knob, mode).checked()
        self.base = self.residual.make_base(env)
        self._knobs = self.residual.knobs()
        self.action_space = _action_space(self.residual.action_dim(env.action_space.shape[0]))
        self._obs = None
        self._state = None

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self._obs = np.asarray(obs, dtype=np.float64)[None, :]
        self._state = self.base.initial_state(1, self._obs)
        return obs, info

    def step(self, action):
        if self._obs is None:
            raise RuntimeError("SetpointResidual: call reset() before step()")
        _check_actions("SetpointResidual", action, self.action_space.shape)
        state = self._state.copy()  # kept only once the env has taken the step
        u = self.residual.act(self.base, self._obs, state, action, self._knobs)[0]
        obs, reward, terminated, truncated, info = self.env.step(u)
        self._state = state
        self._obs = np.asarray(obs, dtype=np.float64)[None, :]
        if self.residual.mode == "knob":
            used = np.asarray(self.residual.setpoints(self.base, action, self._knobs))[0]
            info = {**info, "setpoint": float(used) if used.ndim == 0 else used.tolist()}
        return obs, reward, terminated, truncated, info


def _check_actions(who: str, action, shape: tuple) -> None:
    """``ValueError`` naming ``who`` unless ``action`` is finite real numbers of ``shape``
    (size-1 dimensions aside), checked before the regulator's state is touched."""
    try:
        a = np.asarray(action)
        if a.dtype.kind not in "iuf":  # no strings, booleans or complex numbers
            raise TypeError
    except (TypeError, ValueError):
        raise ValueError(f"{who}: action must be real numbers, got {action!r:.60}") from None
    if [d for d in a.shape if d != 1] != [d for d in shape if d != 1]:
        raise ValueError(f"{who}: action must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{who}: action must be finite, got {action!r:.60}")


def vec_setpoint_residual(venv, residual: ResidualSpec, env_id: str, env_kwargs: dict):
    """``venv`` (an SB3 VecEnv of ``env_id``) under the policy-set setpoint."""
    probe = gym.make(env_id, **dict(env_kwargs))
    try:
        base = residual.make_base(probe, env_id)
    finally:
        probe.close()
    return VecSetpointResidual(venv, residual, base)


def _vec_wrapper_base():
    from stable_baselines3.common.vec_env import VecEnvWrapper

    return VecEnvWrapper


class VecSetpointResidual(_vec_wrapper_base()):
    """:class:`SetpointResidual` for an SB3 VecEnv: one regulator state per lane, reset
    with the lane (SB3 vector envs reset a finished lane in the same step)."""

    def __init__(self, venv, residual: ResidualSpec, base):
        dim = residual.action_dim(venv.action_space.shape[0])
        super().__init__(venv, action_space=_action_space(dim))
        self.residual, self.base = residual, base
        self._knobs = residual.knobs()
        self._obs = None
        self._state = None
        self._pending = None

    def reset(self):
        obs = self.venv.reset()
        self._obs = np.asarray(obs, dtype=np.float64)
        self._state = self.base.initial_state(self.num_envs, self._obs)
        return obs

    def step_async(self, actions):
        _check_actions("VecSetpointResidual", actions, (self.num_envs, *self.action_space.shape))
        state = self._state.copy()  # kept only once the envs have taken the step
        u = self.residual.act(self.base, self._obs, state, actions, self._knobs)
        self.venv.step_async(u)
        self._pending = state

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        self._state, self._pending = self._pending, None
        self._obs = np.asarray(obs, dtype=np.float64)
        if np.any(dones):
            self._state[dones] = self.base.initial_state(int(np.sum(dones)), self._obs[dones])
        return obs, rewards, dones, infos


class ResidualAgent(Agent):
    """A trained residual policy over its regulator, behind the agent protocol.

    ``policy``: the trained policy (an ``agents.rl.PolicyAgent``); ``base``: the regulator
    (built by ``ResidualSpec.make_base``). The state is the regulator's, one row per env;
    the observations and the state are checked as the regulator checks them, and a bad one
    is named under this agent's name (the regulator is a part of it).
    """

    learned = True

    def __init__(self, policy, residual: ResidualSpec, base, name: str | None = None):
        self.policy, self.residual, self.base = policy, residual, base
        self._knobs = residual.knobs()
        self.name = name or f"{policy.name} over {base.name}"
        self.state_size = base.state_size
        self.obs_dim = base.obs_dim
        self.obs_index = base.obs_index

    def initial_state(self, n: int, obs: np.ndarray) -> np.ndarray:
        return self.base.initial_state(n, obs)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        batch, single, st = self._checked_step(observation, state, episode_start)
        a, _ = self.policy.predict(batch, deterministic=deterministic)
        u = self.residual.act(self.base, batch, st, a, self._knobs)
        return (u[0] if single else u), st
