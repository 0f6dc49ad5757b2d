"""Every shipped policy gives the same action for an observation alone and in a batch of 64
(``agents.rl.policy.ExactActor``), on the observations of real episodes."""

import json

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import machining_envs  # noqa: E402,F401
from agents.rl.policy import (  # noqa: E402
    PRETRAINED_DIR,
    PolicyAgent,
    load_policy,
    policy_env_kwargs,
)

SHIPPED = sorted(PRETRAINED_DIR.glob("**/best_model.zip"))
LANES, STEPS = 64, 10


def _config(path):
    return json.loads((path.parent / "config.json").read_text())


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: str(p.relative_to(PRETRAINED_DIR).parent))
def test_a_shipped_policy_acts_the_same_alone_and_in_a_batch(path, monkeypatch):
    """The policy drives 64 lanes of its env (``validation`` episodes) for a few steps; every
    batch of observations its network saw is asked again one observation at a time: the
    actions are the same to the bit."""
    agent = load_policy(path)
    seen = []
    predict = PolicyAgent.predict

    def recording(self, observation, *args, **kwargs):
        seen.append(np.array(observation, copy=True))
        return predict(self, observation, *args, **kwargs)

    monkeypatch.setattr(PolicyAgent, "predict", recording)
    inner = agent.policy if hasattr(agent, "policy") else agent
    assert inner._fast, "the shipped policy must use the batch-independent actor"
    cfg = _config(path)
    # on the env as trained (the peck policies' control="feed" or "voltage_feed")
    venv = gym.make_vec(cfg["env_id"], num_envs=LANES, **policy_env_kwargs(path))
    try:
        obs, _ = venv.reset(seed=0, options={"scenario": "validation"})
        state, start = None, np.ones(LANES, dtype=bool)
        for _ in range(STEPS):
            action, state = agent.predict(obs, state=state, episode_start=start)
            start = np.zeros(LANES, dtype=bool)
            obs, *_ = venv.step(action)
    finally:
        venv.close()
    monkeypatch.setattr(PolicyAgent, "predict", predict)
    assert len(seen) == STEPS and seen[0].shape[0] == LANES
    for batch in seen:
        together = inner.predict(batch)[0]
        alone = np.stack([inner.predict(row)[0] for row in batch])
        np.testing.assert_array_equal(together, alone)
