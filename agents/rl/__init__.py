"""Training, saving and loading Stable-Baselines3 policies on the machining envs.

Hyperparameters live in YAML files in ``agents/rl/configs/`` laid out like rl-zoo3's: one file per
algorithm (``ppo.yml``, ``sac.yml``, ``td3.yml``), one top-level key per env id, and under it the
training settings (``n_timesteps``, ``n_envs``, ``policy``, ``normalize``, ``env_kwargs``,
``eval_freq``, ``eval_episodes``, ``eval_scenarios``, ``checkpoint_freq``, ``action_increment``,
``hide_action``) and any keyword of the algorithm's constructor (``learning_rate``, ``n_steps``,
``policy_kwargs``, ...). Unknown keys and wrong types are rejected before any training starts.

A run folder holds everything needed to reload or continue it::

    run/
      config.json            the resolved configuration, seed and command
      final_model.zip        the model at the end   (+ final_vecnormalize.json)
      best_model.zip         the best on the validation evaluations (+ best_vecnormalize.json)
      checkpoints/           periodic model + VecNormalize snapshots (for --resume)
      eval.csv               the validation evaluations made during training (model selection)
      tb/                    TensorBoard logs

>>> from agents.rl import load_config
>>> cfg = load_config("machining_envs/Turning-v0", "ppo")
>>> cfg.algo, cfg.n_envs > 0, "learning_rate" in cfg.hyperparams
('ppo', True, True)
"""

from agents.rl.config import ALGOS, CONFIG_DIR, ConfigError, TrainConfig, load_config
from agents.rl.policy import (
    GATE_FAILED,
    PRETRAINED_DIR,
    SUPERSEDED,
    PolicyAgent,
    load_policy,
    pretrained,
    pretrained_seeds,
)
from agents.rl.train import FAILED_EPISODE_TIME_S, evaluate_policy_file, primary_score, train

__all__ = [
    "ALGOS",
    "CONFIG_DIR",
    "ConfigError",
    "TrainConfig",
    "load_config",
    "train",
    "evaluate_policy_file",
    "PolicyAgent",
    "load_policy",
    "primary_score",
    "FAILED_EPISODE_TIME_S",
    "pretrained",
    "pretrained_seeds",
    "PRETRAINED_DIR",
    "GATE_FAILED",
    "SUPERSEDED",
]
