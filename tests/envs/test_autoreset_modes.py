"""The native vector envs in their default autoreset mode, Gymnasium's, and in ``DISABLED``
(``gym.make_vec(id, num_envs=N, autoreset_mode=...)``): with ``NEXT_STEP`` a lane that ends
is reset at the next step instead of stepped, with ``DISABLED`` only by
``reset(options={"reset_mask": mask})``; in both, lane i runs exactly the single env's
episodes, as Gymnasium's ``SyncVectorEnv`` in that mode would run them.
(``test_vector.py`` covers ``SAME_STEP``, SB3's.)"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from tests.envs.test_vector import ENV_KWARGS, VECTOR_IDS, _actions, _assert_lane

N_STEPS = 700


def _pair(env_id, mode, n, seed, kwargs=None):
    kwargs = ENV_KWARGS.get(env_id, {}) if kwargs is None else kwargs
    venv = gym.make_vec(env_id, num_envs=n, autoreset_mode=mode, **kwargs)
    singles = [gym.make(env_id, **kwargs) for _ in range(n)]
    obs, info = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        _assert_lane(obs, info, i, *env.reset(seed=seed + i), "reset")
    return venv, singles


#: Further cases of the next-step comparison, where the step a lane takes past its end
#: (undone by its reset) meets state that outlives an episode: the sensor noise that step
#: draws from the lane's generator, which the reset puts back (episodes cut at a fixed
#: number of steps), and the CNC's actuation and the power-limited spindle (``shopfloor``).
NEXT_STEP_CASES = [(env_id, ENV_KWARGS.get(env_id, {})) for env_id in VECTOR_IDS] + [
    ("machining_envs/EndMilling-v0", {"max_episode_time_s": 25.6}),
    ("machining_envs/MicroDrilling-v0", {"max_episode_time_s": 2.56}),
    ("machining_envs/Turning-v0", {"scenario": "shopfloor"}),
    ("machining_envs/EndMilling-v0", {"scenario": "shopfloor", "max_episode_time_s": 20.0}),
    ("machining_envs/ContouringFeed-v0", {"scenario": "shopfloor"}),
]


@pytest.mark.parametrize(
    "env_id, kwargs", NEXT_STEP_CASES, ids=[f"{e.split('/')[1]}-{k}" for e, k in NEXT_STEP_CASES]
)
def test_next_step_lanes_are_the_single_env(env_id, kwargs):
    """A lane that ends returns its last observation and info; at the next step it returns
    the single env's next reset (reward 0, neither terminated nor truncated), whatever its
    action; then it runs that episode."""
    n = 4
    venv, singles = _pair(env_id, "NEXT_STEP", n, 5, kwargs)
    assert venv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    rng = np.random.default_rng(2)
    pending = np.zeros(n, dtype=bool)
    resets = 0
    for step in range(N_STEPS):
        actions = _actions(rng, env_id, venv.single_action_space, n)
        obs, reward, terminated, truncated, info = venv.step(actions)
        assert "final_obs" not in info
        for i, env in enumerate(singles):
            if pending[i]:
                resets += 1
                o, inf = env.reset()
                assert (reward[i], terminated[i], truncated[i]) == (0.0, False, False)
            else:
                o, r, te, tr, inf = env.step(actions[i])
                assert (r, te, tr) == (reward[i], terminated[i], truncated[i]), (step, i)
            _assert_lane(obs, info, i, o, inf, (step, i))
        pending = terminated | truncated
    assert resets >= 3, "the comparison should cross several resets"


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_disabled_lanes_are_the_single_env_and_wait_for_a_masked_reset(env_id):
    """Nothing resets by itself: stepping while a lane has ended raises and steps no lane;
    ``reset(options={"reset_mask": ...})`` resets the marked lanes only (a seed seeds those
    only), returns the others' observations unchanged and marks the info of the reset ones."""
    n = 4
    # (EndMilling-v0's long cuts under a time limit, as in test_vector.py: several resets
    # whatever the scenarios drawn)
    kwargs = {"max_episode_time_s": 20.0} if env_id == "machining_envs/EndMilling-v0" else None
    venv, singles = _pair(env_id, AutoresetMode.DISABLED, n, 9, kwargs)
    rng = np.random.default_rng(3)
    resets = refused = 0
    for step in range(N_STEPS):
        actions = _actions(rng, env_id, venv.single_action_space, n)
        obs, reward, terminated, truncated, info = venv.step(actions)
        for i, env in enumerate(singles):
            o, r, te, tr, inf = env.step(actions[i])
            assert (r, te, tr) == (reward[i], terminated[i], truncated[i]), (step, i)
            _assert_lane(obs, info, i, o, inf, (step, i))
        done = terminated | truncated
        if done.any():
            if refused < 2:  # the other lanes are not stepped either: the comparison goes on
                with pytest.raises(RuntimeError, match="reset them"):
                    venv.step(actions)
                refused += 1
            seeded = resets % 2 == 1
            seeds = [100 * step + i if done[i] else None for i in range(n)]
            new_obs, new_info = venv.reset(
                seed=seeds if seeded else None, options={"reset_mask": done.copy()}
            )
            for i, env in enumerate(singles):
                if done[i]:
                    resets += 1
                    o, inf = env.reset(seed=seeds[i]) if seeded else env.reset()
                    _assert_lane(new_obs, new_info, i, o, inf, (step, i, "reset"))
                else:
                    np.testing.assert_array_equal(new_obs[i], obs[i])
                    assert not any(new_info[k][i] for k in new_info if k[0] == "_")
    assert resets >= 3, "the comparison should cross several resets"


