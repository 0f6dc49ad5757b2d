"""A Gymnasium vector env presented as a Stable-Baselines3 ``VecEnv``.

SB3 trains on its own ``VecEnv`` interface: ``step`` returns ``(obs, reward, done, infos)``
with one info dict per env, an env that ends is reset in the same step, and its last
observation travels in ``infos[i]["terminal_observation"]``. A Gymnasium
``gymnasium.vector.VectorEnv`` with ``metadata["autoreset_mode"] == AutoresetMode.SAME_STEP``
does the same reset and passes the last observation as ``info["final_obs"]``; this adapter
translates one into the other, so ``VecNormalize``, ``VecMonitor``, ``evaluate_policy`` and
every SB3 algorithm work on a native batched env unchanged.

>>> import gymnasium as gym
>>> from agents.rl.vec import SB3VecEnv
>>> venv = SB3VecEnv(gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync",
...                               vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP}))
>>> venv.seed(0)
[0, 1]
>>> venv.reset().shape
(2, 4)
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from machining_envs.wrappers import ActionIncrement

__all__ = ["SB3VecEnv", "VecIncrementalAction"]


class SB3VecEnv(VecEnv):
    """Present a Gymnasium ``VectorEnv`` with same-step autoreset as an SB3 ``VecEnv``.

    Parameters
    ----------
    venv : gymnasium.vector.VectorEnv
        Its ``metadata["autoreset_mode"]`` must be ``AutoresetMode.SAME_STEP``.
    info_keys : iterable of str, optional
        The ``info`` entries copied into the per-env info dicts (all by default, as SB3's
        ``DummyVecEnv`` gives them). Training that needs none of them (``VecMonitor``
        counts episodes itself) may pass ``()``: the terminal observation and
        ``TimeLimit.truncated`` are then given where an env ends, all SB3 reads. The
        copies are Python work per env and key: at N = 1024 the full info costs several
        times the batched step itself. A key the env's info does not hold at the first
        reset is refused then (``ValueError`` listing the keys it has).
    """

    def __init__(self, venv: gym.vector.VectorEnv, info_keys: Iterable[str] | None = None):
        mode = venv.metadata.get("autoreset_mode")
        if mode != AutoresetMode.SAME_STEP:
            raise ValueError(
                "SB3VecEnv needs a vector env with metadata['autoreset_mode'] == "
                f"AutoresetMode.SAME_STEP, got {mode!r}: make it with "
                "gym.make_vec(id, num_envs=N, autoreset_mode='SAME_STEP')"
            )
        self.venv = venv
        if isinstance(info_keys, str):  # one key alone (a string would be its letters)
            info_keys = (info_keys,)
        self.info_keys = None if info_keys is None else tuple(info_keys)
        self._keys_checked = self.info_keys is None
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self.render_mode = getattr(venv, "render_mode", None)
        self._actions: np.ndarray | None = None

    # ---- the VecEnv interface --------------------------------------------------------------
    def reset(self):
        seeds = self._seeds
        # Gymnasium seeds a vector env with one int (lane i gets seed + i) or a list.
        seed = None if all(s is None for s in seeds) else list(seeds)
        options = self._options[0] if self._options and self._options[0] else None
        if any(o != self._options[0] for o in self._options[1:]):
            # The batched env resets every lane with one options dict (Gymnasium's vector
            # API); SB3's DummyVecEnv would give each env its own: refuse, not drop them.
            raise ValueError(
                "SB3VecEnv resets every env with the same options; set_options got different "
                f"options per env ({self._options[0]!r}, ...): pass one dict (its "
                "'scenario' may be a list of one scenario per env)"
            )
        obs, info = self.venv.reset(seed=seed, options=options)
        if not self._keys_checked:
            unknown = [k for k in self.info_keys if k not in info]
            if unknown:
                raise ValueError(
                    f"info_keys {unknown} are not keys of the env's info; it has "
                    f"{sorted(k for k in info if not k.startswith('_'))}"
                )
            self._keys_checked = True
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = self._split(info, np.zeros(self.num_envs, dtype=bool))
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        done = np.logical_or(terminated, truncated)
        infos = self._split(info, done, step=True)
        if done.any():
            # An env that ended reports its last step's info (SB3's convention), not the
            # info of the reset that followed it.
            last = self._split(info.get("final_info", {}), ~done)
            final = info["final_obs"]
            for i in np.flatnonzero(done):
                infos[i] = last[i]
                infos[i]["terminal_observation"] = final[i]
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return obs, np.asarray(reward, dtype=np.float32), done, infos

    def close(self) -> None:
        self.venv.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None] * self.num_envs

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        value = getattr(self.venv, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs):
        out = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [out for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    # ---- helpers ---------------------------------------------------------------------------
    def _split(self, info: dict, skip: np.ndarray, step: bool = False) -> list[dict]:
        """Gymnasium's dict of arrays (with ``_key`` masks) -> one dict per env (empty for the
        envs in ``skip``). A flat array's values come as Python numbers (bool, int, float,
        str), as the single env gives them; other values as the array's elements."""
        n = self.num_envs
        if step and self.info_keys is None:
            # The full info holds TimeLimit.truncated at every step, as SB3's own VecEnvs
            # give it (step_wait sets it for the envs that end; with info_keys, only there).
            out = [{"TimeLimit.truncated": False} for _ in range(n)]
        else:
            out = [{} for _ in range(n)]
        keys = info if self.info_keys is None else [k for k in self.info_keys if k in info]
        keep = ~skip
        every = bool(keep.all())
        for key in keys:
            if key.startswith("_") or key in ("final_obs", "final_info"):
                continue
            values = info[key]
            mask = info.get("_" + key)
            held = keep if mask is None else keep & mask
            flat = isinstance(values, np.ndarray) and values.ndim == 1 and values.dtype != object
            if every and (mask is None or held.all()):  # every env: no index to look up
                for d, v in zip(out, values.tolist() if flat else values, strict=True):
                    d[key] = v
            else:
                lanes = np.flatnonzero(held).tolist()
                picked = values[lanes].tolist() if flat else [values[i] for i in lanes]
                for i, v in zip(lanes, picked, strict=True):
                    out[i][key] = v
        return out


class VecIncrementalAction(VecEnvWrapper):
    """``machining_envs.wrappers.IncrementalAction`` for a whole SB3 ``VecEnv``: the agent
    outputs changes of the env's action, at most ``increment.max_step`` per step, and (with
    ``increment.hide_action``) does not see the action now applied. The same map as the
    per-env wrapper, applied to the batch, so a policy trained on either runs on both."""

    def __init__(self, venv: VecEnv, increment: ActionIncrement):
        super().__init__(venv)
        shape = venv.observation_space.shape
        self.increment = ActionIncrement(*increment).check(shape[0] if shape else None)
        self._raw: np.ndarray | None = None

    def reset(self):
        self._raw = self.venv.reset()
        return self.increment.policy_observation(self._raw)

    def step_async(self, actions: np.ndarray) -> None:
        self.venv.step_async(self.increment.absolute_action(self._raw, actions))

    def step_wait(self):
        obs, reward, done, infos = self.venv.step_wait()
        self._raw = obs
        for info in infos:
            if "terminal_observation" in info:
                info["terminal_observation"] = self.increment.policy_observation(
                    info["terminal_observation"]
                )
        return self.increment.policy_observation(obs), reward, done, infos
