"""SB3 callbacks of the training runs, usable from ``machining-bench train`` and from rl-zoo3.

:class:`ValidationCallback` is the evaluation on ``validation`` named in the shipped configs
(``callback:`` in ``agents/rl/configs/*.yml``, rl-zoo3's key). Every ``eval_freq`` env steps,
and once more when training ends, it runs the policy through the evaluation harness on
``n_episodes`` episodes of the ``validation`` split (seeds 5000, 5001, ..., or from
``first_episode`` on) and scores them with the env's own primary score. Under
``machining-bench train`` it also writes the run's ``eval.csv``, keeps ``best_model.zip``
with its statistics, and saves checkpoints every ``checkpoint_freq`` steps (statistics as
JSON). Under ``python -m rl_zoo3.train`` it finds the env id, the env's keywords and the
action increment in the training env, and reports ``validation/score`` and
``validation/counts`` in the logs; rl-zoo3 saves the models itself (``--save-freq``, its own
``EvalCallback``).
"""

from __future__ import annotations

import csv
import math
import time
from pathlib import Path

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback
from stable_baselines3.common.vec_env import VecNormalize

from agents.rl.stats import save_stats

__all__ = ["ValidationCallback", "JsonStatsCheckpoint", "save_model", "selection_score"]


#: What an episode that does not count costs in the primary score, s: Turning-v0's time
#: limit, i.e. the cut is charged as if it had used the whole budget.
FAILED_EPISODE_TIME_S = 200.0


def evaluation_setup(env_id: str, env_kwargs: dict):
    """The env's task (its metrics function and primary score, ``agents.eval.task_of``) and
    the failure cost of that score for the env."""
    import gymnasium as gym

    from agents.eval import task_of

    env = gym.make(env_id, **dict(env_kwargs))
    try:
        task = task_of(env)
        failed = task.score.failed_value(env)
    finally:
        env.close()
    if not math.isfinite(failed):
        failed = FAILED_EPISODE_TIME_S
    return task.metrics, task.score, failed


def save_model(model, path) -> None:
    """``model.save(path)`` without the run's TensorBoard folder (``tensorboard_log``): a
    model file names no folder of the machine that trained it, and a model loaded to train
    further logs where its ``load(..., tensorboard_log=...)`` says, by default nowhere."""
    model.save(path, exclude=["tensorboard_log"])


class JsonStatsCheckpoint(CheckpointCallback):
    """SB3's CheckpointCallback, with the VecNormalize statistics written as JSON beside
    each checkpoint (``rl_model_vecnormalize_<steps>_steps.json``) instead of a pickle."""

    def __init__(self, save_freq: int, save_path: str, verbose: int = 0):
        super().__init__(save_freq, save_path, save_vecnormalize=False, verbose=verbose)

    def _on_step(self) -> bool:
        keep = super()._on_step()
        if self.n_calls % self.save_freq == 0:
            venv = self.model.get_vec_normalize_env()
            if isinstance(venv, VecNormalize):
                save_stats(venv, self._checkpoint_path("vecnormalize_", extension="json"))
        return keep


def _whole(value) -> int | None:
    """``value`` as an int where it is a whole number (rl-zoo3 writes large counts as
    ``!!float 1e6``), else None."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    return None if isinstance(value, bool) or not isinstance(value, int) else value


def _positive_int(name: str, value) -> int:
    v = _whole(value)
    if v is None or v < 1:
        raise ValueError(f"ValidationCallback: {name} must be an integer >= 1, got {value!r}")
    return v


def _allowances(value) -> list[float] | None:
    """``ValidationCallback``'s ``allowances``: None, or a non-empty list of shares in (0, 1)."""
    if value is None:
        return None
    ok = isinstance(value, (list, tuple)) and len(value) > 0
    ok = ok and all(
        isinstance(a, (int, float)) and not isinstance(a, bool) and 0.0 < a < 1.0 for a in value
    )
    if not ok:
        raise ValueError(
            "ValidationCallback: allowances must be a non-empty list of shares of steps in "
            f"(0, 1), e.g. [0.005, 0.01, 0.02], got {value!r}"
        )
    return [float(a) for a in value]


def selection_score(rows, score, failed_value: float, allowances) -> float:
    """The mean over ``allowances`` of ``score``'s mean charged value of ``rows`` (a
    ``PrimaryScore``; an episode counts at an allowance if under that share of its steps
    were over the limit): the best-model score of :class:`ValidationCallback` given
    ``allowances``."""
    return float(
        np.mean([np.mean([score.charged(r, failed_value, a) for r in rows]) for a in allowances])
    )


