"""Bad input to every env, the same way: actions that are not real numbers, options that are
not a dict, and a bool where a parameter or a reward weight takes a number, are refused
with a message that names the env or the field."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import machining_envs

NOT_REAL = ["0.3", b"0.3", np.array(["0.3"]), [0.3 + 1j], "abc", {}, True, [None]]


@pytest.fixture(scope="module", params=machining_envs.ENV_IDS)
def env(request):
    env = gym.make(request.param)
    env.reset(seed=0)
    yield env
    env.close()


@pytest.mark.parametrize("action", NOT_REAL, ids=repr)
def test_actions_must_be_real_numbers(env, action):
    name = type(env.unwrapped).__name__
    with pytest.raises(ValueError, match=f"{name}: action must be real numbers"):
        env.step(action)


@pytest.mark.parametrize("value", ["0.3", 0.3 + 1j, True], ids=repr)
def test_vector_actions_must_be_real_numbers(env, value):
    venv = gym.make_vec(env.spec.id, num_envs=2)
    venv.reset(seed=0)
    bad = np.full(venv.action_space.shape, value)
    with pytest.raises(ValueError, match="action.* real numbers"):
        venv.step(bad)


@pytest.mark.parametrize("options", ["train", 5, [("scenario", "train")]], ids=repr)
def test_reset_options_must_be_a_dict(env, options):
    with pytest.raises(TypeError, match="options"):
        env.reset(options=options)


def test_a_bool_is_not_a_number_for_any_parameter_or_reward_weight(env):
    base = env.unwrapped
    numeric = [
        f.name
        for f in dataclasses.fields(base.params)
        if isinstance(getattr(base.params, f.name), (int, float))
        and not isinstance(getattr(base.params, f.name), bool)
    ]
    assert numeric
    for name in numeric:
        with pytest.raises((TypeError, ValueError), match=name):
            gym.make(env.spec.id, **{name: True})
    reward_cls = type(base.reward_weights)
    for f in dataclasses.fields(reward_cls):
        if isinstance(getattr(base.reward_weights, f.name), (int, float)):
            with pytest.raises(ValueError, match=f.name):
                reward_cls(**{f.name: True})
