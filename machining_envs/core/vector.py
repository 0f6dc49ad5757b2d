"""What every native vector env shares: N lanes of one process stepped as arrays.

A process's vector env subclasses :class:`LaneVectorEnv` and implements two methods over
its batched physics:

- ``_reset_lanes(lanes, options)``: start new episodes in the lanes ``lanes`` (an index
  array), drawing each lane's scenario from its own generator ``self.lane_rngs[i]``;
  return their observations ``(len(lanes), *obs_shape)`` and their reset info, either as
  a dict of arrays of length ``len(lanes)``, or as a list of the lanes' own info dicts
  (the single env's, Python values), which the base writes into its arrays directly (a
  step resets one or two lanes: making arrays of their few values cost more than the
  values), or as ``None``: the reset lanes' info is then what ``_info_now()`` reports
  for them (a process whose lanes hold their reset info from the moment they start
  implements it: the step's info of every lane, as new arrays);
- ``_step_lanes(actions)``: advance every lane by one control period with the checked
  actions ``(num_envs, *action_shape)``; return observations, rewards, terminations,
  truncations and the step info as a new dict of arrays of length ``num_envs`` (a key
  that only some lanes have comes with a boolean mask under ``"_" + key``; the base adds
  the masks of the others to it). The arrays are new, not views of the lanes' state: they
  become the ``final_info`` of the lanes that end, which are reset after them.

This base checks the actions (a non-finite action in any lane raises ``ValueError``
naming the lane, and nothing is stepped), seeds lane ``i`` with ``seed + i`` exactly as
``env.reset(seed=seed + i)`` seeds the single env, and resets finished lanes in the same
step (``AutoresetMode.SAME_STEP``, declared in ``metadata["autoreset_mode"]``): the
returned observation of such a lane is its new episode's first, its last observation and
info are in ``info["final_obs"]`` and ``info["final_info"]``, exactly as Gymnasium's
``SyncVectorEnv(..., autoreset_mode=AutoresetMode.SAME_STEP)`` reports them.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from machining_envs.core.env import real_actions

__all__ = ["LaneVectorEnv", "check_num_envs", "merge_lane_info", "stack_lane_infos"]

#: The dtype of the info arrays that hold values of these Python types (as ``np.array`` of
#: such values makes them; strings are kept as objects).
_SCALAR_DTYPES = {
    float: np.dtype(np.float64),
    bool: np.dtype(np.bool_),
    int: np.dtype(np.int64),
    str: np.dtype(object),
}


def stack_lane_infos(infos: list[dict]) -> dict:
    """Per-lane info dicts as arrays over those lanes; a key that only some have comes with
    its ``_key`` mask."""
    first = tuple(infos[0]) if infos else ()
    if all(tuple(d) == first for d in infos[1:]):
        # The usual case (every lane has every key, no masks): one array per key.
        return {key: np.array([d[key] for d in infos]) for key in first}
    keys = list(dict.fromkeys(k for d in infos for k in d))
    part = {}
    for key in keys:
        have = np.array([key in d for d in infos])
        vals = [d.get(key) for d in infos]
        if not have.all():
            fill = next(v for v in vals if v is not None)
            zero = np.zeros_like(fill) if isinstance(fill, np.ndarray) else type(fill)(0)
            vals = [v if h else zero for v, h in zip(vals, have, strict=True)]
            part["_" + key] = have
        part[key] = np.array(vals)
    return part


def _write_lane_infos(top: dict, lanes: list, infos: list[dict], kept, every) -> dict:
    """Write the reset infos ``infos`` (one dict per lane of ``lanes``) into ``top``'s
    arrays, in place, where that is exact: a key every other lane holds (its mask is
    ``kept``), every one of the lanes has, with values of one Python type whose arrays have
    the dtype of ``top``'s (float, bool, int, str). The key then holds in every lane. Returns
    the other keys' values, stacked (:func:`stack_lane_infos`), for the general merge."""
    first = infos[0]
    others = infos[1:]
    rest = []
    for k, v in first.items():
        arr = top.get(k)
        t = type(v)
        if (
            arr is None
            or top["_" + k] is not kept
            or _SCALAR_DTYPES.get(t) != arr.dtype
            or any(k not in d or type(d[k]) is not t for d in others)
        ):
            rest.append(k)
            continue
        for i, d in zip(lanes, infos, strict=True):
            arr[i] = d[k]
        top["_" + k] = every
    if not rest and all(len(d) == len(first) for d in others):
        return {}
    return stack_lane_infos([{k: d[k] for k in d if k in rest or k not in first} for d in infos])


