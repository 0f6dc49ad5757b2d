"""IncrementalAction: the agent commands a change of the env's action."""

import gymnasium as gym
import numpy as np
import pytest

from machining_envs.wrappers import ActionIncrement, IncrementalAction
from tests.helpers import CONTOURING, DRILLING, MILLING, TURNING


def _step(env, delta):
    return env.step(np.array([delta], dtype=np.float32))


#: Full feed breaks the tool on a deep cut (the episode ends): turning runs the paper's
#: 405 rpm test, whose first 26 steps are at 1 mm depth, where it does not.
_GENTLE = {TURNING: {"scenario": "paper_405"}}


@pytest.mark.parametrize("env_id", [MILLING, TURNING, DRILLING])
def test_a_step_moves_the_applied_action_by_max_step_and_zero_holds_it(env_id):
    env = IncrementalAction(gym.make(env_id), max_step=0.3)
    i = env.unwrapped.OBS_INDEX["prev_action"]
    obs, _ = env.reset(seed=0, options=_GENTLE.get(env_id))
    a0 = float(obs[i])
    obs = _step(env, 1.0)[0]
    assert float(obs[i]) == pytest.approx(min(a0 + 0.3, 1.0), abs=1e-6)
    held = float(obs[i])
    obs = _step(env, 0.0)[0]
    assert float(obs[i]) == pytest.approx(held, abs=1e-6)
    obs = _step(env, -0.5)[0]
    assert float(obs[i]) == pytest.approx(max(held - 0.15, -1.0), abs=1e-6)
    for _ in range(20):  # saturates at the box, never leaves it
        obs, _, terminated, truncated, _ = _step(env, 1.0)
        assert not (terminated or truncated)
    assert float(obs[i]) == pytest.approx(1.0)
    assert env.unwrapped._n_clipped == 0


def test_the_wrapped_env_gets_the_same_actions_as_absolute_action_computes():
    wrapped = IncrementalAction(gym.make(MILLING), max_step=0.25)
    plain = gym.make(MILLING)
    ow, _ = wrapped.reset(seed=4)
    op, _ = plain.reset(seed=4)
    rng = np.random.default_rng(0)
    for _ in range(50):
        d = rng.uniform(-1.0, 1.0, size=(1,)).astype(np.float32)
        a = IncrementalAction.absolute_action(op, d, 0.25, 2)
        ow, rw, *_ = wrapped.step(d)
        op, rp, *_ = plain.step(a)
        np.testing.assert_array_equal(ow, op)
        assert rw == rp
    batch = IncrementalAction.absolute_action(
        np.stack([op, op]), np.array([[1.0], [-1.0]]), 0.25, 2
    )
    assert batch.shape == (2, 1)


@pytest.mark.parametrize("max_step", [0.0, -0.1, 2.5, float("nan"), "0.3", True])
def test_bad_max_step_names_the_parameter_and_range(max_step):
    with pytest.raises(ValueError, match=r"max_step must be a number in \(0, 2\]"):
        IncrementalAction(gym.make(MILLING), max_step=max_step)


def test_envs_without_a_single_absolute_action_are_refused():
    with pytest.raises(ValueError, match="Box\\(-1, 1, \\(1,\\)\\)"):
        IncrementalAction(gym.make(CONTOURING))


def test_non_finite_delta_and_step_before_reset_raise():
    env = IncrementalAction(gym.make(MILLING))
    with pytest.raises(RuntimeError, match="reset"):
        _step(env, 0.0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        _step(env, float("nan"))


@pytest.mark.parametrize(
    "fields, message",
    [
        ((float("nan"), 2), r"max_step must be a number in \(0, 2\], got nan"),
        ((True, 2), "max_step must be a number"),
        ((0.1, 7), r"prev_action_index must be an integer in \[0, 6\], got 7"),
        ((0.1, 2, "yes"), "hide_action must be True or False"),
        ((0.1, 2, True, (1, 7)), r"hidden must be a list of integers in \[0, 6\], got \(1, 7\)"),
        ((0.1, 2, True, "13"), "hidden must be a list of integers"),
    ],
)
def test_the_batched_increment_checks_its_fields(fields, message):
    # An ActionIncrement made by hand was applied as it came: a NaN step made NaN actions,
    # an index past the observation empty ones, (2, 0), refused by the env mid-step.
    from agents.rl.vec import SB3VecEnv, VecIncrementalAction

    venv = SB3VecEnv(
        gym.make_vec("machining_envs/Turning-v0", num_envs=2, autoreset_mode="SAME_STEP")
    )
    with pytest.raises(ValueError, match=message):
        VecIncrementalAction(venv, ActionIncrement(*fields))


def test_hidden_fields_read_as_zero_and_change_nothing_the_env_gets():
    wrapped = IncrementalAction(
        gym.make(MILLING), max_step=0.3, hide_action=True, hide_fields=["limit", "spindle"]
    )
    plain = gym.make(MILLING)
    index = plain.unwrapped.OBS_INDEX
    zeroed = [index["prev_action"], index["limit"], index["spindle"]]
    assert wrapped.increment.hidden == (index["limit"], index["spindle"])
    ow, _ = wrapped.reset(seed=3, options={"scenario": "ood"})
    op, _ = plain.reset(seed=3, options={"scenario": "ood"})
    rng = np.random.default_rng(1)
    for _ in range(30):
        assert op[index["limit"]] > 0 and op[index["spindle"]] > 0
        np.testing.assert_array_equal(ow[zeroed], 0.0)
        kept = np.delete(np.arange(op.size), zeroed)
        np.testing.assert_array_equal(ow[kept], op[kept])
        d = rng.uniform(-1.0, 1.0, size=(1,)).astype(np.float32)
        a = IncrementalAction.absolute_action(op, d, 0.3, index["prev_action"])
        ow, *_ = wrapped.step(d)
        op, *_ = plain.step(a)


@pytest.mark.parametrize(
    "hide_fields, message",
    [
        (
            ["limt"],
            r"hide_fields: 'limt' is not a field of EndMillingEnv's observation; one of "
            r"\['limit', 'measured', 'spindle'\]",
        ),
        (["history"], "'history' is not a field"),
        ("limit", "hide_fields must be a list of field names"),
        ([9], r"hidden must be a list of integers in \[0, 6\]"),
    ],
)
def test_bad_hidden_fields_name_the_allowed_ones(hide_fields, message):
    with pytest.raises(ValueError, match=message):
        IncrementalAction(gym.make(MILLING), hide_fields=hide_fields)
