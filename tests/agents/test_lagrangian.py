"""PPO-Lagrangian (agents.rl.lagrangian): the penalty on the rollout, the dual ascent, checks."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO, SAC  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402

from agents.rl.lagrangian import LagrangianCallback  # noqa: E402


class _Costly(gym.Env):
    """Reward 1 every step; a cost on every other step (or never); episodes of 8 steps that
    terminate (no time-limit bootstrap changes the rewards)."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, cost_every: int = 2, with_cost: bool = True):
        self.cost_every, self.with_cost, self.t = cost_every, with_cost, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(1, np.float32), {}

    def step(self, action):
        self.t += 1
        info = {}
        if self.with_cost:
            info["cost"] = 1.0 if self.cost_every and self.t % self.cost_every == 0 else 0.0
        return np.zeros(1, np.float32), 1.0, self.t >= 8, False, info


class _Copy(BaseCallback):
    """Keeps a copy of the rollout buffer at the end of a rollout (before training flattens
    it): placed before the Lagrangian callback, what PPO computed; after it, what PPO uses."""

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        buf = self.model.rollout_buffer
        self.rewards, self.advantages = buf.rewards.copy(), buf.advantages.copy()
        self.returns, self.values = buf.returns.copy(), buf.values.copy()


def _ppo(env_kwargs=None, n_envs=2):
    venv = make_vec_env(_Costly, n_envs=n_envs, env_kwargs=env_kwargs or {}, seed=0)
    return PPO("MlpPolicy", venv, n_steps=16, batch_size=16, n_epochs=1, seed=0, device="cpu")


def test_the_rollout_rewards_carry_the_multiplier_times_the_cost_and_gae_is_recomputed():
    model = _ppo()
    lag = LagrangianCallback(budget=0.1, multiplier_lr=2.0, initial_multiplier=3.0)
    before, buf = _Copy(), _Copy()
    model.learn(32, callback=[before, lag, buf])
    # The last rollout: every other step of each 8-step episode cost 1.
    t = np.arange(16) % 8 + 1
    cost = np.repeat((t % 2 == 0).astype(np.float32)[:, None], 2, axis=1)
    used = lag.history[-1][2]
    np.testing.assert_allclose(buf.rewards, before.rewards - used * cost, rtol=0, atol=1e-6)
    assert used > 0 and not np.allclose(buf.advantages, before.advantages)
    np.testing.assert_allclose(buf.returns, buf.advantages + buf.values, rtol=0, atol=1e-5)


def test_the_multiplier_rises_over_budget_and_falls_to_zero_under_it():
    model = _ppo()
    lag = LagrangianCallback(budget=0.1, multiplier_lr=2.0)
    model.learn(96, callback=lag)  # three rollouts of 32 steps, cost rate 0.5
    rates = [h[1] for h in lag.history]
    assert rates == pytest.approx([0.5] * 3)
    assert [h[3] for h in lag.history] == pytest.approx([0.8, 1.6, 2.4])
    free = _ppo({"cost_every": 0})
    lag = LagrangianCallback(budget=0.1, multiplier_lr=2.0, initial_multiplier=0.3)
    free.learn(96, callback=lag)
    assert [h[3] for h in lag.history] == pytest.approx([0.1, 0.0, 0.0])  # never below 0


def test_the_multiplier_stops_at_its_ceiling():
    lag = LagrangianCallback(budget=0.0, multiplier_lr=100.0, max_multiplier=5.0)
    _ppo().learn(32, callback=lag)
    assert lag.multiplier == 5.0


def test_an_env_without_the_cost_is_refused_naming_the_key():
    model = _ppo({"with_cost": False})
    with pytest.raises(ValueError, match="'cost'"):
        model.learn(16, callback=LagrangianCallback())


def test_off_policy_algorithms_are_refused():
    model = SAC("MlpPolicy", _Costly(), learning_starts=1, device="cpu")
    with pytest.raises(TypeError, match="on-policy"):
        model.learn(4, callback=LagrangianCallback())


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"budget": -0.1}, "budget"),
        ({"budget": 1.5}, "budget"),
        ({"budget": float("nan")}, "budget"),
        ({"budget": True}, "budget"),
        ({"multiplier_lr": 0.0}, "multiplier_lr"),
        ({"initial_multiplier": -1.0}, "initial_multiplier"),
        ({"initial_multiplier": 200.0}, "initial_multiplier"),
        ({"max_multiplier": float("inf")}, "max_multiplier"),
        ({"cost_key": ""}, "cost_key"),
    ],
)
def test_bad_settings_are_refused_naming_them(kwargs, name):
    with pytest.raises(ValueError, match=name):
        LagrangianCallback(**kwargs)


def test_a_training_configuration_names_it_as_rl_zoo3_names_a_callback(tmp_path):
    from agents.rl.config import ConfigError, load_config

    path = tmp_path / "ppo.yml"
    path.write_text(
        "machining_envs/Turning-v0:\n"
        "  policy: MlpPolicy\n"
        "  n_timesteps: 1000\n"
        "  callback:\n"
        "    - agents.rl.lagrangian.LagrangianCallback: {budget: 0.005, multiplier_lr: 10.0}\n"
    )
    cfg = load_config("machining_envs/Turning-v0", "ppo", path)
    ((cls, kwargs),) = cfg.callbacks
    assert cls is LagrangianCallback and kwargs == {"budget": 0.005, "multiplier_lr": 10.0}
    path.write_text(path.read_text().replace("multiplier_lr", "multiplier_rate"))
    with pytest.raises(ConfigError, match="multiplier_rate"):
        load_config("machining_envs/Turning-v0", "ppo", path)