class ValidationCallback(BaseCallback):
    """Evaluation on ``validation`` episodes while training (see the module doc).

    Parameters
    ----------
    eval_freq : int
        Env steps (all envs together) between evaluations.
    n_episodes : int
        Episodes per scenario of ``scenarios``, seeds ``5000 + first_episode + i`` (the
        validation seeds).
    scenarios : list of str
        Scenario names to evaluate on; ``test`` and ``ood`` are refused (they are the
        benchmark's).
    checkpoint_freq : int, optional
        Env steps between checkpoints, when the run has a folder (``machining-bench
        train``); rl-zoo3 runs save with its own ``--save-freq``.
    allowances : list of float, optional
        The shares of steps over the limit at which an episode still counts, for the score
        that chooses the best model: the mean over them of the env's primary score (e.g.
        ``[0.005, 0.01, 0.02]``, the benchmark's verdict allowances, so that a policy that
        counts only at the loosest one is not chosen). Default: the score's own allowance
        (2 %). ``valid`` is always the share counting at 2 %.
    first_episode : int, optional
        The first validation episode used (default 0, the split's first). A run whose
        policy is checked afterwards on the first 100 validation episodes
        (``benchmarks/policy_validation.py``) chooses its best model on episodes apart from
        them with ``first_episode: 100``, so that the check is not the choice's own score.
    """

    def __init__(
        self,
        eval_freq: int = 10_000,
        n_episodes: int = 10,
        scenarios=("validation",),
        checkpoint_freq: int | None = None,
        verbose: int = 1,
        allowances=None,
        first_episode: int = 0,
    ):
        from machining_envs.core.splits import MAX_SPLIT_EPISODES, check_not_held_out

        super().__init__(verbose)
        self.eval_freq = _positive_int("eval_freq", eval_freq)
        self.n_episodes = _positive_int("n_episodes", n_episodes)
        if isinstance(scenarios, str) or not all(isinstance(s, str) for s in scenarios):
            raise ValueError(
                f"ValidationCallback: scenarios must be a list of scenario names, got {scenarios!r}"
            )
        self.scenarios = list(scenarios)
        check_not_held_out(self.scenarios, "ValidationCallback (scenarios)")
        self.checkpoint_freq = (
            None if checkpoint_freq is None else _positive_int("checkpoint_freq", checkpoint_freq)
        )
        self.allowances = _allowances(allowances)
        first = _whole(first_episode)
        top = MAX_SPLIT_EPISODES - self.n_episodes
        if first is None or not 0 <= first <= top:
            raise ValueError(
                f"ValidationCallback: first_episode must be an integer in [0, {top}] (the "
                f"split has {MAX_SPLIT_EPISODES} episodes, {self.n_episodes} are evaluated), "
                f"got {first_episode!r}"
            )
        self.first_episode = first
        self.best = math.inf
        self.next_at = 0
        self.last: dict | None = None
        self.last_at = -1
        # Set by bind() (machining-bench train) or found in the training env (rl-zoo3).
        self.env_id: str | None = None
        self.env_kwargs: dict = {}
        self.increment = None
        self.residual = None
        self.out: Path | None = None
        self._t0 = time.perf_counter()
        self._checkpoints: JsonStatsCheckpoint | None = None
        self._setup = None
        #: Called with each evaluation's row (``timesteps``, ``wall_s``, ``score``, ``valid``,
        #: the secondary metric, ``best``): a sweep reports it to Ray Tune.
        self.on_evaluation = None

    def bind(
        self, env_id: str, env_kwargs: dict, increment, out: Path | None, residual=None
    ) -> ValidationCallback:
        """Tell the callback what it would otherwise read from the training env, and the run
        folder to write ``eval.csv``, the best model and the checkpoints to. ``residual``:
        the ``ResidualSpec`` fields of a policy that sets a regulator's setpoint."""
        self.env_id, self.env_kwargs, self.increment = env_id, dict(env_kwargs), increment
        self.residual = residual
        self.out = None if out is None else Path(out)
        return self

    # ---- SB3 hooks -------------------------------------------------------------------------
    def _init_callback(self) -> None:
        if self.env_id is None:
            self._discover()
        self._setup = evaluation_setup(self.env_id, self.env_kwargs)
        if self.out is not None and self.checkpoint_freq is not None:
            n_envs = self.training_env.num_envs
            self._checkpoints = JsonStatsCheckpoint(
                max(1, self.checkpoint_freq // n_envs), str(self.out / "checkpoints")
            )
            self._checkpoints.init_callback(self.model)

    def _on_training_start(self) -> None:
        self._t0 = time.perf_counter()
        self.next_at = self.model.num_timesteps + self.eval_freq
        eval_csv = self._eval_csv()
        if eval_csv is not None and eval_csv.is_file():  # a resumed run keeps its best
            with open(eval_csv) as fh:
                scores = [float(r["score"]) for r in csv.DictReader(fh)]
            self.best = min(scores, default=math.inf)

    def _on_step(self) -> bool:
        if self._checkpoints is not None:
            self._checkpoints.on_step()
        if self.model.num_timesteps >= self.next_at:
            self.next_at += self.eval_freq
            self.evaluate_now()
        return True

    def _on_training_end(self) -> None:
        # Once per step count: rl-zoo3 calls its first callback's on_training_end again after
        # learn(), and a run whose last evaluation fell on its last step needs no other.
        if self.last_at != self.model.num_timesteps:
            self.evaluate_now()

    # ---- the evaluation ---------------------------------------------------------------------
    def _discover(self) -> None:
        """The env id, its keywords and the action increment, read from the training env
        (as rl-zoo3 builds it: ``gym.make`` with the config's ``env_kwargs`` and wrappers)."""
        from machining_envs.wrappers import IncrementalAction

        spec = self.training_env.get_attr("spec", [0])[0]
        if spec is None:
            raise ValueError("ValidationCallback: the training env has no spec (not made by id)")
        self.env_id = spec.id
        self.env_kwargs = {k: v for k, v in (spec.kwargs or {}).items() if k != "render_mode"}
        if self.training_env.env_is_wrapped(IncrementalAction, [0])[0]:
            self.increment = self.training_env.get_attr("increment", [0])[0]
        from agents.rl.residual import SetpointResidual

        if self.training_env.env_is_wrapped(SetpointResidual, [0])[0]:
            self.residual = self.training_env.get_attr("residual", [0])[0]._asdict()

    def _eval_csv(self) -> Path | None:
        return None if self.out is None else self.out / "eval.csv"

    def evaluate_now(self) -> dict:
        """Evaluate the current policy now; returns ``{"score", "valid", <secondary>}``."""
        from agents.eval import evaluate
        from agents.rl.policy import PolicyAgent
        from machining_envs.core.splits import split_seeds

        metrics_fn, score_fn, failed_value = self._setup
        venv = self.model.get_vec_normalize_env()
        obs_rms = venv.obs_rms if isinstance(venv, VecNormalize) else None
        clip = venv.clip_obs if isinstance(venv, VecNormalize) else 10.0
        eps = venv.epsilon if isinstance(venv, VecNormalize) else 1e-8
        agent = PolicyAgent(self.model, obs_rms, clip, eps, increment=self.increment)
        if self.residual is not None:
            from agents.rl.residual import ResidualAgent, ResidualSpec

            spec, policy = ResidualSpec(**self.residual), agent

            def agent(env):
                return ResidualAgent(policy, spec, spec.make_base(env, self.env_id))

        ev = evaluate(
            agent,
            self.env_id,
            self.scenarios,
            n_episodes=self.n_episodes,
            seed=split_seeds("validation", self.first_episode + self.n_episodes)[
                self.first_episode
            ],
            env_kwargs=dict(self.env_kwargs),
            metrics_fn=metrics_fn,
        )
        s = score_fn(ev.rows, failed_value)
        if self.allowances is not None:
            s["score"] = selection_score(ev.rows, score_fn, failed_value, self.allowances)
        sec = score_fn.secondary_key or "secondary"
        s = {"score": s["score"], "valid": s["valid"], sec: s["secondary"]}
        self.last, self.last_at = s, self.model.num_timesteps
        self.logger.record("validation/score", s["score"])
        self.logger.record("validation/counts", s["valid"])
        if self.verbose and self.out is None:
            print(
                f"validation at {self.model.num_timesteps} steps: score {s['score']:.4g} "
                f"({s['valid']:.0%} of {len(ev.rows)} episodes count)"
            )
        eval_csv = self._eval_csv()
        if eval_csv is not None:
            new = not eval_csv.is_file()
            with open(eval_csv, "a", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=["timesteps", "wall_s", "score", "valid", sec])
                if new:
                    w.writeheader()
                w.writerow(
                    {
                        "timesteps": self.model.num_timesteps,
                        "wall_s": round(time.perf_counter() - self._t0, 1),
                        **s,
                    }
                )
            if s["score"] < self.best:
                save_model(self.model, self.out / "best_model.zip")
                if isinstance(venv, VecNormalize):
                    save_stats(venv, self.out / "best_vecnormalize.json")
        self.best = min(self.best, s["score"])
        if self.on_evaluation is not None:
            self.on_evaluation(
                {
                    "timesteps": self.model.num_timesteps,
                    "wall_s": time.perf_counter() - self._t0,
                    **s,
                    "best": self.best,
                }
            )
        return s
