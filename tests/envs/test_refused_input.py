"""Refused input changes nothing: a reset whose options, seeds or mask are refused leaves
every generator as it was (the next unseeded reset, and every lane's next autoreset, draw
what they would have), and a batch of actions of the wrong shape is refused, never
reshaped so that one lane's command goes to another."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import machining_envs

VECTOR_IDS = [i for i in machining_envs.ENV_IDS if gym.spec(i).vector_entry_point is not None]

#: Reset arguments every env refuses, with the error each gives.
REFUSED_RESETS = [
    ({"seed": 123, "options": {"scenario": "bogus"}}, ValueError),
    ({"seed": 123, "options": {"scenario": "train", "speed": 2}}, ValueError),
    ({"seed": 123, "options": "train"}, TypeError),
]


@pytest.mark.parametrize("env_id", machining_envs.ENV_IDS)
def test_a_refused_reset_keeps_the_generator_and_the_episode(env_id):
    env, twin = gym.make(env_id), gym.make(env_id)
    env.reset(seed=5)
    twin.reset(seed=5)
    for kwargs, error in REFUSED_RESETS:
        with pytest.raises(error):
            env.reset(**kwargs)
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    np.testing.assert_array_equal(env.step(action)[0], twin.step(action)[0])  # goes on
    state = env.unwrapped.np_random.bit_generator.state
    assert state == twin.unwrapped.np_random.bit_generator.state
    # The next unseeded reset is the episode it would have been, not seed 123's.
    np.testing.assert_array_equal(env.reset()[0], twin.reset()[0])


def _rng_states(venv) -> list:
    return [r.bit_generator.state for r in venv.unwrapped.lane_rngs]


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_a_refused_vector_reset_replaces_no_lane_generator(env_id):
    venv = gym.make_vec(env_id, num_envs=3)
    venv.reset(seed=5)
    before = _rng_states(venv)
    refused = [
        *REFUSED_RESETS,
        ({"seed": 123, "options": {"scenario": ["train", "bogus", "train"]}}, ValueError),
        ({"seed": 123, "options": {"scenario": ["train"] * 2}}, ValueError),
        ({"seed": [7, -1, 9]}, ValueError),  # lane 0's seed is fine, lane 1's is not
        ({"seed": [7, 8, 9.5]}, ValueError),
    ]
    for kwargs, error in refused:
        with pytest.raises(error):
            venv.reset(**kwargs)
        assert _rng_states(venv) == before, kwargs
    with pytest.raises(ValueError, match="seed of lane 1"):
        venv.reset(seed=[7, -1, 9])


@pytest.mark.parametrize("env_id", VECTOR_IDS[:1])
def test_a_refused_masked_reset_replaces_no_lane_generator(env_id):
    venv = gym.make_vec(env_id, num_envs=3, autoreset_mode="DISABLED")
    venv.reset(seed=5)
    before = _rng_states(venv)
    mask = np.array([True, False, True])
    for kwargs, error in [
        ({"seed": 123, "options": {"reset_mask": mask, "scenario": "bogus"}}, ValueError),
        ({"seed": 123, "options": {"reset_mask": np.array([1, 0, 1])}}, ValueError),
        ({"seed": [1, 2, -3], "options": {"reset_mask": mask}}, ValueError),
    ]:
        with pytest.raises(error):
            venv.reset(**kwargs)
        assert _rng_states(venv) == before, kwargs
    # Lane 1's seed is not used by a mask that leaves it alone: no error, lanes 0, 2 reseeded.
    venv.reset(seed=[1, -1, 3], options={"reset_mask": mask})
    after = _rng_states(venv)
    assert after[1] == before[1] and after[0] != before[0]


def test_a_transposed_action_batch_is_refused():
    """Contouring-v0 takes (N, 2) actions; a (2, N) batch holds as many numbers, and was
    reshaped row-major, lane 0 getting the X commands of lanes 0 and 1."""
    venv = gym.make_vec("machining_envs/Contouring-v0", num_envs=3)
    venv.reset(seed=0)
    actions = np.array([[0.1, -0.1], [0.2, -0.2], [0.3, -0.3]], dtype=np.float32)
    for bad in (actions.T, actions.reshape(-1), actions.reshape(2, 3)):
        with pytest.raises(ValueError, match=r"shape \(3, 2\)"):
            venv.step(bad)
    venv.step(actions[:, None, :])  # dimensions of size 1 alone are taken
    venv.step(actions)


def test_a_flat_batch_of_one_dimensional_actions_is_taken():
    venv = gym.make_vec("machining_envs/Turning-v0", num_envs=3)
    twin = gym.make_vec("machining_envs/Turning-v0", num_envs=3)
    venv.reset(seed=0)
    twin.reset(seed=0)
    a = np.array([0.1, 0.2, 0.3], dtype=np.float32)
    np.testing.assert_array_equal(venv.step(a)[0], twin.step(a[:, None])[0])
    with pytest.raises(ValueError, match=r"shape \(3, 1\)"):
        venv.step(np.zeros((1, 6), dtype=np.float32))
