"""Training configurations: the YAML files in ``agents/rl/configs/``, read and checked before
any training starts (see ``agents.rl``).

The files are rl-zoo3's hyperparameter files, so ``python -m rl_zoo3.train --conf-file`` runs
them unmodified: one entry per env id with rl-zoo3's keys (``policy``, ``n_timesteps``,
``n_envs``, ``normalize``, ``env_kwargs``, ``env_wrapper``, ``callback``, ``policy_kwargs``)
and the algorithm's keywords. ``env_wrapper`` may name one of
``machining_envs.wrappers.IncrementalAction`` (with ``max_step``, ``hide_action`` and
``hide_fields``) and
``agents.rl.residual.SetpointResidual`` (the policy moves a tuned classical agent's setting);
``callback`` names ``agents.rl.callbacks.ValidationCallback`` (the evaluation on the
``validation`` split: its ``eval_freq``, ``n_episodes``, ``scenarios``,
``checkpoint_freq``) and any other SB3 callback by import path. rl-zoo3's value syntax is
read too: ``!!float 1e6`` counts, ``lin_<x>`` schedules, and ``"dict(...)"`` strings for
``policy_kwargs`` and ``normalize`` (parsed as literals, never evaluated; ``nn.<Name>``
stands for ``torch.nn.<Name>``). The older keys of ours (``eval_freq``, ``eval_episodes``,
``eval_scenarios``, ``checkpoint_freq``, ``action_increment``, ``hide_action``) are still
read.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from pathlib import Path

from agents.rl.algos import ALGOS, algorithm_classes
from agents.rl.files import read_utf8

__all__ = ["ALGOS", "CONFIG_DIR", "ConfigError", "TrainConfig", "load_config", "source_label"]

CONFIG_DIR = Path(__file__).resolve().parent / "configs"


def source_label(path) -> str:
    """How a run's record (``config.json``) names the config file ``path``: a shipped one as
    ``agents/rl/configs/<name>`` wherever the package is installed, another by its path
    relative to the working directory where it lies below it, else by its absolute path
    (never a path of the machine that trained, for the shipped files)."""
    p = Path(path).resolve()
    for root, label in ((CONFIG_DIR, Path("agents/rl/configs")), (Path.cwd().resolve(), Path())):
        if p.is_relative_to(root):
            return (label / p.relative_to(root)).as_posix()
    return str(p)


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
    "callback": (str, list),
    "env_wrapper": (str, list),
    "noise_type": (str,),
    "noise_std": (float, int),
}
#: rl-zoo3's exploration noise of the off-policy algorithms (``noise_type``, ``noise_std``).
NOISE_TYPES = ("normal", "ornstein-uhlenbeck")
#: The names ``callback`` and ``env_wrapper`` entries may give our own classes by.
VALIDATION_CALLBACK = "agents.rl.callbacks.ValidationCallback"
INCREMENT_WRAPPER = "machining_envs.wrappers.IncrementalAction"
RESIDUAL_WRAPPER = "agents.rl.residual.SetpointResidual"
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
    eval_allowances: list | None = None
    """The allowances the best model is chosen at (``ValidationCallback``'s ``allowances``;
    None: the score's own, 2 %)."""
    eval_first_episode: int = 0
    """The first validation episode the best model is chosen on (``ValidationCallback``'s
    ``first_episode``)."""
    action_increment: float | None = None
    """If set, the policy outputs a change of the env's action of at most this much per step
    (``machining_envs.wrappers.IncrementalAction``); the saved policy applies it by itself."""
    hide_action: bool = False
    """With ``action_increment``: the policy does not see the action now applied."""
    hide_fields: tuple[str, ...] = ()
    """With ``action_increment``: observation fields the policy sees as 0, by name
    (``IncrementalAction``'s ``hide_fields``)."""
    noise_type: str | None = None
    """Exploration noise added to the actions of SAC and TD3 (rl-zoo3's key): ``"normal"``
    or ``"ornstein-uhlenbeck"``, of standard deviation ``noise_std`` in action units."""
    noise_std: float = 0.1
    hyperparams: dict = field(default_factory=dict)
    callbacks: list = field(default_factory=list)
    """Other SB3 callbacks named in ``callback``: ``(class, keywords)`` pairs."""
    residual: dict | None = None
    """``env_wrapper: SetpointResidual``: the ``ResidualSpec`` fields (the policy sets the
    setpoint of a classical regulator; ``agents.rl.residual``)."""
    source: str = ""
    """The file the entry was read from (:func:`source_label`)."""


def _check_type(where: str, key: str, value, types: tuple[type, ...]) -> None:
    ok = isinstance(value, types) and not (isinstance(value, bool) and bool not in types)
    if not ok:
        names = " or ".join(t.__name__ for t in types)
        raise ConfigError(f"{where}: {key} must be {names}, got {type(value).__name__} {value!r}")


def _entries(where: str, key: str, value) -> list[tuple[str, dict]]:
    """rl-zoo3's list form of ``callback`` / ``env_wrapper``: a name, or a list of names and
    one-key mappings ``{name: {keyword: value}}``."""
    out = []
    for item in value if isinstance(value, list) else [value]:
        if isinstance(item, str):
            out.append((item, {}))
        elif isinstance(item, dict) and len(item) == 1:
            ((name, kwargs),) = item.items()
            kwargs = {} if kwargs is None else kwargs
            if not isinstance(name, str) or not isinstance(kwargs, dict):
                raise ConfigError(f"{where}: {key}: {item!r} must map a name to its keywords")
            out.append((name, dict(kwargs)))
        else:
            raise ConfigError(
                f"{where}: {key} entries must be names or {{name: {{keyword: value}}}}, got {item!r}"
            )
    return out


def _import(where: str, key: str, name: str):
    import importlib

    module, _, attr = name.rpartition(".")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError, ValueError):
        raise ConfigError(f"{where}: {key}: cannot import {name!r}") from None


