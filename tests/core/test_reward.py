"""The regulation envs' one reward-weights type (``machining_envs.core.reward``)."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import machining_envs  # noqa: F401  (registers the ids)
from machining_envs.core.reward import LimitReward, resolve_reward
from machining_envs.drilling.env import DrillingReward
from machining_envs.milling.env import MillingReward
from machining_envs.turning.env import TurningReward


def test_one_type_whose_fields_are_the_weights_array_in_order():
    assert TurningReward is MillingReward is DrillingReward is LimitReward
    w = LimitReward(tracking=0.3, overlimit=20.0, target=0.8, progress=1.0, breakage=100.0)
    names = [f.name for f in dataclasses.fields(LimitReward)]
    assert names == ["tracking", "overlimit", "target", "progress", "breakage"]
    np.testing.assert_array_equal(w.weights(), [0.3, 20.0, 0.8, 1.0, 100.0])
    assert w.weights().dtype == np.float64


@pytest.mark.parametrize("former", ["overforce", "overtorque"])
def test_a_dict_may_use_the_former_name_of_overlimit(former):
    assert resolve_reward({former: 7.0}, LimitReward).overlimit == 7.0
    with pytest.raises(TypeError, match="unexpected keyword argument 'overlimt'"):
        resolve_reward({"overlimt": 7.0}, LimitReward)
    with pytest.raises(ValueError, match="reward weight overlimit must be a finite number"):
        resolve_reward({former: -1.0}, LimitReward)


@pytest.mark.parametrize("env_id", ["Turning-v0", "EndMilling-v0", "MicroDrilling-v0"])
def test_a_users_weights_are_the_ones_the_step_uses(env_id):
    """All weights zero: every reward is 0; progress alone: none is negative."""
    zero = {"tracking": 0.0, "overlimit": 0.0, "progress": 0.0, "breakage": 0.0}
    rewards = {}
    for name, weights in (("zero", zero), ("progress", {**zero, "progress": 1.0})):
        env = gym.make(f"machining_envs/{env_id}", reward=weights)
        env.reset(seed=3)
        rewards[name] = [env.step(np.array([0.5], dtype=np.float32))[1] for _ in range(20)]
        assert env.unwrapped.reward_weights == LimitReward(**weights)
    assert rewards["zero"] == [0.0] * 20
    assert min(rewards["progress"]) >= 0.0 and max(rewards["progress"]) > 0.0
