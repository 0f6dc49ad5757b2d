"""Saved policies behind the agent protocol: a model with its VecNormalize statistics
(``load_policy``) and the policies shipped in ``agents/rl/pretrained/`` (``pretrained``)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from agents.base import check_observation
from agents.rl.algos import ALGOS, algorithm_classes
from agents.rl.files import read_json_object
from agents.rl.stats import read_stats, stats_path

__all__ = [
    "PolicyAgent",
    "ExactActor",
    "load_policy",
    "load_model",
    "read_run_config",
    "run_env_kwargs",
    "policy_env_kwargs",
    "pretrained",
    "pretrained_seeds",
    "PRETRAINED_DIR",
    "GATE_FAILED",
    "SUPERSEDED",
]


#: Below this variance in the training statistics an observation field never varied: the
#: envs' observations are of order one, so their fields that vary at all vary by far more.
CONSTANT_VAR = 1e-6


def _never_varied(obs_rms) -> tuple[np.ndarray, np.ndarray]:
    """``(index, value)`` of the fields whose variance in ``obs_rms`` is below
    ``CONSTANT_VAR``, with their mean as float32 (none without statistics)."""
    if obs_rms is None:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.float32)
    index = np.flatnonzero(np.asarray(obs_rms.var) < CONSTANT_VAR)
    return index, np.asarray(obs_rms.mean, dtype=np.float32).reshape(-1)[index]


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
        # the fields that never varied in training, found once: the statistics are frozen
        self._held = _never_varied(obs_rms)
        index, value = self._held
        self._held_seen = (
            None
            if obs_rms is None
            else (value - np.asarray(obs_rms.mean)[index])
            / np.sqrt(np.asarray(obs_rms.var)[index] + epsilon)
        )

    def held_fields(self) -> tuple[np.ndarray, np.ndarray]:
        """The observation fields that never varied in training and the value each had
        (float32, the observations' type): those whose variance in the frozen statistics is
        below ``CONSTANT_VAR`` (Turning-v0's force limit, fixed at 1000 N on ``train``; a field
        hidden from the policy, always 0)."""
        return self._held

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """``obs`` normalised by the frozen statistics, clipped to ``clip_obs``; a field that
        never varied in training is shown the value it had there (``held_fields``): divided
        by the normaliser's near-zero spread, any other value would reach the clip."""
        if self.obs_rms is None:
            return obs
        out = (obs - self.obs_rms.mean) / np.sqrt(self.obs_rms.var + self.epsilon)
        index = self._held[0]
        if index.size:
            out[..., index] = self._held_seen
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
        return cls(
            [tuple(x) for x in layers],
            pol.observation_space.shape,
            space.low.astype(np.float64),
            space.high.astype(np.float64),
            squash,
        )

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


#: What a run's ``config.json`` holds that loading a policy reads: key -> allowed types.
_RUN_FIELDS = {
    "env_id": (str,),
    "algo": (str,),
    "seed": (int,),
    "config": (dict,),
    "action_increment": (dict, type(None)),
    "residual": (dict, type(None)),
}


def read_run_config(path) -> dict:
    """A run's ``config.json`` (what :func:`agents.rl.train` writes), checked: a JSON object
    whose ``env_id`` and ``algo`` are strings (``algo`` one of ``ALGOS``), ``seed`` an
    integer, ``config`` an object and ``action_increment`` / ``residual`` objects or null,
    where present. ``ValueError`` naming the file and the field otherwise."""
    meta = read_json_object(path, "run record (config.json)")
    for key, types in _RUN_FIELDS.items():
        if key in meta and (not isinstance(meta[key], types) or isinstance(meta[key], bool)):
            names = " or ".join("null" if t is type(None) else t.__name__ for t in types)
            raise ValueError(f"{path}: {key} must be {names}, got {meta[key]!r:.60}")
    if "algo" in meta and meta["algo"] not in ALGOS:
        raise ValueError(f"{path}: algo must be one of {list(ALGOS)}, got {meta['algo']!r}")
    if meta.get("action_increment"):
        from machining_envs.wrappers import ActionIncrement

        try:
            ActionIncrement.from_record(meta["action_increment"])
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: action_increment: {exc}") from None
    if meta.get("residual"):
        from agents.rl.residual import ResidualSpec

        try:
            ResidualSpec(**meta["residual"]).checked()
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: residual: {exc}") from None
        if not isinstance(meta.get("env_id"), str):
            raise ValueError(f"{path}: a residual run must name its env_id")
    return meta


def _normalises(meta: dict) -> bool | None:
    """Whether the run of ``meta`` normalised its observations (None: it does not say)."""
    config = meta.get("config")
    if not isinstance(config, dict) or "normalize" not in config:
        return None
    norm = config["normalize"]
    if isinstance(norm, dict):
        return bool(norm.get("norm_obs", True))
    return bool(norm)


#: What an SB3 model archive holds that loading reads.
_MODEL_MEMBERS = ("data", "policy.pth")
_MODEL_DATA_KEYS = ("policy_class", "observation_space", "action_space")


def load_model(algo: str, path, **kwargs):
    """SB3's ``<ALGO>.load(path, device="cpu", **kwargs)``, with a damaged or foreign file
    refused by a ``ValueError`` naming it: not a zip archive, without SB3's ``data`` or
    ``policy.pth``, ``data`` that is not a JSON object naming the policy and its spaces,
    or anything SB3 or torch fail on while reading it (checked here rather than by SB3's
    ``assert``, which ``python -O`` skips)."""
    import zipfile

    path = Path(path)
    label = f"{path}: not a {algo.upper()} model saved by Stable-Baselines3"
    try:
        with zipfile.ZipFile(path) as zf:
            names = set(zf.namelist())
            missing = [m for m in _MODEL_MEMBERS if m not in names]
            if missing:
                raise ValueError(f"{label} (the archive has no {' or '.join(missing)})")
            data = json.loads(zf.read("data").decode("utf-8"))
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        raise ValueError(f"{label} ({type(exc).__name__}: {exc})") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{label} (its data is not JSON: {exc})") from None
    if not isinstance(data, dict) or any(k not in data for k in _MODEL_DATA_KEYS):
        raise ValueError(f"{label} (its data does not name {', '.join(_MODEL_DATA_KEYS)})")
    try:
        model = algorithm_classes()[algo].load(path, device="cpu", **kwargs)
    except Exception as exc:  # noqa: BLE001 - whatever a damaged file makes SB3 or torch raise
        raise ValueError(f"{label} ({type(exc).__name__}: {str(exc)[:200]})") from exc
    from gymnasium import spaces

    for which in ("observation_space", "action_space"):
        if not isinstance(getattr(model, which, None), spaces.Box):
            raise ValueError(f"{label} (its {which} is not a Box)")
    return model


def _env_id_and_spaces(env):
    """``(id or None, observation space, action space)`` of ``env``: an id (made once to
    read its spaces) or a gymnasium env."""
    import gymnasium as gym

    if isinstance(env, str):
        if env not in gym.registry:
            raise ValueError(f"env must be a registered env id or an env, got {env!r}")
        made = gym.make(env)
        try:
            return env, made.observation_space, made.action_space
        finally:
            made.close()
    spec = getattr(env, "spec", None) or getattr(getattr(env, "unwrapped", None), "spec", None)
    if not hasattr(env, "observation_space") or not hasattr(env, "action_space"):
        raise TypeError(f"env must be an env id or a gymnasium env, got {env!r:.60}")
    return (spec.id if spec is not None else None), env.observation_space, env.action_space


def _check_env(model_path: Path, meta: dict, model, residual, target, force: bool) -> None:
    """``ValueError`` unless the policy of ``model_path`` fits the env ``target`` (what
    :func:`_env_id_and_spaces` gives): the env the run's record names (unless ``force``),
    and in every case the observation and action shapes the model was trained with."""
    env_id, obs_space, act_space = target
    trained_on = meta.get("env_id")
    if env_id is not None and trained_on is not None and trained_on != env_id and not force:
        raise ValueError(
            f"{model_path} was trained on {trained_on}, not {env_id} (force=True to load it "
            "for another env with the same spaces)"
        )
    shape = tuple(model.observation_space.shape)
    if shape != tuple(obs_space.shape):
        raise ValueError(
            f"{model_path} takes observations of shape {shape}, but "
            f"{env_id or 'the env'}'s are {tuple(obs_space.shape)}"
        )
    n_act = int(np.prod(act_space.shape, dtype=int))
    want = (residual.action_dim(n_act),) if residual is not None else tuple(act_space.shape)
    if tuple(model.action_space.shape) != want:
        raise ValueError(
            f"{model_path} gives actions of shape {tuple(model.action_space.shape)}, but "
            f"{env_id or 'the env'} takes {want}"
        )


def _check_env_options(model_path: Path, meta: dict, env) -> None:
    """``ValueError`` where ``env`` was made with another value of an option its run trained
    with (:func:`run_env_kwargs`; an option the env keeps as an attribute of that name, such
    as MicroDrilling-v0's ``control``): the same spaces, other commands (a peck policy's
    feed velocities read as valve voltages)."""
    base = getattr(env, "unwrapped", env)
    for key, want in run_env_kwargs(meta).items():
        have = getattr(base, key, None)
        if isinstance(want, str) and isinstance(have, str) and have != want:
            raise ValueError(
                f"{model_path} acts on the env made with {key}={want!r} (its run's "
                f"env_kwargs), but this env has {key}={have!r}: make it with "
                f"gym.make(..., {key}={want!r})"
            )


def load_policy(
    model_path,
    name: str | None = None,
    algo: str | None = None,
    stats=None,
    env=None,
    force: bool = False,
):
    """Load ``*.zip`` and its VecNormalize statistics (``*_vecnormalize.json`` beside it,
    or ``stats``).

    The algorithm comes from ``algo``, else the run's ``config.json`` beside the model, else
    the file name (``ppo``, ``sac`` or ``td3`` in it); otherwise ``ValueError``. Statistics
    are read from JSON only (``agents.rl.stats``): a pickled ``*_vecnormalize.pkl`` is
    refused, since reading it could run code; convert one you trust with
    ``machining-bench convert-stats FILE.pkl``. SB3's ``.zip`` itself unpickles parts of its
    content: load models only from sources you trust.

    Every file read is checked against what it is read for (``ValueError`` naming the file):
    the model archive (:func:`load_model`), ``config.json`` (:func:`read_run_config`), and
    the statistics against the model's observations (one finite mean and a variance > 0
    per entry); a run whose ``config.json`` says it normalised its observations needs its
    statistics file (``FileNotFoundError`` naming it). ``env`` (an env id or a gymnasium
    env), where given, is the env the policy is loaded for: the run's record must name it
    (``force=True`` skips this) and the model's observation and action shapes must be its.

    Returns a :class:`PolicyAgent`, or, for a run trained with ``SetpointResidual``
    (``residual`` in its ``config.json``), an ``agents.rl.residual.ResidualAgent``: the
    policy over the regulator whose setpoint it sets.
    """
    model_path = Path(model_path)
    if not model_path.is_file():
        raise FileNotFoundError(f"no model at {model_path}")
    if not isinstance(force, (bool, np.bool_)):
        raise TypeError(f"force must be True or False, got {force!r}")
    target = _env_id_and_spaces(env) if env is not None else None
    meta_path = model_path.parent / "config.json"
    meta = read_run_config(meta_path) if meta_path.is_file() else {}
    if algo is None:
        algo = meta.get("algo")
    increment = residual = None  # (both checked by read_run_config)
    if meta.get("action_increment"):
        from machining_envs.wrappers import ActionIncrement

        increment = ActionIncrement.from_record(meta["action_increment"])
    if meta.get("residual"):
        from agents.rl.residual import ResidualSpec

        residual = ResidualSpec(**meta["residual"])
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
        if not stats.is_file() and _normalises(meta):
            raise FileNotFoundError(
                f"no statistics file at {stats}, but {meta_path} says the run normalised "
                "its observations: without them the policy sees other numbers than in "
                "training (pass stats= the run's *_vecnormalize.json)"
            )
    else:
        stats = Path(stats)
        if not stats.is_file():
            raise FileNotFoundError(f"no statistics file at {stats}")
        if stats.suffix != ".json":
            raise ValueError(f"stats must be a .json statistics file, got {stats}")
    norm = read_stats(stats) if stats.is_file() else None
    model = load_model(algo, model_path)
    obs_rms, clip, eps = None, 10.0, 1e-8
    if norm is not None and norm.norm_obs:
        shape = tuple(model.observation_space.shape)
        if norm.obs_mean.shape != shape:
            raise ValueError(
                f"{stats}: statistics of observations of shape {norm.obs_mean.shape}, but "
                f"the model {model_path} takes observations of shape {shape}"
            )
        if _normalises(meta) is False:
            raise ValueError(
                f"{stats}: statistics that normalise the observations, but {meta_path} says "
                "the run did not normalise them"
            )
        from stable_baselines3.common.running_mean_std import RunningMeanStd

        obs_rms = RunningMeanStd(shape=norm.obs_mean.shape)
        obs_rms.mean, obs_rms.var, obs_rms.count = norm.obs_mean, norm.obs_var, norm.obs_count
        clip, eps = norm.clip_obs, norm.epsilon
    if increment is not None:
        n_obs = int(np.prod(model.observation_space.shape, dtype=int))
        try:
            increment.check(n_obs)
        except ValueError as exc:
            raise ValueError(f"{meta_path}: action_increment: {exc}") from None
    if target is not None:
        _check_env(model_path, meta, model, residual, target, bool(force))
        if not isinstance(env, str):
            _check_env_options(model_path, meta, env)
    agent = PolicyAgent(
        model,
        obs_rms,
        clip,
        eps,
        name=name or f"{algo.upper()} ({model_path.parent.name})",
        increment=increment,
    )
    if residual is not None:  # the policy sets the setpoint of a classical regulator
        import gymnasium as gym

        from agents.rl.residual import ResidualAgent

        # the env as trained (MicroDrilling-v0's peck cycle needs its control="feed")
        made = gym.make(meta["env_id"], **run_env_kwargs(meta))
        try:
            base = residual.make_base(made, meta["env_id"])
        finally:
            made.close()
        return ResidualAgent(agent, residual, base, name=agent.name)
    return agent


def run_env_kwargs(meta: dict) -> dict:
    """The ``gym.make`` keywords a run's policy needs to act (its ``config.json``'s
    ``env_kwargs`` without the training ``scenario`` and ``reward``): e.g. ``control``."""
    kwargs = dict(meta.get("config", {}).get("env_kwargs", {}) or {})
    return {k: v for k, v in kwargs.items() if k not in ("scenario", "reward")}


def policy_env_kwargs(model_path) -> dict:
    """:func:`run_env_kwargs` of the run whose model is ``model_path`` (its ``config.json``
    beside it; ``{}`` where there is none): the keywords to make the env it acts on."""
    meta = Path(model_path).parent / "config.json"
    return run_env_kwargs(read_run_config(meta)) if meta.is_file() else {}


PRETRAINED_DIR = Path(__file__).resolve().parent / "pretrained"

#: Shipped folders that are not benchmark rows: the first formulations tried (plain policies
#: and a TD3 residual), kept so their validation scores and gate results can be reproduced
#: and as small examples to load. Seeds of each fail the seed gate (``agents.rl.gate``: fewer
#: than 90 % of its episodes counting, or one past the overload ceiling), and a policy ships
#: as a row only when every seed passes it (``docs/training.md``).
GATE_FAILED = (
    "contouring_feed_ppo",
    "contouring_ppo",
    "micro_drilling_ppo",
    "turning_ppo",
    "turning_td3_residual",
)
#: Shipped folders whose every seed passes the gate but whose formulation another of the same
#: env replaced: one that beat it on ``validation``, or one that met a shipping rule written
#: in its config before it was trained. The benchmark runs one learned formulation an env
#: (folder -> the row that replaced it).
SUPERSEDED = {
    "end_milling_ppo": "end_milling_ppo_load_only",
    "micro_drilling_ppo_peck": "micro_drilling_ppo_peck_voltage_feed",
    "micro_drilling_ppo_peck_voltage": "micro_drilling_ppo_peck_voltage_feed",
    "turning_ppo_residual": "turning_ppo_residual_ref85",
}


def pretrained(name: str):
    """Factory ``env -> agent`` for a shipped policy ``agents/rl/pretrained/<name>/best_model.zip``.

    ``ValueError`` naming the shipped policies when ``name`` is not one of them."""
    shipped = sorted(p.parent.name for p in PRETRAINED_DIR.glob("*/best_model.zip"))
    if name not in shipped:
        raise ValueError(f"pretrained name must be one of {shipped}, got {name!r}")
    path = PRETRAINED_DIR / name / "best_model.zip"

    def make(env=None) -> PolicyAgent:
        """The policy, checked against ``env`` (its id and spaces) where given."""
        return load_policy(path, name=f"{name} (pretrained)", env=env)

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
        seed = read_run_config(meta).get("seed", 0) if meta.is_file() else 0
        found.append((seed, folder / "best_model.zip"))
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