def _read_callbacks(where: str, value, cfg: TrainConfig) -> None:
    """``callback``: the ValidationCallback's keywords become the run's evaluation settings;
    any other name must be an SB3 callback class, made with its keywords at training."""
    import inspect as _inspect

    from stable_baselines3.common.callbacks import BaseCallback

    for name, kwargs in _entries(where, "callback", value):
        if name in (VALIDATION_CALLBACK, "ValidationCallback"):
            from agents.rl.callbacks import ValidationCallback

            allowed = set(_inspect.signature(ValidationCallback.__init__).parameters) - {"self"}
            bad = set(kwargs) - allowed
            if bad:
                raise ConfigError(
                    f"{where}: callback {name}: unknown keywords {sorted(bad)}; allowed {sorted(allowed)}"
                )
            try:
                cb = ValidationCallback(**kwargs)
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"{where}: callback {name}: {exc}") from None
            cfg.eval_freq, cfg.eval_episodes = cb.eval_freq, cb.n_episodes
            cfg.eval_scenarios = cb.scenarios
            cfg.eval_allowances = cb.allowances
            cfg.eval_first_episode = cb.first_episode
            if cb.checkpoint_freq is not None:
                cfg.checkpoint_freq = cb.checkpoint_freq
        else:
            cls = _import(where, "callback", name)
            if not (isinstance(cls, type) and issubclass(cls, BaseCallback)):
                raise ConfigError(f"{where}: callback: {name} is not an SB3 callback class")
            try:
                _inspect.signature(cls).bind(**kwargs)
            except TypeError as exc:
                raise ConfigError(f"{where}: callback {name}: {exc}") from None
            cfg.callbacks.append((cls, kwargs))


def _read_wrappers(where: str, value, cfg: TrainConfig) -> None:
    """``env_wrapper``: ``IncrementalAction`` or ``SetpointResidual`` (the native vector envs
    run no gymnasium wrappers, and a policy's wrapper must be known to replay it outside
    training)."""
    entries = _entries(where, "env_wrapper", value)
    if len(entries) > 1:
        raise ConfigError(f"{where}: env_wrapper: one wrapper at most, got {len(entries)}")
    for name, kwargs in entries:
        if name in (RESIDUAL_WRAPPER, "SetpointResidual"):
            from agents.rl.residual import ResidualSpec

            try:
                cfg.residual = ResidualSpec(**kwargs).checked()._asdict()
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"{where}: env_wrapper {name}: {exc}") from None
            continue
        if name not in (INCREMENT_WRAPPER, "IncrementalAction"):
            raise ConfigError(
                f"{where}: env_wrapper: machining-bench train applies {INCREMENT_WRAPPER} or "
                f"{RESIDUAL_WRAPPER}, got {name!r}"
            )
        bad = set(kwargs) - {"max_step", "hide_action", "hide_fields"}
        if bad:
            raise ConfigError(
                f"{where}: env_wrapper {name}: unknown keywords {sorted(bad)}; "
                "allowed ['hide_action', 'hide_fields', 'max_step']"
            )
        if "max_step" not in kwargs:
            raise ConfigError(f"{where}: env_wrapper {name}: max_step is required")
        _check_type(where, "max_step", kwargs["max_step"], (float, int))
        cfg.action_increment = kwargs["max_step"]
        hide = kwargs.get("hide_action", False)
        _check_type(where, "hide_action", hide, (bool,))
        cfg.hide_action = hide
        fields = kwargs.get("hide_fields", [])
        if not (isinstance(fields, list) and all(isinstance(f, str) for f in fields)):
            raise ConfigError(
                f"{where}: env_wrapper {name}: hide_fields must be a list of observation "
                f"field names, got {fields!r}"
            )
        cfg.hide_fields = tuple(fields)


