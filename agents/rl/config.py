"""Training configurations: the YAML files in ``agents/rl/configs/`` (rl-zoo3 layout), read
and checked before any training starts (see ``agents.rl``)."""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["ALGOS", "CONFIG_DIR", "ConfigError", "TrainConfig", "load_config"]

CONFIG_DIR = Path(__file__).resolve().parent / "configs"


def _algos():
    from stable_baselines3 import PPO, SAC, TD3

    return {"ppo": PPO, "sac": SAC, "td3": TD3}


ALGOS = ("ppo", "sac", "td3")


class ConfigError(ValueError):
    """A configuration file or entry that cannot be used; raised before training starts."""


# Settings of ours (not algorithm keywords), with their types.
_SETTINGS: dict[str, tuple[type, ...]] = {
    "n_timesteps": (int,),
    "n_envs": (int,),
    "policy": (str,),
    "normalize": (bool, dict),
    "env_kwargs": (dict,),
    "eval_freq": (int,),
    "eval_episodes": (int,),
    "eval_scenarios": (list,),
    "checkpoint_freq": (int,),
    "action_increment": (float, int),
    "hide_action": (bool,),
}
_NORMALIZE_KEYS = {"norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon"}


@dataclass
class TrainConfig:
    """A resolved training configuration (see the module docstring for the file layout)."""

    env_id: str
    algo: str
    n_timesteps: int = 100_000
    n_envs: int = 4
    policy: str = "MlpPolicy"
    normalize: bool | dict = True
    env_kwargs: dict = field(default_factory=dict)
    eval_freq: int = 10_000
    eval_episodes: int = 10
    eval_scenarios: list = field(default_factory=lambda: ["test"])
    checkpoint_freq: int = 20_000
    action_increment: float | None = None
    """If set, the policy outputs a change of the env's action of at most this much per step
    (``machining_envs.wrappers.IncrementalAction``); the saved policy applies it by itself."""
    hide_action: bool = False
    """With ``action_increment``: the policy does not see the action now applied."""
    hyperparams: dict = field(default_factory=dict)
    source: str = ""


def _check_type(where: str, key: str, value, types: tuple[type, ...]) -> None:
    ok = isinstance(value, types) and not (isinstance(value, bool) and bool not in types)
    if not ok:
        names = " or ".join(t.__name__ for t in types)
        raise ConfigError(f"{where}: {key} must be {names}, got {type(value).__name__} {value!r}")


def load_config(env_id: str, algo: str, path=None) -> TrainConfig:
    """Read and validate the configuration of ``algo`` on ``env_id``.

    ``path`` defaults to ``agents/rl/configs/<algo>.yml``. Raises ``ConfigError`` (a
    ``ValueError``) for a missing file or entry, an unknown key, or a wrong type.
    """
    import yaml

    algo = algo.lower()
    if algo not in ALGOS:
        raise ConfigError(f"algo must be one of {list(ALGOS)}, got {algo!r}")
    path = Path(path) if path is not None else CONFIG_DIR / f"{algo}.yml"
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict) or env_id not in data:
        known = sorted(data) if isinstance(data, dict) else []
        raise ConfigError(f"{path}: no entry for {env_id!r} (entries: {known})")
    entry = data[env_id]
    if not isinstance(entry, dict):
        raise ConfigError(f"{path}: the entry for {env_id!r} must be a mapping")
    where = f"{path}:{env_id}"
    algo_params = set(inspect.signature(_algos()[algo].__init__).parameters) - {
        "self",
        "policy",
        "env",
    }
    cfg = TrainConfig(env_id=env_id, algo=algo, source=str(path))
    hyper = {}
    for key, value in entry.items():
        if key in _SETTINGS:
            _check_type(where, key, value, _SETTINGS[key])
            setattr(cfg, key, value)
        elif key in algo_params:
            hyper[key] = value
        else:
            import difflib

            close = difflib.get_close_matches(key, [*_SETTINGS, *algo_params], n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ConfigError(f"{where}: unknown key {key!r}{hint}")
    for key in ("n_timesteps", "n_envs", "eval_freq", "eval_episodes", "checkpoint_freq"):
        if getattr(cfg, key) < 1:
            raise ConfigError(f"{where}: {key} must be >= 1, got {getattr(cfg, key)}")
    if cfg.action_increment is not None:
        cfg.action_increment = float(cfg.action_increment)
        if not 0.0 < cfg.action_increment <= 2.0:
            raise ConfigError(
                f"{where}: action_increment must be in (0, 2], got {cfg.action_increment}"
            )
    if cfg.hide_action and cfg.action_increment is None:
        raise ConfigError(f"{where}: hide_action needs action_increment")
    if isinstance(cfg.normalize, dict):
        bad = set(cfg.normalize) - _NORMALIZE_KEYS
        if bad:
            raise ConfigError(
                f"{where}: unknown normalize keys {sorted(bad)}; allowed {sorted(_NORMALIZE_KEYS)}"
            )
    for key in ("learning_rate", "gamma", "ent_coef", "clip_range", "tau"):
        if key in hyper and not isinstance(hyper[key], (int, float, str)):
            _check_type(where, key, hyper[key], (float,))
    for key in (
        "n_steps",
        "batch_size",
        "n_epochs",
        "buffer_size",
        "learning_starts",
        "train_freq",
    ):
        if key in hyper:
            _check_type(where, key, hyper[key], (int,) if key != "train_freq" else (int, list))
    if "policy_kwargs" in hyper:
        _check_type(where, "policy_kwargs", hyper["policy_kwargs"], (dict,))
    cfg.hyperparams = hyper
    return cfg
