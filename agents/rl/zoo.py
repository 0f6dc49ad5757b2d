"""A trained policy in rl-zoo3's folder layout, so that ``python -m rl_zoo3.enjoy`` runs it.

``machining-bench export --zoo --model <run>/best_model.zip`` writes one (by default in
``<run>/zoo``) for any saved policy with its run's ``config.json``: a run folder of
``machining-bench train``, or a shipped policy. The layout is the one rl-zoo3's trainer
leaves::

    <zoo>/<algo>/<env name>_1/
        best_model.zip, <env name>.zip      the validation-chosen policy (both names)
        <env name>/config.yml               the hyperparameters: normalize, env_kwargs, env_wrapper
        <env name>/args.yml                 the arguments of the run (rl-zoo3's train's keys)
        <env name>/env_kwargs.yml           the env's keyword arguments
        <env name>/vecnormalize.pkl         the policy's normalisation statistics

where ``<env name>`` is the id with ``/`` replaced by ``-``. Run it with::

    python -m rl_zoo3.enjoy --algo ppo --env machining_envs/Turning-v0 -f <zoo> \\
        --gym-packages machining_envs --exp-id 1 --load-best --no-render

(``--no-render``: without it rl-zoo3 opens the env in ``"human"`` mode and draws every step
with matplotlib.) The folder is written whole or not at all: it is assembled beside its
place and moved there at the end, and an existing one is refused.

``vecnormalize.pkl`` is a pickle because rl-zoo3 reads only that; this library never reads
one (``agents.rl.stats``), and its runs hold none until the view is asked for. It holds the
policy's own statistics (the JSON file beside the model), so the view's final-model name
runs the chosen policy too.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

__all__ = ["check_zoo_export", "write_zoo_folder", "zoo_env_name"]


def zoo_env_name(env_id: str) -> str:
    """rl-zoo3's folder name of an env id (``machining_envs/Turning-v0`` ->
    ``machining_envs-Turning-v0``)."""
    return env_id.replace("/", "-")


def _hyperparams(meta: dict) -> dict:
    """The run's configuration in rl-zoo3's keys (what its ``config.yml`` holds)."""
    cfg = meta["config"]
    hyper = {
        "policy": cfg.get("policy", "MlpPolicy"),
        "n_timesteps": cfg.get("n_timesteps"),
        "n_envs": cfg.get("n_envs"),
        "normalize": cfg.get("normalize", False),
        "env_kwargs": cfg.get("env_kwargs", {}),
    }
    inc = meta.get("action_increment")
    if inc:
        hyper["env_wrapper"] = [
            {
                "machining_envs.wrappers.IncrementalAction": {
                    "max_step": inc["max_step"],
                    "hide_action": inc.get("hide_action", False),
                    **({"hide_fields": list(inc["hidden"])} if inc.get("hidden") else {}),
                }
            }
        ]
    return hyper


def _args(meta: dict, hyper: dict) -> dict:
    """``args.yml``: the run's arguments under the keys of rl-zoo3's ``train`` (``enjoy``
    reads its ``env_kwargs``)."""
    return {
        "algo": meta["algo"],
        "env": meta["env_id"],
        "env_kwargs": hyper["env_kwargs"] or None,
        "gym_packages": ["machining_envs"],
        "n_timesteps": hyper["n_timesteps"],
        "seed": meta.get("seed"),
        "trained_by": meta.get("command", "machining-bench train"),
    }


def check_zoo_export(model_path, out=None) -> tuple[dict, Path]:
    """What :func:`write_zoo_folder` checks before it writes anything: the model, its run's
    ``config.json`` (a plain policy's), its statistics where the run normalises, and that
    the experiment folder is new. Returns the run's configuration and that folder."""
    from agents.rl.stats import stats_path

    model_path = Path(model_path)
    if not model_path.is_file():
        raise FileNotFoundError(f"no model at {model_path}")
    meta_path = model_path.parent / "config.json"
    if not meta_path.is_file():
        raise FileNotFoundError(
            f"no config.json beside {model_path}: the rl-zoo3 view needs the run's configuration"
        )
    try:
        meta = json.loads(meta_path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{meta_path} is not a run's configuration (JSON): {exc}") from None
    if not isinstance(meta, dict) or not {"env_id", "algo", "config"} <= set(meta):
        raise ValueError(f"{meta_path} is not a run's configuration (env_id, algo, config)")
    if meta.get("residual"):
        raise ValueError(
            f"{model_path} is a residual policy over a classical regulator: rl-zoo3 replays it "
            "with the env_wrapper agents.rl.residual.SetpointResidual, which this folder "
            "does not record; export plain policies only"
        )
    if meta["config"].get("normalize") and not stats_path(model_path).is_file():
        raise FileNotFoundError(
            f"the run normalises observations but {stats_path(model_path)} is missing"
        )
    name = zoo_env_name(meta["env_id"])
    root = Path(out) if out is not None else model_path.parent / "zoo"
    exp = root / meta["algo"] / f"{name}_1"
    if exp.exists():
        raise FileExistsError(f"{exp} exists already: remove it or choose another --out")
    return meta, exp


def write_zoo_folder(model_path, out=None) -> Path:
    """Write the rl-zoo3 view of the saved policy ``model_path`` (with the run's
    ``config.json`` and the statistics JSON beside it) under ``out`` (default: the
    ``zoo`` folder beside the model); returns the experiment folder. The folder is
    assembled beside its place and moved there whole: a failure leaves nothing."""
    import gymnasium as gym
    import yaml
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from agents.rl.stats import read_stats, restore_stats, stats_path

    meta, exp = check_zoo_export(model_path, out)
    model_path = Path(model_path)
    name = zoo_env_name(meta["env_id"])
    hyper = _hyperparams(meta)
    made = [p for p in (exp.parent, *exp.parent.parents) if not p.exists()]
    exp.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{exp.name}.", dir=exp.parent))
    try:
        params = staging / name
        params.mkdir()
        for target in ("best_model.zip", f"{name}.zip"):
            shutil.copyfile(model_path, staging / target)
        if hyper["normalize"]:
            env = gym.make(meta["env_id"], **hyper["env_kwargs"])
            kw = hyper["normalize"] if isinstance(hyper["normalize"], dict) else {}
            venv = VecNormalize(DummyVecEnv([lambda: env]), **kw)
            restore_stats(venv, read_stats(stats_path(model_path)))
            venv.save(str(params / "vecnormalize.pkl"))
            venv.close()
        (params / "config.yml").write_text(yaml.safe_dump(hyper, sort_keys=True))
        (params / "args.yml").write_text(yaml.safe_dump(_args(meta, hyper), sort_keys=True))
        (params / "env_kwargs.yml").write_text(yaml.safe_dump(hyper["env_kwargs"]))
        staging.rename(exp)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        for folder in made:  # the folders this call made, deepest first
            try:
                folder.rmdir()
            except OSError:
                break
        raise
    return exp
