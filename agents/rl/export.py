"""A learned policy as one ONNX file, for the controller of a real machine.

:func:`export_onnx` writes what :class:`~agents.rl.policy.PolicyAgent` computes, from the
env's raw observation to the env's action, as one ONNX graph: the frozen VecNormalize
statistics (normalise, clip), the SB3 network's deterministic action (clipped to the action
box, or unscaled for squashed policies) and, for a policy trained with
``action_increment``, the increment applied to the action now in force. Nothing of Python
or torch is needed to run it: onnxruntime (or any ONNX runtime on the machine's
controller) takes a float32 batch ``(n, obs_dim)`` and returns ``(n, action_dim)``.

The export checks itself: onnxruntime must reproduce the SB3 actions on observations from
real episodes to ``atol`` (1e-5), and the per-decision latency of one observation is
measured against the env's control period.

Needs the ``onnx`` extra: ``pip install 'machining-envs[rl,onnx]'``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np

from agents.rl.policy import PolicyAgent, load_policy

__all__ = ["ExportResult", "export_onnx", "control_period_s", "saved_algorithm"]


@dataclass(frozen=True)
class ExportResult:
    path: Path
    """The ONNX file."""
    n_checked: int
    """Observations on which onnxruntime was compared with SB3."""
    max_abs_error: float
    """Largest difference of the actions, onnxruntime vs SB3."""
    latency_s: float
    """Median time of one decision (one observation) in onnxruntime, s."""
    control_period_s: float
    """Time between two decisions of the env, s."""

    def summary(self) -> str:
        share = self.latency_s / self.control_period_s
        return (
            f"wrote {self.path}: onnxruntime reproduces the SB3 actions to "
            f"{self.max_abs_error:.1e} on {self.n_checked} observations; one decision takes "
            f"{self.latency_s * 1e6:.0f} us, {share:.2%} of the env's control period "
            f"({self.control_period_s * 1e3:g} ms)"
        )


#: The policy classes SB3 records in a saved model, and their algorithm.
_POLICY_CLASSES = {"ActorCriticPolicy": "ppo", "SACPolicy": "sac", "TD3Policy": "td3"}


def saved_algorithm(model_path) -> str | None:
    """The algorithm (``"ppo"``, ``"sac"``, ``"td3"``) of the SB3 model saved at
    ``model_path``, read from the policy class its zip records (without loading it); None
    where the file does not tell."""
    import json
    import re
    import zipfile

    try:
        with zipfile.ZipFile(model_path) as z:
            data = json.loads(z.read("data"))
        text = json.dumps(data.get("policy_class", {}))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, AttributeError):
        return None
    found = {algo for cls, algo in _POLICY_CLASSES.items() if re.search(rf"\b{cls}\b", text)}
    return found.pop() if len(found) == 1 else None


def control_period_s(env) -> float:
    """Seconds between two decisions of ``env`` (its decision interval, else its sample
    time)."""
    base = env.unwrapped
    period = getattr(base, "decision_interval_s", None)
    return float(period if period is not None else base.params.sample_time_s)


def _module(agent: PolicyAgent):
    """The torch module ``raw observation -> env action`` of ``agent``."""
    import torch

    policy = agent.model.policy
    space = agent.model.action_space

    class Deployed(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.policy = policy
            f32 = torch.float32
            n_obs = int(np.prod(agent.model.observation_space.shape))
            mask = torch.ones(n_obs, dtype=f32)
            inc = agent.increment
            if inc is not None and inc.hide_action:
                mask[inc.prev_action_index] = 0.0
            for i in () if inc is None else inc.hidden:
                mask[i] = 0.0
            held, value = agent.held_fields()
            mask[held] = 0.0
            hold = torch.zeros(n_obs, dtype=f32)
            hold[held] = torch.tensor(value, dtype=f32)
            self.register_buffer("mask", mask)
            self.register_buffer("hold", hold)
            rms = agent.obs_rms
            mean = np.zeros(n_obs) if rms is None else np.asarray(rms.mean)
            scale = np.ones(n_obs) if rms is None else np.sqrt(np.asarray(rms.var) + agent.epsilon)
            self.register_buffer("mean", torch.tensor(mean, dtype=f32))
            self.register_buffer("scale", torch.tensor(scale, dtype=f32))
            self.normalise = rms is not None
            self.clip_obs = float(agent.clip_obs)
            self.register_buffer("low", torch.tensor(space.low, dtype=f32))
            self.register_buffer("high", torch.tensor(space.high, dtype=f32))
            self.squash = bool(getattr(policy, "squash_output", False))
            self.increment = inc

        def _deterministic(self, x):
            """The network's deterministic action (what ``predict(deterministic=True)``
            computes before clipping), without building a distribution object."""
            p = self.policy
            if hasattr(p, "mlp_extractor"):  # PPO / A2C: the Gaussian's mean
                features = p.extract_features(x, p.pi_features_extractor)
                return p.action_net(p.mlp_extractor.forward_actor(features))
            actor = p.actor
            if hasattr(actor, "get_action_dist_params"):  # SAC: tanh of the mean
                mean, _, _ = actor.get_action_dist_params(x)
                return torch.tanh(mean)
            return actor(x)  # TD3: deterministic already

        def forward(self, obs):
            x = obs * self.mask + self.hold  # hidden fields 0, held ones their value
            if self.normalise:
                x = torch.clamp((x - self.mean) / self.scale, -self.clip_obs, self.clip_obs)
            a = self._deterministic(x)
            if self.squash:
                a = self.low + 0.5 * (a + 1.0) * (self.high - self.low)
            else:
                a = torch.maximum(torch.minimum(a, self.high), self.low)
            inc = self.increment
            if inc is not None:
                i = inc.prev_action_index
                prev = obs[:, i : i + 1]
                a = torch.clamp(prev + inc.max_step * torch.clamp(a, -1.0, 1.0), -1.0, 1.0)
            return a

    return Deployed().eval()


def _observations(env_id: str, n: int, seed: int) -> np.ndarray:
    """``n`` observations of real episodes (``train`` scenarios, random actions held for a
    few steps so that the states spread)."""
    env = gym.make(env_id)
    rng = np.random.default_rng(seed)
    out = []
    obs, _ = env.reset(seed=seed)
    action = env.action_space.sample()
    while len(out) < n:
        out.append(obs)
        if rng.random() < 0.2:
            action = rng.uniform(env.action_space.low, env.action_space.high).astype(np.float32)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            obs, _ = env.reset()
    env.close()
    return np.asarray(out, dtype=np.float32)


def export_onnx(
    model_path,
    env_id: str | None = None,
    out=None,
    algo: str | None = None,
    stats=None,
    n_check: int = 500,
    atol: float = 1e-5,
    seed: int = 0,
) -> ExportResult:
    """Write the policy saved at ``model_path`` as ONNX (default: beside it, ``.onnx``) and
    check it; see the module docstring.

    ``env_id`` defaults to the run's ``config.json``. ``ValueError`` if onnxruntime's
    actions differ from SB3's by more than ``atol`` anywhere (the file is then removed).
    """
    import json

    import onnxruntime as ort
    import torch

    model_path = Path(model_path)
    if env_id is not None and env_id not in gym.registry:
        raise ValueError(f"unknown env id {env_id!r}")
    recorded = saved_algorithm(model_path)
    if algo is not None and recorded is not None and algo != recorded:
        raise ValueError(f"algo {algo!r}: {model_path} is a {recorded} model")
    agent = load_policy(model_path, algo=algo, stats=stats)
    if not isinstance(agent, PolicyAgent):
        raise ValueError(
            f"{model_path} is a residual policy: it runs over a classical regulator, which "
            "the ONNX graph does not hold; export plain policies only"
        )
    if env_id is None:
        meta = model_path.parent / "config.json"
        if not meta.is_file():
            raise ValueError(f"no config.json beside {model_path}: give the env id")
        env_id = json.loads(meta.read_text())["env_id"]
    out = Path(out) if out is not None else model_path.with_suffix(".onnx")
    probe = gym.make(env_id)
    space = probe.observation_space
    probe.close()
    if space.shape != agent.model.observation_space.shape:
        raise ValueError(
            f"{model_path} takes observations of shape {agent.model.observation_space.shape}, "
            f"{env_id} gives {space.shape}"
        )
    module = _module(agent)
    obs = _observations(env_id, n_check, seed)
    n_obs = obs.shape[1]
    batch = torch.export.Dim("batch")
    with torch.no_grad():
        program = torch.onnx.export(
            module,
            (torch.zeros(2, n_obs),),
            dynamo=True,
            input_names=["observation"],
            output_names=["action"],
            dynamic_shapes=({0: batch},),
            verbose=False,
        )
    program.save(str(out))
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    onnx_actions = session.run(None, {"observation": obs})[0]
    sb3_actions = np.asarray(agent.predict(obs, deterministic=True)[0])
    err = float(np.max(np.abs(onnx_actions - sb3_actions)))
    if not err <= atol:
        out.unlink(missing_ok=True)
        raise ValueError(f"onnxruntime differs from SB3 by {err:.2e} > atol={atol:g}")
    one = obs[:1]
    for _ in range(20):
        session.run(None, {"observation": one})
    times = []
    for _ in range(500):
        t0 = time.perf_counter()
        session.run(None, {"observation": one})
        times.append(time.perf_counter() - t0)
    env = gym.make(env_id)
    period = control_period_s(env)
    env.close()
    return ExportResult(out, len(obs), err, float(np.median(times)), period)
