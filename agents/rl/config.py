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

_INF = float("inf")
#: Ranges of the algorithms' numeric keywords that SB3 needs (checked before training):
#: key -> (lo, hi, lo open, integer). A schedule ``"lin_<x>"`` (rl-zoo3's syntax) is
#: checked on ``x`` for the keys that take one.
_HYPER_RANGES: dict[str, tuple[float, float, bool, bool]] = {
    "learning_rate": (0.0, 1.0, True, False),
    "gamma": (0.0, 1.0, True, False),
    "gae_lambda": (0.0, 1.0, False, False),
    "clip_range": (0.0, _INF, True, False),
    "ent_coef": (0.0, _INF, False, False),
    "vf_coef": (0.0, _INF, False, False),
    "max_grad_norm": (0.0, _INF, True, False),
    "tau": (0.0, 1.0, True, False),
    "target_policy_noise": (0.0, _INF, False, False),
    "target_noise_clip": (0.0, _INF, False, False),
    "n_steps": (1, _INF, False, True),
    "batch_size": (1, _INF, False, True),
    "n_epochs": (1, _INF, False, True),
    "buffer_size": (1, _INF, False, True),
    "learning_starts": (0, _INF, False, True),
    "policy_delay": (1, _INF, False, True),
}
_SCHEDULE_KEYS = ("learning_rate", "clip_range")
#: Ranges of the ``normalize`` mapping's numbers (VecNormalize's keywords).
_NORMALIZE_RANGES = {
    "clip_obs": (0.0, _INF, True),
    "clip_reward": (0.0, _INF, True),
    "gamma": (0.0, 1.0, True),
    "epsilon": (0.0, 1.0, True),
}


def _in_range(where: str, key: str, value, lo, hi, lo_open: bool, integer: bool):
    """``value`` if it is a number in the range (integer where asked), else ConfigError."""
    is_num = isinstance(value, (int, float)) and not isinstance(value, bool)
    if integer and is_num and isinstance(value, float) and value.is_integer():
        value = int(value)  # rl-zoo3 writes large counts as !!float 1e6
    ok = is_num and (not integer or isinstance(value, int)) and value == value
    ok = ok and (value > lo if lo_open else value >= lo) and value <= hi
    if not ok:
        kind = "an integer" if integer else "a number"
        bounds = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
        raise ConfigError(f"{where}: {key} must be {kind} in {bounds}, got {value!r}")
    return value


def _schedule(where: str, key: str, value):
    """A constant or rl-zoo3's linear schedule ``"lin_<x>"`` (x at the start, 0 at the end)."""
    if isinstance(value, str):
        if not value.startswith("lin_"):
            raise ConfigError(
                f"{where}: {key} must be a number or a linear schedule 'lin_<x>', got {value!r}"
            )
        try:
            start = float(value[4:])
        except ValueError:
            raise ConfigError(f"{where}: {key}: cannot read the number in {value!r}") from None
        lo, hi, lo_open, _ = _HYPER_RANGES[key]
        start = _in_range(where, key, start, lo, hi, lo_open, False)
        return LinearSchedule(start)
    lo, hi, lo_open, integer = _HYPER_RANGES[key]
    return _in_range(where, key, value, lo, hi, lo_open, integer)


@dataclass(frozen=True)
class LinearSchedule:
    """rl-zoo3's ``lin_<x>``: ``x`` times the share of training left (SB3 calls it with
    ``progress_remaining``, 1 at the start and 0 at the end)."""

    start: float

    def __call__(self, progress_remaining: float) -> float:
        return progress_remaining * self.start


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
    eval_scenarios: list = field(default_factory=lambda: ["validation"])
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
            if _SETTINGS[key] == (int,) and isinstance(value, float) and value.is_integer():
                value = int(value)  # rl-zoo3 writes large counts as !!float 1e6
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
    if isinstance(cfg.normalize, dict):
        for key, value in cfg.normalize.items():
            if key in _NORMALIZE_RANGES:
                lo, hi, lo_open = _NORMALIZE_RANGES[key]
                _in_range(where, f"normalize.{key}", value, lo, hi, lo_open, False)
            else:
                _check_type(where, f"normalize.{key}", value, (bool,))
    for key, value in hyper.items():
        if key in _SCHEDULE_KEYS:
            hyper[key] = _schedule(where, key, value)
        elif key == "ent_coef" and isinstance(value, str):
            if not (value == "auto" or value.startswith("auto_")):
                raise ConfigError(
                    f"{where}: ent_coef must be a number >= 0 or 'auto', got {value!r}"
                )
        elif key in _HYPER_RANGES:
            lo, hi, lo_open, integer = _HYPER_RANGES[key]
            hyper[key] = _in_range(where, key, value, lo, hi, lo_open, integer)
    if "train_freq" in hyper:
        tf = hyper["train_freq"]
        ok = (isinstance(tf, int) and not isinstance(tf, bool) and tf >= 1) or (
            isinstance(tf, list)
            and len(tf) == 2
            and isinstance(tf[0], int)
            and tf[0] >= 1
            and tf[1] in ("step", "episode")
        )
        if not ok:
            raise ConfigError(
                f"{where}: train_freq must be an integer >= 1 or [n, 'step' | 'episode'], got {tf!r}"
            )
        if isinstance(tf, list):
            hyper["train_freq"] = tuple(tf)
    if cfg.algo == "ppo":
        rollout = hyper.get("n_steps", 2048) * cfg.n_envs
        if rollout < 2:
            raise ConfigError(f"{where}: n_steps x n_envs must be > 1 for PPO, got {rollout}")
        if hyper.get("batch_size", 64) > rollout:
            raise ConfigError(
                f"{where}: batch_size must be <= n_steps x n_envs = {rollout}, "
                f"got {hyper['batch_size']}"
            )
    if "policy_kwargs" in hyper:
        _check_type(where, "policy_kwargs", hyper["policy_kwargs"], (dict,))
    cfg.hyperparams = hyper
    return cfg