def merge_lane_info(info: dict, lanes: np.ndarray, part: dict, num_envs: int) -> None:
    """Write ``part`` (arrays over ``lanes``) into ``info`` (arrays over all lanes, with
    ``_key`` masks), in place. Masks shared between keys that every one of ``lanes`` has
    stay shared (one new mask for them all)."""
    merged: dict[int, tuple] = {}  # id(old mask) -> (old mask, kept alive; new mask)
    for key, values in part.items():
        if key.startswith("_"):
            continue
        values = np.asarray(values)
        if values.dtype.kind in "US":  # strings of any length (scenario names)
            values = values.astype(object)
        if key not in info:
            info[key] = np.zeros((num_envs, *values.shape[1:]), dtype=values.dtype)
            info["_" + key] = np.zeros(num_envs, dtype=bool)
        elif info[key].dtype != values.dtype and info[key].dtype != object:
            info[key] = info[key].astype(np.result_type(info[key], values))
        mask = part.get("_" + key)
        if mask is None:
            info[key][lanes] = values
            old = info["_" + key]
            if id(old) not in merged:
                new = old.copy()  # masks may be shared between keys: never written in place
                new[lanes] = True
                merged[id(old)] = (old, new)
            info["_" + key] = merged[id(old)][1]
        else:
            mask = np.asarray(mask, dtype=bool)
            info[key][lanes[mask]] = values[mask]
            new = info["_" + key].copy()
            new[lanes[mask]] = True
            info["_" + key] = new


def check_num_envs(num_envs) -> int:
    """``num_envs`` as an int >= 1 (``TypeError`` / ``ValueError`` naming it otherwise)."""
    if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)):
        raise TypeError(f"num_envs must be an integer >= 1, got {num_envs!r}")
    if num_envs < 1:
        raise ValueError(f"num_envs must be an integer >= 1, got {num_envs}")
    return int(num_envs)


