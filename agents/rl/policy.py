"""Saved policies behind the agent protocol: a model with its VecNormalize statistics
(``load_policy``) and the policies shipped in ``agents/rl/pretrained/`` (``pretrained``)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from agents.base import check_observation
from agents.rl.algos import ALGOS, algorithm_classes
from agents.rl.stats import read_stats, stats_path

__all__ = [
    "PolicyAgent",
    "ExactActor",
    "load_policy",
    "pretrained",
    "pretrained_seeds",
    "PRETRAINED_DIR",
]


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

    def _observations(self, observation) -> np.ndarray:
        """The observation as float32 of shape ``(obs_dim,)`` or ``(n_envs, obs_dim)``,
        checked: real numbers, the model's shape, finite (``ValueError`` naming the entry)."""
        shape = tuple(self.model.observation_space.shape)
        try:
            raw = np.asarray(observation)
            if raw.dtype.kind not in "biuf":
                raise TypeError
        except (TypeError, ValueError):
            raise ValueError(
                f"{self.name}: observation must be real numbers of shape {shape} or "
                f"(n_envs, *{shape}), got {observation!r:.80}"
            ) from None
        if raw.shape != shape and raw.shape[1:] != shape:
            raise ValueError(
                f"{self.name}: observation must have shape {shape} or (n_envs, *{shape}), "
                f"got {raw.shape}"
            )
        raw = raw.astype(np.float32, copy=False)
        batch = raw.reshape(-1, int(np.prod(shape, dtype=int)))
        check_observation(self.name, batch)
        return raw

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3's ``predict`` on the raw observation (normalised here).

        Raises
        ------
        ValueError
            The observation is not real numbers of the model's observation shape (one env's
            or a batch), or an entry is NaN or infinite (the message names the entry).
        """
        raw = self._observations(observation)
        seen = raw if self.increment is None else self.increment.policy_observation(raw)
        if deterministic and state is None and self._fast:
            out = self._mean_action(self.normalize(seen))
        else:
            out, state = self.model.predict(
                self.normalize(seen),
                state=state,
                episode_start=episode_start,
                deterministic=deterministic,
            )
        if self.increment is None:
            return out, state
        return self.increment.absolute_action(raw, out), state

    @property
    def _fast(self) -> bool:
        """Whether :meth:`_mean_action` computes SB3's deterministic ``predict``: a plain
        MLP actor (:class:`ExactActor`: PPO/A2C with a diagonal Gaussian on a box, or
        TD3's deterministic actor)."""
        actor = getattr(self, "_actor_cached", None)
        if actor is None:
            actor = self._actor_cached = ExactActor.of(self.model.policy) or False
        return actor is not False

    def _mean_action(self, obs: np.ndarray) -> np.ndarray:
        """The policy's deterministic action (:class:`ExactActor`): the same for an
        observation whatever the batch it comes in, on any machine."""
        return self._actor_cached(obs)


class ExactActor:
    """A policy's deterministic action computed in float64 without BLAS, one observation's
    arithmetic not depending on the batch it is in.

    Torch's float32 matrix products pick kernels, blockings and thread splits by the batch
    size and the CPU, so the same observation gave different actions alone and in a batch
    of 64 (1 in 10^7 relative; enough to move an episode near the counting threshold). Here
    every layer is ``np.einsum`` in float64 (numpy's own loops: each output a sum over the
    inputs in order, whatever the batch), with the layers' float32 weights exactly; the
    action is rounded to float32 at the end. Against SB3's float32 ``predict`` it differs
    by float32 rounding only.

    :meth:`of` builds it for an actor-critic policy with a diagonal Gaussian (PPO, A2C: the
    mean action, clipped to the box) or TD3's actor (tanh, then scaled to the box), each a
    ``Flatten`` extractor and ``Linear`` layers with ``Tanh``/``ReLU``; None otherwise.
    """

    def __init__(self, layers, obs_shape, low, high, squash: bool):
        self.layers = layers  # (W float64 (out, in), b float64 (out,), activation or None)
        self.obs_shape = tuple(obs_shape)
        self.low, self.high, self.squash = low, high, squash

    @classmethod
    def of(cls, pol) -> ExactActor | None:
        from gymnasium import spaces
        from stable_baselines3.common.torch_layers import FlattenExtractor

        if not isinstance(pol.action_space, spaces.Box) or not isinstance(
            pol.observation_space, spaces.Box
        ):
            return None
        seqs = cls._modules_of(pol)
        if seqs is None:
            return None
        extractor, modules, squash = seqs
        if not isinstance(extractor, FlattenExtractor):
            return None
        layers = []
        for m in modules:
            name = type(m).__name__
            if name == "Linear":
                w = m.weight.detach().cpu().numpy().astype(np.float64)
                b = m.bias.detach().cpu().numpy().astype(np.float64)
                layers.append([w, b, None])
            elif name in ("Tanh", "ReLU") and layers and layers[-1][2] is None:
                layers[-1][2] = name
            else:
                return None
        pol.set_training_mode(False)
        space = pol.action_space
        return cls([tuple(x) for x in layers], pol.observation_space.shape,
                   space.low.astype(np.float64), space.high.astype(np.float64), squash)  # fmt: skip

    @staticmethod
    def _modules_of(pol):
        """``(features extractor, modules in order, squashed)`` of a supported policy."""
        from stable_baselines3.common.distributions import DiagGaussianDistribution
        from stable_baselines3.common.policies import ActorCriticPolicy

        if isinstance(pol, ActorCriticPolicy):
            if not isinstance(pol.action_dist, DiagGaussianDistribution) or pol.squash_output:
                return None
            net = list(pol.mlp_extractor.policy_net) + [pol.action_net]
            return pol.pi_features_extractor, net, False
        actor = getattr(pol, "actor", None)
        mu = getattr(actor, "mu", None)
        if type(pol).__name__ == "TD3Policy" and mu is not None and pol.squash_output:
            return actor.features_extractor, list(mu), True
        return None

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float64)
        one = x.ndim == len(self.obs_shape)
        x = x.reshape(-1, int(np.prod(self.obs_shape, dtype=int)))
        for w, b, act in self.layers:
            x = np.einsum("bi,oi->bo", x, w) + b
            if act == "Tanh":
                x = np.tanh(x)
            elif act == "ReLU":
                x = np.maximum(x, 0.0)
        if self.squash:  # TD3: the actor's tanh output scaled to the box
            x = self.low + 0.5 * (x + 1.0) * (self.high - self.low)
        else:
            x = np.clip(x, self.low, self.high)
        a = x.astype(np.float32)
        return a[0] if one else a


