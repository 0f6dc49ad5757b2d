"""VecNormalize statistics as JSON: a file that cannot run code when it is read.

SB3's ``VecNormalize.save`` pickles the whole wrapper, and unpickling a file runs whatever
code it names; so the library writes the statistics a policy needs (``*_vecnormalize.json``
beside ``*_model.zip``) with :func:`save_stats` and reads them back with :func:`read_stats`,
which accepts nothing but numbers of the right shapes. (SB3's model ``.zip`` files
themselves still unpickle parts of their content when loaded: load models only from
sources you trust.)
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agents.rl.files import read_json_object

__all__ = [
    "NormStats",
    "save_stats",
    "read_stats",
    "restore_stats",
    "stats_path",
    "convert_pickle",
]

FORMAT = "machining_envs/vecnormalize-1"


@dataclass(frozen=True)
class NormStats:
    """What VecNormalize needs to normalise as it did in training."""

    norm_obs: bool
    norm_reward: bool
    clip_obs: float
    clip_reward: float
    gamma: float
    epsilon: float
    obs_mean: np.ndarray
    obs_var: np.ndarray
    obs_count: float
    ret_mean: float
    ret_var: float
    ret_count: float


def stats_path(model_path) -> Path:
    """The statistics file of a model: ``best_model.zip`` -> ``best_vecnormalize.json``,
    ``rl_model_100_steps.zip`` -> ``rl_model_vecnormalize_100_steps.json``."""
    model_path = Path(model_path)
    stem = model_path.stem
    name = stem.replace("rl_model_", "rl_model_vecnormalize_", 1)
    if name == stem:
        name = stem.replace("model", "vecnormalize")
    return model_path.with_name(name + ".json")


def save_stats(venv, path) -> Path:
    """Write the statistics of a ``VecNormalize`` to ``path`` (JSON)."""
    data = {
        "format": FORMAT,
        "norm_obs": bool(venv.norm_obs),
        "norm_reward": bool(venv.norm_reward),
        "clip_obs": float(venv.clip_obs),
        "clip_reward": float(venv.clip_reward),
        "gamma": float(venv.gamma),
        "epsilon": float(venv.epsilon),
        "obs_mean": np.asarray(venv.obs_rms.mean, dtype=np.float64).tolist(),
        "obs_var": np.asarray(venv.obs_rms.var, dtype=np.float64).tolist(),
        "obs_count": float(venv.obs_rms.count),
        "ret_mean": float(np.asarray(venv.ret_rms.mean).reshape(-1)[0]),
        "ret_var": float(np.asarray(venv.ret_rms.var).reshape(-1)[0]),
        "ret_count": float(venv.ret_rms.count),
    }
    path = Path(path)
    path.write_text(json.dumps(data, indent=1))
    return path


def _number(path, key, value, lo=-math.inf, lo_open=False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{path}: {key} must be a finite number, got {value!r}")
    if value < lo or (lo_open and value == lo):
        raise ValueError(f"{path}: {key} must be {'>' if lo_open else '>='} {lo}, got {value}")
    return float(value)


def read_stats(path) -> NormStats:
    """Read statistics written by :func:`save_stats`; ``ValueError`` naming the file and the
    field for anything else (a binary file, a mean or a variance that is not finite, a
    variance that is not > 0). Whether they fit a model is the reader's check
    (``agents.rl.load_policy``: their length against the model's observations)."""
    path = Path(path)
    data = read_json_object(path, "statistics file")
    if data.get("format") != FORMAT:
        raise ValueError(f"{path}: not a statistics file (format must be {FORMAT!r})")
    flags = {}
    for key in ("norm_obs", "norm_reward"):
        if not isinstance(data.get(key), bool):
            raise ValueError(f"{path}: {key} must be true or false, got {data.get(key)!r}")
        flags[key] = data[key]
    vectors = {}
    for key in ("obs_mean", "obs_var"):
        v = data.get(key)
        if not isinstance(v, list) or not v:
            raise ValueError(f"{path}: {key} must be a list of numbers")
        vectors[key] = np.array([_number(path, f"{key}[{i}]", x) for i, x in enumerate(v)])
    if vectors["obs_mean"].shape != vectors["obs_var"].shape:
        raise ValueError(f"{path}: obs_mean and obs_var must have the same length")
    if not np.all(vectors["obs_var"] > 0):  # VecNormalize's start at 1 and stay > 0
        i = int(np.flatnonzero(~(vectors["obs_var"] > 0))[0])
        raise ValueError(f"{path}: obs_var must be > 0, got obs_var[{i}] = {vectors['obs_var'][i]}")
    return NormStats(
        **flags,
        clip_obs=_number(path, "clip_obs", data.get("clip_obs"), 0.0, lo_open=True),
        clip_reward=_number(path, "clip_reward", data.get("clip_reward"), 0.0, lo_open=True),
        gamma=_number(path, "gamma", data.get("gamma"), 0.0),
        epsilon=_number(path, "epsilon", data.get("epsilon"), 0.0, lo_open=True),
        obs_mean=vectors["obs_mean"],
        obs_var=vectors["obs_var"],
        obs_count=_number(path, "obs_count", data.get("obs_count"), 0.0),
        ret_mean=_number(path, "ret_mean", data.get("ret_mean")),
        ret_var=_number(path, "ret_var", data.get("ret_var"), 0.0),
        ret_count=_number(path, "ret_count", data.get("ret_count"), 0.0),
    )


def restore_stats(venv, stats: NormStats) -> None:
    """Set a ``VecNormalize``'s statistics and settings to ``stats`` (to resume training)."""
    shape = tuple(venv.obs_rms.mean.shape)
    if stats.obs_mean.shape != shape:
        raise ValueError(
            f"the statistics are for observations of shape {stats.obs_mean.shape}, "
            f"the env's are {shape}"
        )
    venv.norm_obs, venv.norm_reward = stats.norm_obs, stats.norm_reward
    venv.clip_obs, venv.clip_reward = stats.clip_obs, stats.clip_reward
    venv.gamma, venv.epsilon = stats.gamma, stats.epsilon
    venv.obs_rms.mean = stats.obs_mean.copy()
    venv.obs_rms.var = stats.obs_var.copy()
    venv.obs_rms.count = stats.obs_count
    venv.ret_rms.mean = np.float64(stats.ret_mean)
    venv.ret_rms.var = np.float64(stats.ret_var)
    venv.ret_rms.count = stats.ret_count


def convert_pickle(path) -> Path:
    """Write the JSON statistics of a pickled ``VecNormalize`` (``VecNormalize.save``) beside
    it. Reading the pickle runs any code it names: only for files you trust."""
    import pickle

    path = Path(path)
    with open(path, "rb") as fh:
        venv = pickle.load(fh)  # the caller vouches for the file
    return save_stats(venv, path.with_suffix(".json"))
