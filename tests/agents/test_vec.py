"""``agents.rl.vec.SB3VecEnv``: a Gymnasium vector env with same-step autoreset behaves, to
SB3, exactly like SB3's own ``DummyVecEnv`` over the same envs."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.env_util import make_vec_env

import machining_envs
from agents.rl.vec import SB3VecEnv
from tests.helpers import TURNING


def _pair(env_id: str, n: int, seed: int, **kwargs):
    native = SB3VecEnv(
        gym.make_vec(
            env_id,
            num_envs=n,
            vectorization_mode="sync",
            vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP},
            **kwargs,
        )
    )
    dummy = make_vec_env(env_id, n_envs=n, env_kwargs=kwargs)
    native.seed(seed)
    dummy.seed(seed)
    return native, dummy


@pytest.mark.parametrize("env_id", ["machining_envs/Turning-v0", "CartPole-v1"])
def test_same_as_dummy_vec_env_across_resets(env_id):
    native, dummy = _pair(env_id, 3, 7)
    o1, o2 = native.reset(), dummy.reset()
    np.testing.assert_array_equal(o1, o2)
    rng = np.random.default_rng(0)
    n_done = 0
    for _ in range(300):
        a = np.stack([native.action_space.sample() for _ in range(3)])
        if env_id.startswith("machining"):
            a = rng.uniform(-1, 1, size=(3, 1)).astype(np.float32)
        r1, r2 = native.step(a), dummy.step(a)
        np.testing.assert_array_equal(r1[0], r2[0])
        np.testing.assert_array_equal(r1[1], r2[1])
        np.testing.assert_array_equal(r1[2], r2[2])
        for i1, i2 in zip(r1[3], r2[3], strict=True):
            if "terminal_observation" in i2:
                n_done += 1
                np.testing.assert_array_equal(
                    i1["terminal_observation"], i2["terminal_observation"]
                )
                assert i1["TimeLimit.truncated"] == i2["TimeLimit.truncated"]
            for key in set(i2) - {"terminal_observation", "TimeLimit.truncated", "episode"}:
                assert np.all(i1[key] == i2[key]), key
    assert n_done > 0  # the comparison went through resets


def test_refuses_next_step_autoreset():
    venv = gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync")
    with pytest.raises(ValueError, match="SAME_STEP"):
        SB3VecEnv(venv)


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind == "f" and b.dtype.kind == "f":
        return np.array_equal(a, b, equal_nan=True)
    return np.array_equal(a, b)


@pytest.mark.parametrize("env_id", machining_envs.ENV_IDS)
def test_native_vector_env_is_dummy_vec_env_to_sb3(env_id):
    """The adapter over ``gym.make_vec(id)`` (the native batched env) gives SB3 what its
    ``DummyVecEnv`` of single envs gives: observations, rewards, dones and every info key,
    at every step and across resets (a fresh ``reset()`` after seeding included)."""
    n = 3
    native = SB3VecEnv(gym.make_vec(env_id, num_envs=n, autoreset_mode="SAME_STEP"))
    dummy = make_vec_env(env_id, n_envs=n)
    native.seed(11)
    dummy.seed(11)
    np.testing.assert_array_equal(native.reset(), dummy.reset())
    rng = np.random.default_rng(1)
    for _ in range(150):
        a = rng.uniform(-1.0, 1.0, size=(n, *native.action_space.shape)).astype(np.float32)
        r1, r2 = native.step(a), dummy.step(a)
        for j in range(3):
            np.testing.assert_array_equal(r1[j], r2[j])
        for i1, i2 in zip(r1[3], r2[3], strict=True):
            assert set(i1) == set(i2) - {"episode"}
            for key in i1:
                assert _same(i1[key], i2[key]), key
    np.testing.assert_array_equal(native.reset(), dummy.reset())


def test_refuses_different_options_per_env():
    """SB3's ``set_options`` may give each env its own options; the batched env resets every
    lane with one dict, so different ones are refused, not dropped."""
    venv = SB3VecEnv(
        gym.make_vec("machining_envs/Turning-v0", num_envs=2, autoreset_mode="SAME_STEP")
    )
    venv.set_options([{"scenario": "train"}, {"scenario": "validation"}])
    with pytest.raises(ValueError, match="same options"):
        venv.reset()
    venv.set_options({"scenario": "paper_405"})  # one dict for every env
    venv.reset()
    assert list(venv.venv.unwrapped._core.names.array()) == ["paper_405", "paper_405"]


def test_info_keys_are_checked_at_the_first_reset_and_one_key_is_a_tuple_of_one():
    # An unknown key was dropped without a word; a string was taken letter by letter.
    venv = SB3VecEnv(
        gym.make_vec(TURNING, num_envs=2, autoreset_mode="SAME_STEP"), info_keys=("nope", "force_N")
    )
    with pytest.raises(ValueError, match=r"info_keys \['nope'\] are not keys.*'force_N'"):
        venv.reset()
    venv = SB3VecEnv(
        gym.make_vec(TURNING, num_envs=2, autoreset_mode="SAME_STEP"), info_keys="force_N"
    )
    venv.reset()
    assert [set(i) for i in venv.reset_infos] == [{"force_N"}, {"force_N"}]