def _literal(where: str, key: str, text: str):
    """rl-zoo3 writes some values as Python source (``"dict(net_arch=[64, 64])"``), which it
    evaluates. Here it is parsed: literals, ``dict(...)`` with keyword arguments, and
    ``nn.<Name>`` / ``torch.nn.<Name>`` (torch's layer classes); anything else is refused."""
    import ast

    try:
        tree = ast.parse(text.strip(), mode="eval").body
    except SyntaxError:
        raise ConfigError(f"{where}: {key}: cannot read {text!r}") from None

    def value(node):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id == "dict"
        ):
            if node.args or any(k.arg is None for k in node.keywords):
                raise ConfigError(f"{where}: {key}: dict(...) takes keyword arguments only")
            return {k.arg: value(k.value) for k in node.keywords}
        if isinstance(node, ast.Attribute):
            parts = []
            n = node
            while isinstance(n, ast.Attribute):
                parts.append(n.attr)
                n = n.value
            if isinstance(n, ast.Name):
                parts.append(n.id)
            path = ".".join(reversed(parts))
            for prefix in ("torch.nn.", "th.nn.", "nn."):
                if path.startswith(prefix) and path.count(".") == prefix.count("."):
                    import torch

                    layer = getattr(torch.nn, path[len(prefix) :], None)
                    if isinstance(layer, type):
                        return layer
            raise ConfigError(f"{where}: {key}: unknown name {path!r} in {text!r}")
        if isinstance(node, ast.Dict):
            return {value(k): value(v) for k, v in zip(node.keys, node.values, strict=True)}
        if isinstance(node, (ast.List, ast.Tuple)):
            items = [value(e) for e in node.elts]
            return items if isinstance(node, ast.List) else tuple(items)
        if isinstance(node, ast.Name) and node.id in ("True", "False", "None"):
            return {"True": True, "False": False, "None": None}[node.id]
        try:
            return ast.literal_eval(node)
        except ValueError:
            raise ConfigError(f"{where}: {key}: cannot read {text!r} (literals only)") from None

    return value(tree)


def load_config(env_id: str, algo: str, path=None, overrides: dict | None = None) -> TrainConfig:
    """Read and validate the configuration of ``algo`` on ``env_id``.

    ``path`` defaults to ``agents/rl/configs/<algo>.yml``. ``overrides`` replaces keys of the
    entry (a sweep's sampled hyperparameters) before the checks. Raises ``ConfigError`` (a
    ``ValueError``) for a missing file or entry, an unknown key, or a wrong type.
    """
    import yaml

    algo = algo.lower()
    if algo not in ALGOS:
        raise ConfigError(f"algo must be one of {list(ALGOS)}, got {algo!r}")
    path = Path(path) if path is not None else CONFIG_DIR / f"{algo}.yml"
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    text = read_utf8(path, "configuration file", ConfigError)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict) or env_id not in data:
        known = sorted(data) if isinstance(data, dict) else []
        raise ConfigError(f"{path}: no entry for {env_id!r} (entries: {known})")
    entry = data[env_id]
    if not isinstance(entry, dict):
        raise ConfigError(f"{path}: the entry for {env_id!r} must be a mapping")
    where = f"{path}:{env_id}"
    if overrides:
        if not isinstance(overrides, dict):
            raise ConfigError(f"overrides must be a mapping, got {type(overrides).__name__}")
        entry = {**entry, **overrides}
        where += f" with {sorted(overrides)} replaced"
    algo_params = set(inspect.signature(algorithm_classes()[algo].__init__).parameters) - {
        "self",
        "policy",
        "env",
    }
    cfg = TrainConfig(env_id=env_id, algo=algo, source=source_label(path))
    hyper = {}
    for key, value in entry.items():
        if key in ("policy_kwargs", "normalize") and isinstance(value, str):
            value = _literal(where, key, value)
        if key == "callback":
            _read_callbacks(where, value, cfg)
        elif key == "env_wrapper":
            _read_wrappers(where, value, cfg)
        elif key in _SETTINGS:
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
    if cfg.noise_type is not None:
        if cfg.noise_type not in NOISE_TYPES:
            raise ConfigError(
                f"{where}: noise_type must be one of {list(NOISE_TYPES)}, got {cfg.noise_type!r}"
            )
        if cfg.algo == "ppo":
            raise ConfigError(f"{where}: noise_type is for SAC and TD3; PPO samples its actions")
    cfg.noise_std = _in_range(where, "noise_std", cfg.noise_std, 0.0, 10.0, True, False)
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
    aliases = sorted(getattr(algorithm_classes()[algo], "policy_aliases", {}))
    if aliases and cfg.policy not in aliases:
        raise ConfigError(f"{where}: policy must be one of {aliases}, got {cfg.policy!r}")
    if "policy_kwargs" in hyper:
        _check_type(where, "policy_kwargs", hyper["policy_kwargs"], (dict,))
        bad = [k for k in hyper["policy_kwargs"] if not isinstance(k, str)]
        if bad:
            raise ConfigError(f"{where}: policy_kwargs keys must be names, got {bad[0]!r}")
    cfg.hyperparams = hyper
    return cfg
