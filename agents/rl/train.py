"""Training a Stable-Baselines3 policy on a machining env (``train``), with held-out
evaluation by the env's own task (metrics and primary score), checkpoints and resuming."""

from __future__ import annotations

import json
import re
import sys
import time
from dataclasses import asdict
from pathlib import Path

import gymnasium as gym
import numpy as np

import machining_envs  # noqa: F401  (registers the env ids)
from agents.eval import Evaluation, evaluate
from agents.rl.algos import algorithm_classes
from agents.rl.callbacks import (
    FAILED_EPISODE_TIME_S,
    ValidationCallback,
    evaluation_setup,
    save_model,
)
from agents.rl.config import ConfigError, TrainConfig, load_config
from agents.rl.policy import load_model, load_policy
from agents.rl.stats import read_stats, restore_stats, save_stats, stats_path
from machining_envs.core.checks import is_integer, is_seed
from machining_envs.core.score import REGULATION_SCORE, PrimaryScore
from machining_envs.core.splits import check_not_held_out

__all__ = ["train", "evaluate_policy_file", "primary_score", "FAILED_EPISODE_TIME_S"]


def primary_score(rows: list[dict], failed_time_s: float = FAILED_EPISODE_TIME_S) -> dict:
    """The primary score of a set of regulation episodes (Turning-v0, EndMilling-v0).

    An episode *counts* if it finished the workpiece, the tool did not break, and the
    regulated signal spent under 2 % of the time above 1.1x its reference. Score: mean
    machining time (s, lower is better) with every episode that does not count charged
    ``failed_time_s``, so no policy can win by breaking the constraint. Returns ``score``,
    ``valid`` (share of episodes that counted) and ``itae`` (mean) for the table. The other
    envs' scores are their tasks' (``machining_envs.core.score``).
    """
    return REGULATION_SCORE(rows, failed_time_s)


#: How training runs the envs: the native batched vector env (ids that have one), SB3's
#: ``SubprocVecEnv`` (one process per env) or ``DummyVecEnv`` (one after another).
VEC_KINDS = ("native", "subproc", "dummy")


def _vec_kind(env_id: str, vec: str | None) -> str:
    """``vec`` checked (``ConfigError`` otherwise), or the default for ``env_id``."""
    has_native = gym.spec(env_id).vector_entry_point is not None
    if vec is None:
        return "native" if has_native else "dummy"
    if vec not in VEC_KINDS:
        raise ConfigError(f"vec must be one of {list(VEC_KINDS)}, got {vec!r}")
    if vec == "native" and not has_native:
        raise ConfigError(f"vec='native': {env_id} has no native vector env")
    return vec


