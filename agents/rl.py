"""Training, saving and loading Stable-Baselines3 policies on the machining envs.

Hyperparameters live in YAML files in ``agents/configs/`` laid out like rl-zoo3's: one file per
algorithm (``ppo.yml``, ``sac.yml``, ``td3.yml``), one top-level key per env id, and under it the
training settings (``n_timesteps``, ``n_envs``, ``policy``, ``normalize``, ``env_kwargs``,
``eval_freq``, ``eval_episodes``, ``eval_scenarios``, ``checkpoint_freq``, ``action_increment``,
``hide_action``) and any keyword of the algorithm's constructor (``learning_rate``, ``n_steps``,
``policy_kwargs``, ...). Unknown keys and wrong types are rejected before any training starts.

A run folder holds everything needed to reload or continue it::

    run/
      config.json            the resolved configuration, seed and command
      final_model.zip        the model at the end   (+ final_vecnormalize.pkl)
      best_model.zip         the best on the held-out evaluation (+ best_vecnormalize.pkl)
      checkpoints/           periodic model + VecNormalize snapshots (for --resume)
      eval.csv               the held-out evaluations made during training
      tb/                    TensorBoard logs

>>> from agents.rl import load_config
>>> cfg = load_config("machining_envs/Turning-v0", "ppo")
>>> cfg.algo, cfg.n_envs > 0, "learning_rate" in cfg.hyperparams
('ppo', True, True)
"""

from __future__ import annotations

import csv
import inspect
import json
import math
import re
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np

import machining_envs  # noqa: F401  (registers the env ids)
from agents.harness import Evaluation, evaluate
from agents.scores import REGULATION_SCORE, PrimaryScore