def load_policy(model_path, name: str | None = None, algo: str | None = None, stats=None):
    """Load ``*.zip`` and its VecNormalize statistics (``*_vecnormalize.json`` beside it,
    or ``stats``).

    The algorithm comes from ``algo``, else the run's ``config.json`` beside the model, else
    the file name (``ppo``, ``sac`` or ``td3`` in it); otherwise ``ValueError``. Statistics
    are read from JSON only (``agents.rl.stats``): a pickled ``*_vecnormalize.pkl`` is
    refused, since reading it could run code; convert one you trust with
    ``machining-bench convert-stats FILE.pkl``. SB3's ``.zip`` itself unpickles parts of its
    content: load models only from sources you trust.

    Returns a :class:`PolicyAgent`, or, for a run trained with ``SetpointResidual``
    (``residual`` in its ``config.json``), an ``agents.rl.residual.ResidualAgent``: the
    policy over the regulator whose setpoint it sets.
    """
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

        increment = ActionIncrement(**meta["action_increment"]).check()
    if algo is None:
        m = re.search(r"(ppo|sac|td3)", model_path.name.lower())
        if m is None:
            raise ValueError(
                f"cannot tell the algorithm of {model_path}: pass algo= one of {list(ALGOS)}"
            )
        algo = m.group(1)
    if algo not in ALGOS:
        raise ValueError(f"algo must be one of {list(ALGOS)}, got {algo!r}")
    if stats is None:
        stats = stats_path(model_path)
        pickled = stats.with_suffix(".pkl")
        if not stats.is_file() and pickled.is_file():
            raise ValueError(
                f"{pickled} is a pickle, which can run code when read: convert it once, if "
                f"you trust it, with `machining-bench convert-stats {pickled}`"
            )
    else:
        stats = Path(stats)
        if not stats.is_file():
            raise FileNotFoundError(f"no statistics file at {stats}")
        if stats.suffix != ".json":
            raise ValueError(f"stats must be a .json statistics file, got {stats}")
    norm = read_stats(stats) if stats.is_file() else None
    model = algorithm_classes()[algo].load(model_path, device="cpu")
    obs_rms, clip, eps = None, 10.0, 1e-8
    if norm is not None and norm.norm_obs:
        from stable_baselines3.common.running_mean_std import RunningMeanStd

        obs_rms = RunningMeanStd(shape=norm.obs_mean.shape)
        obs_rms.mean, obs_rms.var, obs_rms.count = norm.obs_mean, norm.obs_var, norm.obs_count
        clip, eps = norm.clip_obs, norm.epsilon
    agent = PolicyAgent(
        model,
        obs_rms,
        clip,
        eps,
        name=name or f"{algo.upper()} ({model_path.parent.name})",
        increment=increment,
    )
    if meta.get("residual"):  # the policy sets the setpoint of a classical regulator
        import gymnasium as gym

        from agents.rl.residual import ResidualAgent, ResidualSpec

        spec = ResidualSpec(**meta["residual"])
        env = gym.make(meta["env_id"])
        try:
            base = spec.make_base(env, meta["env_id"])
        finally:
            env.close()
        return ResidualAgent(agent, spec, base, name=agent.name)
    return agent


PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"


def pretrained(name: str):
    """Factory ``env -> agent`` for a shipped policy ``agents/rl/pretrained/<name>/best_model.zip``.

    ``ValueError`` naming the shipped policies when ``name`` is not one of them."""
    shipped = sorted(p.parent.name for p in PRETRAINED_DIR.glob("*/best_model.zip"))
    if name not in shipped:
        raise ValueError(f"pretrained name must be one of {shipped}, got {name!r}")
    path = PRETRAINED_DIR / name / "best_model.zip"

    def make(env=None) -> PolicyAgent:
        return load_policy(path, name=f"{name} (pretrained)")

    make.__name__ = f"pretrained_{name}"
    make.learned = True  # the benchmark gives learned agents their margin over the classical
    return make


def pretrained_seeds(name: str, root=None) -> list[tuple[int, Path]]:
    """The policies of ``<root>/<name>`` (default ``agents/rl/pretrained``), one per training
    seed, as ``(seed, model path)``: the folder's own ``best_model.zip`` (its seed from the
    ``config.json`` beside it) and every ``seed_<k>/best_model.zip`` below it.
    ``FileNotFoundError`` when there is none; ``ValueError`` when two claim one seed."""
    folder = Path(root or PRETRAINED_DIR) / name
    found = []
    if (folder / "best_model.zip").is_file():
        meta = folder / "config.json"
        seed = json.loads(meta.read_text()).get("seed", 0) if meta.is_file() else 0
        found.append((int(seed), folder / "best_model.zip"))
    for sub in sorted(folder.glob("seed_*/best_model.zip")):
        tail = sub.parent.name.removeprefix("seed_")
        if tail.isdigit():
            found.append((int(tail), sub))
    if not found:
        raise FileNotFoundError(
            f"no policy in {folder} (best_model.zip or seed_<k>/best_model.zip)"
        )
    seeds = [s for s, _ in found]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"{folder}: two policies for one training seed: {sorted(seeds)}")
    return sorted(found)