def _make_vec(cfg: TrainConfig, seed: int, vec: str | None = None):
    """The training VecEnv of ``cfg`` and the ``ActionIncrement`` it applies (or None).

    ``vec`` is one of ``VEC_KINDS``; by default ``native`` where the id has a native vector
    env, else ``dummy``. All three give every env ``seed + i`` at the first reset, so they
    run the same episodes.

    On the native vector env, SB3's per-env info dicts carry only what SB3 reads (the
    terminal observation and ``TimeLimit.truncated`` where an env ends, the episode's
    return and length from ``VecMonitor``) unless the configuration names callbacks of its
    own, which may read the env's info as ``DummyVecEnv`` gives it: then every key. Copying
    the env's info into 16 dicts a step was a sixth of PPO's whole ``learn()`` on
    Turning-v0 (``benchmarks/train_throughput.py``). The policy learnt is the same.
    """
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecMonitor, VecNormalize

    from machining_envs.wrappers import IncrementalAction

    vec = _vec_kind(cfg.env_id, vec)
    wrapper_kwargs = None
    if cfg.action_increment is not None:
        wrapper_kwargs = {
            "max_step": cfg.action_increment,
            "hide_action": cfg.hide_action,
            "hide_fields": cfg.hide_fields,
        }
    if vec == "native":
        from agents.rl.vec import SB3VecEnv, VecIncrementalAction

        info_keys = None if cfg.callbacks else ()
        venv = VecMonitor(
            SB3VecEnv(
                gym.make_vec(
                    cfg.env_id,
                    num_envs=cfg.n_envs,
                    autoreset_mode="SAME_STEP",
                    **dict(cfg.env_kwargs),
                ),
                info_keys=info_keys,
            )
        )
        increment = None
        if wrapper_kwargs is not None:
            probe = gym.make(cfg.env_id, **dict(cfg.env_kwargs))
            increment = IncrementalAction(probe, **wrapper_kwargs).increment
            probe.close()
            venv = VecIncrementalAction(venv, increment)
        venv.seed(seed)
    else:
        venv = make_vec_env(
            cfg.env_id,
            n_envs=cfg.n_envs,
            seed=seed,
            env_kwargs=dict(cfg.env_kwargs),
            wrapper_class=IncrementalAction if wrapper_kwargs is not None else None,
            wrapper_kwargs=wrapper_kwargs,
            vec_env_cls=SubprocVecEnv if vec == "subproc" else None,
        )
        increment = venv.get_attr("increment", [0])[0] if wrapper_kwargs is not None else None
    if cfg.residual is not None:  # the policy sets a classical regulator's setpoint
        from agents.rl.residual import ResidualSpec, vec_setpoint_residual

        venv = vec_setpoint_residual(venv, ResidualSpec(**cfg.residual), cfg.env_id, cfg.env_kwargs)
    if cfg.normalize:
        kw = cfg.normalize if isinstance(cfg.normalize, dict) else {}
        venv = VecNormalize(venv, **kw)
    return venv, increment


def _action_noise(cfg: TrainConfig, venv) -> dict:
    """``{"action_noise": ...}`` of the config's ``noise_type`` (SB3's noise objects, one
    process per action dimension), or nothing."""
    if cfg.noise_type is None:
        return {}
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

    n = venv.action_space.shape[0]
    kind = NormalActionNoise if cfg.noise_type == "normal" else OrnsteinUhlenbeckActionNoise
    return {"action_noise": kind(mean=np.zeros(n), sigma=cfg.noise_std * np.ones(n))}


def _check_env_setup(cfg: TrainConfig) -> None:
    """Make the env with the config's ``env_kwargs`` and reset it on every evaluation
    scenario, so that a wrong keyword or scenario name fails before training starts."""
    where = f"{cfg.source}:{cfg.env_id}"
    try:
        check_not_held_out(cfg.eval_scenarios, "training (eval_scenarios)")
        check_not_held_out(
            [cfg.env_kwargs.get("scenario", "train")], "training (env_kwargs.scenario)"
        )
    except ValueError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    try:
        env = gym.make(cfg.env_id, **dict(cfg.env_kwargs))
    except gym.error.Error as exc:
        raise ConfigError(f"{where}: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: env_kwargs: {exc}") from None
    try:
        for name in cfg.eval_scenarios:
            try:
                env.reset(seed=0, options={"scenario": name})
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"{where}: eval_scenarios: {exc}") from None
    finally:
        env.close()


