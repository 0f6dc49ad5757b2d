import gymnasium as gym
import numpy as np
import pytest

import machining_envs  # noqa: F401

TURNING = "machining_envs/Turning-v0"


@pytest.fixture
def turning_env():
    env = gym.make(TURNING)
    yield env
    env.close()


def random_rollout(env, n_steps: int, seed: int):
    """Random actions from a seeded generator; resets on episode end. Returns arrays."""
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    out_obs, out_rew, out_force = [obs], [], []
    for _ in range(n_steps):
        obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, size=1).astype(np.float32))
        out_obs.append(obs)
        out_rew.append(r)
        out_force.append(info["force_N"])
        if term or trunc:
            obs, _ = env.reset()
            out_obs.append(obs)
    return np.array(out_obs), np.array(out_rew), np.array(out_force)