class LaneVectorEnv(gym.vector.VectorEnv):
    """Base of the native vector envs (see the module docstring)."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}
    #: Name used in error messages (the single env's class name, say).
    env_name: str = "LaneVectorEnv"

    def __init__(
        self,
        num_envs: int,
        single_observation_space: gym.Space,
        single_action_space: gym.Space,
    ) -> None:
        self.num_envs = check_num_envs(num_envs)
        self.single_observation_space = single_observation_space
        self.single_action_space = single_action_space
        self.observation_space = batch_space(single_observation_space, self.num_envs)
        self.action_space = batch_space(single_action_space, self.num_envs)
        self.render_mode = None
        #: The step info's keys (as ``_step_lanes`` returns them) -> the masks every lane
        #: gets, worked out once per set of keys.
        self._mask_keys: dict[tuple, tuple] = {}
        self._every = np.ones(self.num_envs, dtype=bool)
        self.lane_rngs: list[np.random.Generator] = [
            seeding.np_random()[0] for _ in range(self.num_envs)
        ]
        self._started = False

    # ---- the VectorEnv interface ------------------------------------------------------------
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ):
        """Start a new episode in every lane; ``seed`` (int: lane ``i`` gets ``seed + i``;
        or one seed per lane) and ``options`` (e.g. ``{"scenario": ...}``) as for the single
        env."""
        if options is not None and not isinstance(options, dict):
            raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
        if seed is not None:
            if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
                seeds = [int(seed) + i for i in range(self.num_envs)]
            elif isinstance(seed, (list, tuple)) and len(seed) == self.num_envs:
                seeds = list(seed)
            else:
                raise ValueError(
                    f"seed must be None, an int or a list of {self.num_envs} seeds, got {seed!r}"
                )
            for i, s in enumerate(seeds):
                if s is not None:
                    self.lane_rngs[i] = seeding.np_random(s)[0]
        lanes = np.arange(self.num_envs)
        obs, part = self._reset_lanes(lanes, options)
        self._started = True
        if part is None:
            info = self._info_now()
            self._with_masks(info)
            return obs, info
        if isinstance(part, list):
            part = stack_lane_infos(part)
        info: dict = {}
        merge_lane_info(info, lanes, part, self.num_envs)
        return obs, info

    def _info_now(self) -> dict:
        """Every lane's info now, as new arrays (a key only some lanes hold comes with its
        ``_key`` mask): needed by a process whose ``_reset_lanes`` returns ``None``."""
        raise NotImplementedError(f"{type(self).__name__}: _reset_lanes returned no info")

    def _with_masks(self, info: dict) -> np.ndarray:
        """Add to ``info`` (a new dict) the mask of every lane for each key that has none:
        one array, shared by those keys, which is returned."""
        keys = tuple(info)
        masks = self._mask_keys.get(keys)
        if masks is None:
            masks = tuple("_" + k for k in keys if k[0] != "_" and "_" + k not in info)
            if len(self._mask_keys) >= 64:  # a few sets of keys occur; never let it grow
                self._mask_keys.clear()
            self._mask_keys[keys] = masks
        every = self._every.copy()  # a copy of a template: np.ones costs several times more
        info.update(dict.fromkeys(masks, every))
        return every

    def step(self, actions):
        if not self._started:
            raise RuntimeError(f"{self.env_name} (vector): call reset() before step()")
        shape = (self.num_envs, *self.single_action_space.shape)
        a = real_actions(actions, f"{self.env_name} (vector)")
        if a.shape != shape:
            if a.size == math.prod(shape):
                a = a.reshape(shape)
            else:
                raise ValueError(
                    f"{self.env_name} (vector): actions must have shape {shape}, got {a.shape}"
                )
        if not np.isfinite(a).all():
            finite = np.isfinite(a).reshape(self.num_envs, -1).all(axis=1)
            lane = int(np.flatnonzero(~finite)[0])
            raise ValueError(
                f"{self.env_name} (vector): the action of lane {lane} is {a[lane].tolist()} "
                "(not finite); no lane was stepped"
            )
        obs, reward, terminated, truncated, info = self._step_lanes(a)
        every = self._with_masks(info)  # _step_lanes' dict is new at every step
        done = np.logical_or(terminated, truncated)
        if not done.any():
            return obs, reward, terminated, truncated, info
        lanes = np.flatnonzero(done)
        final_obs = np.full(self.num_envs, None, dtype=object)
        for i in lanes.tolist():
            final_obs[i] = obs[i].copy()
        # The step's info arrays are the final info; _reset_lanes does not write to them.
        new_obs, part = self._reset_lanes(lanes, None)
        obs = obs.copy()
        obs[lanes] = new_obs
        final_info: dict = {}
        if part is None:  # the lanes hold their reset info: every lane's info read again
            for k, v in info.items():
                if k[0] != "_":
                    mask = info["_" + k]
                    final_info[k], final_info["_" + k] = v, done if mask is every else mask & done
            top = self._info_now()
            self._with_masks(top)
            top["final_obs"], top["_final_obs"] = final_obs, done.copy()
            top["final_info"], top["_final_info"] = final_info, done.copy()
            return obs, reward, terminated, truncated, top
        top: dict = {}
        kept = ~done
        for k, v in info.items():
            if k[0] == "_":
                continue
            mask = info["_" + k]
            if mask is every:  # the keys of every lane share their masks, as above
                final_info[k], final_info["_" + k] = v, done
                top[k], top["_" + k] = v.copy(), kept
            else:
                final_info[k], final_info["_" + k] = v, mask & done
                top[k], top["_" + k] = v.copy(), mask & kept
        if isinstance(part, list):
            part = _write_lane_infos(top, lanes.tolist(), part, kept, every)
        rest = {}
        for k, new in part.items():
            if (
                top.get("_" + k) is kept  # every other lane holds the key
                and type(new) is np.ndarray
                and new.dtype == top[k].dtype
                and "_" + k not in part
            ):  # the common case, written straight in: then every lane holds it
                top[k][lanes] = new
                top["_" + k] = every
            else:
                rest[k] = new
        merge_lane_info(top, lanes, rest, self.num_envs)
        top["final_obs"], top["_final_obs"] = final_obs, done.copy()
        top["final_info"], top["_final_info"] = final_info, done.copy()
        return obs, reward, terminated, truncated, top

    def close_extras(self, **kwargs) -> None:
        return None