def test_gymnasium_observation_wrappers_take_the_next_step_mode():
    """Gymnasium's vector observation wrappers refuse same-step autoreset; in the other
    modes they run on the native env."""
    venv = gym.wrappers.vector.NormalizeObservation(
        gym.make_vec("machining_envs/Turning-v0", num_envs=3, autoreset_mode="next_step")
    )
    venv.reset(seed=0)
    for _ in range(60):
        obs = venv.step(venv.action_space.sample())[0]
    assert np.isfinite(obs).all()


def test_a_bad_autoreset_mode_or_mask_is_refused_naming_it():
    with pytest.raises(ValueError, match="autoreset_mode must be .*NEXT_STEP"):
        gym.make_vec("machining_envs/Turning-v0", num_envs=2, autoreset_mode="sometimes")
    same = gym.make_vec("machining_envs/Turning-v0", num_envs=2, autoreset_mode="SAME_STEP")
    same.reset(seed=0)
    with pytest.raises(ValueError, match="reset_mask.*DISABLED"):
        same.reset(options={"reset_mask": np.array([True, False])})
    off = gym.make_vec("machining_envs/Turning-v0", num_envs=2, autoreset_mode="DISABLED")
    with pytest.raises(RuntimeError, match="reset\\(\\) every lane"):
        off.reset(options={"reset_mask": np.array([True, False])})
    off.reset(seed=0)
    for bad in (np.array([1, 0]), np.array([True]), np.array([False, False]), "yes"):
        with pytest.raises(ValueError, match="reset_mask"):
            off.reset(options={"reset_mask": bad})


def test_a_masked_reset_takes_the_scenarios_of_its_lanes_only():
    """A list of scenarios in a masked reset: the marked lanes start on theirs, and the
    entries of the others are not read (None is fine there)."""
    venv = gym.make_vec("machining_envs/EndMilling-v0", num_envs=4, autoreset_mode="DISABLED")
    venv.reset(seed=0, options={"scenario": ["train", "validation", "paper_step", "paper_taper"]})
    mask = np.array([True, False, True, False])
    _, info = venv.reset(options={"reset_mask": mask, "scenario": ["ood", None, "ood", None]})
    assert list(info["scenario"]) == ["ood", "validation", "ood", "paper_taper"]
    np.testing.assert_array_equal(info["_scenario"], mask)
    with pytest.raises(ValueError, match="scenario of lane 0"):
        venv.reset(options={"reset_mask": mask, "scenario": [None, "ood", "ood", "ood"]})


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_gymnasium_vector_wrappers_run_on_the_default_vector_env(env_id):
    """``gym.make_vec(id, num_envs=8)`` as it comes (``NEXT_STEP``, Gymnasium's default)
    under Gymnasium's ``ClipAction``, ``NormalizeObservation`` and
    ``RecordEpisodeStatistics`` with their default arguments (``NormalizeObservation``
    refused the envs' former default, ``SAME_STEP``); with a time limit of 40 decisions,
    so that every lane ends and restarts twice, the statistics record every episode."""
    from gymnasium.wrappers.vector import ClipAction, NormalizeObservation, RecordEpisodeStatistics

    venv = NormalizeObservation(gym.make_vec(env_id, num_envs=8))  # the case
    venv.reset(seed=0)
    venv.step(venv.action_space.sample())
    venv.close()
    probe = gym.make(env_id)
    period = getattr(probe.unwrapped, "decision_interval_s", None)
    period = period if period is not None else probe.unwrapped.params.sample_time_s
    probe.close()
    base = gym.make_vec(env_id, num_envs=8, max_episode_time_s=40 * period)
    assert base.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    venv = RecordEpisodeStatistics(NormalizeObservation(ClipAction(base)))
    venv.reset(seed=0)
    rng = np.random.default_rng(0)
    shape = venv.action_space.shape
    episodes = 0
    for _ in range(130):
        obs, reward, terminated, truncated, info = venv.step(rng.uniform(-2.0, 2.0, shape))
        assert np.isfinite(obs).all() and np.isfinite(reward).all()
        if "episode" in info:
            episodes += int(info["_episode"].sum())
            assert (info["episode"]["l"][info["_episode"]] >= 1).all()
    assert episodes >= 16  # every lane ended at least twice
    assert len(venv.return_queue) == min(episodes, venv.return_queue.maxlen)
    venv.close()