def _model_steps(path: Path) -> int:
    """``num_timesteps`` recorded in a saved SB3 model (read from its JSON, not unpickled)."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as zf:
            return int(json.loads(zf.read("data"))["num_timesteps"])
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return -1


def _resume_point(out: Path):
    """The model to resume from: the latest checkpoint or the final model, whichever has
    the more steps; ``(None, -1)`` if the run has neither."""
    best, steps = None, -1
    for p in (out / "checkpoints").glob("rl_model_*_steps.zip"):
        m = re.search(r"_(\d+)_steps", p.name)
        if m and int(m.group(1)) > steps:
            best, steps = p, int(m.group(1))
    final = out / "final_model.zip"
    if final.is_file():
        n = _model_steps(final)
        if n >= steps:
            best, steps = final, n
    return best, steps


def _check_new_run_folder(out: Path) -> None:
    """``out`` can become a new run's folder: it does not exist or is an empty folder, and
    the nearest folder that exists above it is writable (``FileExistsError`` for a file in
    the way, ``PermissionError`` for a folder that cannot be written), checked before any
    work so that a refused run leaves nothing behind."""
    import os

    if out.exists() and not out.is_dir():
        raise FileExistsError(f"--out {out} is a file: choose a folder")
    if out.is_dir() and any(out.iterdir()):
        raise FileExistsError(f"{out} is not empty: choose another --out or pass --resume")
    above = out
    while not above.exists():
        above = above.parent
    if not above.is_dir():
        raise FileExistsError(f"--out {out} lies under {above}, which is a file")
    if not os.access(above, os.W_OK | os.X_OK):
        raise PermissionError(f"--out {out}: {above} is not writable")


def _new_model(cfg: TrainConfig, AlgoCls, venv, seed: int, out: Path):
    """The untrained model of ``cfg`` on ``venv``; ``ConfigError`` naming ``policy`` and
    ``policy_kwargs`` when SB3 cannot build its policy from them (an unknown policy, a
    keyword the policy does not take, a layer size it cannot use)."""
    try:
        return AlgoCls(
            cfg.policy,
            venv,
            seed=seed,
            device="cpu",
            tensorboard_log=str(out / "tb"),  # (made by learn(), not here)
            verbose=0,
            **_action_noise(cfg, venv),
            **cfg.hyperparams,
        )
    except Exception as exc:  # noqa: BLE001 - SB3 and torch raise many kinds here
        kwargs = cfg.hyperparams.get("policy_kwargs", {})
        raise ConfigError(
            f"{cfg.source}:{cfg.env_id}: cannot build the policy {cfg.policy!r} with "
            f"policy_kwargs {kwargs!r}: {type(exc).__name__}: {str(exc)[:200]}"
        ) from exc


def _resumed_model(cfg: TrainConfig, ckpt: Path, venv, out: Path):
    """The model of ``ckpt`` on ``venv``, with the statistics saved beside it restored;
    ``ConfigError`` naming the file when one is damaged, does not fit the env, or (the
    run normalises) the statistics are missing."""
    from stable_baselines3.common.vec_env import VecNormalize

    stats = stats_path(ckpt)
    try:
        if isinstance(venv, VecNormalize):
            if not stats.is_file():
                raise ValueError(
                    f"--resume: no statistics file at {stats}, but the run normalises its "
                    "observations (resuming without them would start them afresh)"
                )
            restore_stats(venv, read_stats(stats))
        return load_model(cfg.algo, ckpt, env=venv, tensorboard_log=str(out / "tb"))
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


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
    vec: str | None = None,
    overrides: dict | None = None,
    on_evaluation=None,
    command: str | None = None,
) -> Path:
    """Train ``algo`` on ``env_id``; returns the run folder. See the module docstring.

    ``overrides`` replaces keys of the config entry (checked like the file's);
    ``on_evaluation`` is called with each validation evaluation's row (a sweep reports it);
    ``command`` is the command line ``config.json`` records as the run's (default: this
    process's; a sweep's trial, which runs in a Ray worker, is given the sweep's).
    """
    import torch
    from stable_baselines3.common.callbacks import CallbackList
    from stable_baselines3.common.vec_env import VecNormalize

    cfg = load_config(env_id, algo, config_path, overrides)  # all checks before anything starts
    _check_env_setup(cfg)
    vec_kind = _vec_kind(env_id, vec)
    if not is_seed(seed):
        raise ConfigError(f"seed must be an integer in [0, 2**32), got {seed!r}")
    if n_timesteps is not None:
        if not is_integer(n_timesteps):
            raise ConfigError(f"n_timesteps must be an integer >= 1, got {n_timesteps!r}")
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
        ckpt, done_steps = _resume_point(out)
        if ckpt is None:
            raise FileNotFoundError(
                f"--resume: no checkpoint in {ckpt_dir} and no final_model.zip in {out}"
            )
    else:
        _check_new_run_folder(out)
    torch.set_num_threads(1)
    AlgoCls = algorithm_classes()[cfg.algo]

    # ``increment``: the wrapper's ActionIncrement, for evaluation and the run record.
    venv, increment = _make_vec(cfg, seed, vec_kind)
    try:
        if resume:
            model = _resumed_model(cfg, ckpt, venv, out)
            remaining = max(0, cfg.n_timesteps - model.num_timesteps)
            if verbose:
                print(f"resuming {ckpt.name} at {model.num_timesteps} steps; {remaining} to go")
        else:
            model = _new_model(cfg, AlgoCls, venv, seed, out)
            remaining = cfg.n_timesteps
    except BaseException:
        venv.close()
        raise
    out.mkdir(parents=True, exist_ok=True)  # only now: a refused run leaves no folder
    if not resume:
        meta = {
            "env_id": env_id,
            "algo": cfg.algo,
            "seed": seed,
            "config": asdict(cfg),
            "command": " ".join(sys.argv) if command is None else command,
            "vec": vec_kind,
        }
        if overrides:
            meta["overrides"] = overrides
        if increment is not None:
            meta["action_increment"] = increment._asdict()
        if cfg.residual is not None:  # the regulator's settings as trained with, resolved
            from agents.rl.residual import ResidualSpec

            spec = ResidualSpec(**cfg.residual)
            meta["residual"] = {**cfg.residual, "params": spec.settings(env_id)}
        (out / "config.json").write_text(json.dumps(meta, indent=2, default=str))

    eval_cb = ValidationCallback(
        cfg.eval_freq,
        cfg.eval_episodes,
        cfg.eval_scenarios,
        cfg.checkpoint_freq,
        verbose=0,
        allowances=cfg.eval_allowances,
        first_episode=cfg.eval_first_episode,
    ).bind(env_id, cfg.env_kwargs, increment, out, cfg.residual)
    eval_cb.on_evaluation = on_evaluation
    callbacks = [eval_cb, *(cls(**kwargs) for cls, kwargs in cfg.callbacks)]
    t0 = time.perf_counter()
    model.learn(
        remaining,
        callback=CallbackList(callbacks),
        progress_bar=progress_bar,
        reset_num_timesteps=not resume,
        tb_log_name=cfg.algo,
    )
    learn_s = time.perf_counter() - t0
    save_model(model, out / "final_model.zip")
    if isinstance(venv, VecNormalize):
        save_stats(venv, out / "final_vecnormalize.json")
    if not (out / "best_model.zip").is_file():  # e.g. every evaluation scored inf
        save_model(model, out / "best_model.zip")
        if isinstance(venv, VecNormalize):
            save_stats(venv, out / "best_vecnormalize.json")
    venv.close()
    if verbose:
        print(
            f"trained {cfg.algo} on {env_id} for {model.num_timesteps} steps in "
            f"{learn_s:.0f} s ({remaining / max(learn_s, 1e-9):.0f} env-steps/s of learn(), "
            f"validation evaluations included; {vec_kind} envs); run folder {out}"
        )
    return out


def evaluate_policy_file(
    model_path,
    env_id: str,
    scenarios,
    n_episodes: int,
    seed: int,
    algo: str | None = None,
    stats=None,
    progress: bool = False,
    force: bool = False,
) -> tuple[Evaluation, dict, PrimaryScore]:
    """The harness on a saved policy (with its VecNormalize statistics: ``stats``, or the
    JSON beside the model), with the env's own metrics; returns the evaluation, its primary
    score and the env's ``PrimaryScore``. The policy must have been trained on ``env_id``
    (its ``config.json`` says), unless ``force``; its shapes must be the env's in any case
    (``agents.rl.load_policy``)."""
    if not isinstance(env_id, str) or env_id not in gym.registry:
        raise ValueError(f"env_id must be a registered env id, got {env_id!r}")
    metrics_fn, score_fn, failed = evaluation_setup(env_id, {})
    ev = evaluate(
        load_policy(model_path, algo=algo, stats=stats, env=env_id, force=force),
        env_id,
        scenarios,
        n_episodes=n_episodes,
        seed=seed,
        metrics_fn=metrics_fn,
        progress=progress,
    )
    return ev, score_fn(ev.rows, failed), score_fn