__all__ = [
    "ALGOS",
    "CONFIG_DIR",
    "ConfigError",
    "TrainConfig",
    "load_config",
    "train",
    "PolicyAgent",
    "load_policy",
    "primary_score",
    "FAILED_EPISODE_TIME_S",
    "pretrained",
    "PRETRAINED_DIR",
]

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

    ``path`` defaults to ``agents/configs/<algo>.yml``. Raises ``ConfigError`` (a
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


#: What an episode that does not count costs in the primary score, s: Turning-v0's time
#: limit, i.e. the cut is charged as if it had used the whole budget.
FAILED_EPISODE_TIME_S = 200.0


def primary_score(rows: list[dict], failed_time_s: float = FAILED_EPISODE_TIME_S) -> dict:
    """The primary score of a set of regulation episodes (Turning-v0, EndMilling-v0).

    An episode *counts* if it finished the workpiece, the tool did not break, and the
    regulated signal spent under 2 % of the time above 1.1x its reference. Score: mean
    machining time (s, lower is better) with every episode that does not count charged
    ``failed_time_s``, so no policy can win by breaking the constraint. Returns ``score``,
    ``valid`` (share of episodes that counted) and ``itae`` (mean) for the table. The other
    envs' scores are in ``agents.scores``.
    """
    return REGULATION_SCORE(rows, failed_time_s)


class PolicyAgent:
    """An SB3 model with its VecNormalize statistics, behind the agent protocol.

    Normalises each observation with the frozen statistics, then calls the model's
    ``predict``; so the harness and SB3's ``evaluate_policy`` on raw envs both work. A policy
    trained with ``action_increment`` (``increment``, a
    ``machining_envs.wrappers.ActionIncrement``) outputs a change of the action; ``predict`` shows it what the wrapper showed it in
    training and turns its output into the env's action from the raw observation
    (``IncrementalAction``), so it runs on the plain env.
    """

    def __init__(
        self,
        model,
        obs_rms=None,
        clip_obs: float = 10.0,
        epsilon: float = 1e-8,
        name: str | None = None,
        increment=None,
    ):
        self.model = model
        self.obs_rms = obs_rms
        self.clip_obs = clip_obs
        self.epsilon = epsilon
        self.name = name or f"{type(model).__name__} policy"
        self.increment = increment

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        if self.obs_rms is None:
            return obs
        out = (obs - self.obs_rms.mean) / np.sqrt(self.obs_rms.var + self.epsilon)
        return np.clip(out, -self.clip_obs, self.clip_obs).astype(np.float32)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        raw = np.asarray(observation, dtype=np.float32)
        if self.increment is None:
            return self.model.predict(
                self.normalize(raw),
                state=state,
                episode_start=episode_start,
                deterministic=deterministic,
            )
        delta, state = self.model.predict(
            self.normalize(self.increment.policy_observation(raw)),
            state=state,
            episode_start=episode_start,
            deterministic=deterministic,
        )
        return self.increment.absolute_action(raw, delta), state


def load_policy(model_path, name: str | None = None, algo: str | None = None) -> PolicyAgent:
    """Load ``*.zip`` and, if present, the VecNormalize statistics saved beside it.

    The algorithm comes from ``algo``, else the run's ``config.json`` beside the model, else
    the file name (``ppo``, ``sac`` or ``td3`` in it); otherwise ``ValueError``.
    """
    import pickle

    model_path = Path(model_path)
    if not model_path.is_file():
        raise FileNotFoundError(f"no model at {model_path}")
    meta_path = model_path.parent / "config.json"
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    if algo is None:
        algo = meta.get("algo")
    increment = None
    if meta.get("action_increment"):
        from machining_envs.wrappers import ActionIncrement

        increment = ActionIncrement(**meta["action_increment"])
    if algo is None:
        m = re.search(r"(ppo|sac|td3)", model_path.name.lower())
        if m is None:
            raise ValueError(
                f"cannot tell the algorithm of {model_path}: pass algo= one of {list(ALGOS)}"
            )
        algo = m.group(1)
    if algo not in ALGOS:
        raise ValueError(f"algo must be one of {list(ALGOS)}, got {algo!r}")
    model = _algos()[algo].load(model_path, device="cpu")
    stats = model_path.with_name(model_path.stem.replace("model", "vecnormalize") + ".pkl")
    obs_rms, clip, eps = None, 10.0, 1e-8
    if stats.is_file():
        with open(stats, "rb") as fh:
            vn = pickle.load(fh)
        if vn.norm_obs:
            obs_rms, clip, eps = vn.obs_rms, vn.clip_obs, vn.epsilon
    return PolicyAgent(
        model,
        obs_rms,
        clip,
        eps,
        name=name or f"{algo.upper()} ({model_path.parent.name})",
        increment=increment,
    )


PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"


def pretrained(name: str):
    """Factory ``env -> agent`` for a shipped policy ``agents/pretrained/<name>/best_model.zip``."""
    path = PRETRAINED_DIR / name / "best_model.zip"

    def make(env=None) -> PolicyAgent:
        return load_policy(path, name=f"{name} (pretrained)")

    make.__name__ = f"pretrained_{name}"
    make.learned = True  # the benchmark gives learned agents their margin over the classical
    return make


def _make_vec(cfg: TrainConfig, seed: int):
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    wrapper, wrapper_kwargs = None, None
    if cfg.action_increment is not None:
        from machining_envs.wrappers import IncrementalAction

        wrapper = IncrementalAction
        wrapper_kwargs = {"max_step": cfg.action_increment, "hide_action": cfg.hide_action}
    venv = make_vec_env(
        cfg.env_id,
        n_envs=cfg.n_envs,
        seed=seed,
        env_kwargs=dict(cfg.env_kwargs),
        wrapper_class=wrapper,
        wrapper_kwargs=wrapper_kwargs,
    )
    if cfg.normalize:
        kw = cfg.normalize if isinstance(cfg.normalize, dict) else {}
        venv = VecNormalize(venv, **kw)
    return venv


def benchmark_spec(env_id: str):
    """The benchmark spec of an env id (``agents.benchmark.BENCHMARKS``), matched by the env's
    class so that ids registered from other projects with our env classes find theirs;
    None for an env of another class."""
    from agents.benchmark import BENCHMARKS

    def entry(eid):
        e = gym.spec(eid).entry_point
        return e if isinstance(e, str) else f"{e.__module__}:{e.__qualname__}"

    return next((b for b in BENCHMARKS if b.env_id == env_id), None) or next(
        (b for b in BENCHMARKS if entry(b.env_id) == entry(env_id)), None
    )


def _evaluation_setup(env_id: str, env_kwargs: dict):
    """The env's metrics function and primary score (its benchmark spec's, else the
    regulation envs') and the failure cost of that score for the env."""
    from machining_envs.metrics import regulation_metrics

    spec = benchmark_spec(env_id)
    metrics_fn = spec.metrics_fn if spec else regulation_metrics
    score = spec.score if spec else REGULATION_SCORE
    env = gym.make(env_id, **dict(env_kwargs))
    failed = score.failed_value(env)
    env.close()
    if not math.isfinite(failed):
        failed = FAILED_EPISODE_TIME_S
    return metrics_fn, score, failed


def _latest_checkpoint(folder: Path):
    best, steps = None, -1
    for p in folder.glob("rl_model_*_steps.zip"):
        m = re.search(r"_(\d+)_steps", p.name)
        if m and int(m.group(1)) > steps:
            best, steps = p, int(m.group(1))
    return best, steps


def train(
    env_id: str,
    algo: str = "ppo",
    out_dir="runs/run",
    seed: int = 0,
    config_path=None,
    n_timesteps: int | None = None,
    resume: bool = False,
    progress_bar: bool = True,
    verbose: bool = True,
) -> Path:
    """Train ``algo`` on ``env_id``; returns the run folder. See the module docstring."""
    import torch
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback
    from stable_baselines3.common.vec_env import VecNormalize

    cfg = load_config(env_id, algo, config_path)  # all validation before anything starts
    if n_timesteps is not None:
        if n_timesteps < 1:
            raise ConfigError(f"n_timesteps must be >= 1, got {n_timesteps}")
        cfg.n_timesteps = int(n_timesteps)
    if progress_bar:
        try:
            import rich  # noqa: F401
            import tqdm  # noqa: F401
        except ImportError:
            progress_bar = False
    out = Path(out_dir)
    ckpt_dir = out / "checkpoints"
    if resume:
        ckpt, done_steps = _latest_checkpoint(ckpt_dir)
        if ckpt is None:
            raise FileNotFoundError(f"--resume: no checkpoint in {ckpt_dir}")
    elif out.exists() and any(out.iterdir()):
        raise FileExistsError(f"{out} is not empty: choose another --out or pass --resume")
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    AlgoCls = _algos()[cfg.algo]

    venv = _make_vec(cfg, seed)
    increment = None  # the wrapper's ActionIncrement, for evaluation and the run record
    if cfg.action_increment is not None:
        w = venv.venv if isinstance(venv, VecNormalize) else venv
        increment = w.get_attr("increment", [0])[0]
    if resume:
        stats = ckpt.with_name(
            ckpt.name.replace("rl_model_", "rl_model_vecnormalize_").replace(".zip", ".pkl")
        )
        if isinstance(venv, VecNormalize) and stats.is_file():
            venv = VecNormalize.load(str(stats), venv.venv)
        model = AlgoCls.load(ckpt, env=venv, device="cpu", tensorboard_log=str(out / "tb"))
        remaining = max(0, cfg.n_timesteps - model.num_timesteps)
        if verbose:
            print(f"resuming {ckpt.name} at {model.num_timesteps} steps; {remaining} to go")
    else:
        model = AlgoCls(
            cfg.policy,
            venv,
            seed=seed,
            device="cpu",
            tensorboard_log=str(out / "tb"),
            verbose=0,
            **cfg.hyperparams,
        )
        remaining = cfg.n_timesteps
        meta = {
            "env_id": env_id,
            "algo": cfg.algo,
            "seed": seed,
            "config": asdict(cfg),
            "command": " ".join(sys.argv),
        }
        if increment is not None:
            meta["action_increment"] = increment._asdict()
        (out / "config.json").write_text(json.dumps(meta, indent=2, default=str))

    eval_csv = out / "eval.csv"
    metrics_fn, score_fn, failed_value = _evaluation_setup(env_id, cfg.env_kwargs)

    class HeldOutEval(BaseCallback):
        """Every ``eval_freq`` env steps: the harness on the held-out scenarios; keep the best."""

        def __init__(self):
            super().__init__()
            self.best = math.inf
            self.next_at = 0

        def _on_training_start(self) -> None:
            self.next_at = self.model.num_timesteps + cfg.eval_freq
            if eval_csv.is_file():
                with open(eval_csv) as fh:
                    scores = [float(r["score"]) for r in csv.DictReader(fh)]
                self.best = min(scores, default=math.inf)

        def _on_step(self) -> bool:
            if self.model.num_timesteps >= self.next_at:
                self.next_at += cfg.eval_freq
                self.evaluate_now()
            return True

        def evaluate_now(self) -> None:
            obs_rms = venv.obs_rms if isinstance(venv, VecNormalize) else None
            clip = venv.clip_obs if isinstance(venv, VecNormalize) else 10.0
            agent = PolicyAgent(self.model, obs_rms, clip, increment=increment)
            ev = evaluate(
                agent,
                env_id,
                cfg.eval_scenarios,
                n_episodes=cfg.eval_episodes,
                seed=10_000,
                env_kwargs=dict(cfg.env_kwargs),
                metrics_fn=metrics_fn,
            )
            s = score_fn(ev.rows, failed_value)
            sec = score_fn.secondary_key or "secondary"
            s = {"score": s["score"], "valid": s["valid"], sec: s["secondary"]}
            new = not eval_csv.is_file()
            with open(eval_csv, "a", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=["timesteps", "wall_s", "score", "valid", sec])
                if new:
                    w.writeheader()
                w.writerow(
                    {
                        "timesteps": self.model.num_timesteps,
                        "wall_s": round(time.perf_counter() - t0, 1),
                        **s,
                    }
                )
            self.logger.record("eval/score", s["score"])
            self.logger.record("eval/valid", s["valid"])
            if s["score"] < self.best:
                self.best = s["score"]
                self.model.save(out / "best_model.zip")
                if isinstance(venv, VecNormalize):
                    venv.save(str(out / "best_vecnormalize.pkl"))

    ckpt_cb = CheckpointCallback(
        max(1, cfg.checkpoint_freq // cfg.n_envs),
        str(ckpt_dir),
        save_vecnormalize=bool(cfg.normalize),
    )
    eval_cb = HeldOutEval()
    t0 = time.perf_counter()
    model.learn(
        remaining,
        callback=CallbackList([ckpt_cb, eval_cb]),
        progress_bar=progress_bar,
        reset_num_timesteps=not resume,
        tb_log_name=cfg.algo,
    )
    model.save(out / "final_model.zip")
    if isinstance(venv, VecNormalize):
        venv.save(str(out / "final_vecnormalize.pkl"))
    eval_cb.evaluate_now()
    if not (out / "best_model.zip").is_file():  # e.g. every evaluation scored inf
        model.save(out / "best_model.zip")
        if isinstance(venv, VecNormalize):
            venv.save(str(out / "best_vecnormalize.pkl"))
    venv.close()
    if verbose:
        print(
            f"trained {cfg.algo} on {env_id} for {model.num_timesteps} steps in "
            f"{time.perf_counter() - t0:.0f} s; run folder {out}"
        )
    return out


def evaluate_policy_file(
    model_path, env_id: str, scenarios, n_episodes: int, seed: int
) -> tuple[Evaluation, dict, PrimaryScore]:
    """The harness on a saved policy (with its VecNormalize statistics), with the env's own
    metrics; returns the evaluation, its primary score and the env's ``PrimaryScore``."""
    metrics_fn, score_fn, failed = _evaluation_setup(env_id, {})
    ev = evaluate(
        load_policy(model_path),
        env_id,
        scenarios,
        n_episodes=n_episodes,
        seed=seed,
        metrics_fn=metrics_fn,
    )
    return ev, score_fn(ev.rows, failed), score_fn
