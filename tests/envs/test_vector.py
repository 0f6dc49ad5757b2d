"""The native vector envs (``gym.make_vec(id, num_envs=N)``): every lane is the single env,
and the vector env keeps Gymnasium's vector conventions.

Parametrised over every id registered with a ``vector_entry_point``, in the ``SAME_STEP``
autoreset mode (SB3's; ``test_autoreset_modes.py`` covers the default, ``NEXT_STEP``).
"""

from __future__ import annotations

import copy
import dataclasses
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

import machining_envs


def make_vec(env_id: str, **kwargs):
    """``gym.make_vec`` in the mode this file covers, ``SAME_STEP``, unless told another."""
    kwargs.setdefault("autoreset_mode", "SAME_STEP")
    return gym.make_vec(env_id, **kwargs)


VECTOR_IDS = [i for i in machining_envs.ENV_IDS if gym.spec(i).vector_entry_point is not None]
#: Steps of the lane-by-lane comparison, and how far random actions reach (below +1 the
#: turning tool still breaks within some tens of steps, so lanes autoreset often; on the
#: milling env's log map the lower half of the actions crawls, median 0.7 counts, and a
#: workpiece would take about a thousand steps).
N_STEPS = 2000
ACTION_BOUND = {
    "machining_envs/Turning-v0": (-1.0, 0.3),
    "machining_envs/EndMilling-v0": (-0.5, 1.0),
}
#: Keywords of both the vector and the single envs in the lane-by-lane comparison. A
#: MicroDrilling-v0 hole takes 1000-3000 steps and random voltages rarely break the drill,
#: so a 2 s limit ends its episodes (truncated) every 200 steps; its other episode ends
#: (finished, broken, feed control) are compared in tests/drilling/test_vector.py.
#: Under random axis commands a Contouring-v0 table neither finishes nor diverges, and its
#: runs last the reference's duration plus 0.5 s (thousands of 0.2 ms steps): a 50 ms time
#: limit truncates every lane every 250 steps, so the 2000 steps cross about 30 autoresets.
ENV_KWARGS = {
    "machining_envs/MicroDrilling-v0": {"max_episode_time_s": 2.0},
    "machining_envs/Contouring-v0": {"max_episode_time_s": 0.05},
}


def _actions(rng, env_id: str, space, n: int) -> np.ndarray:
    lo, hi = ACTION_BOUND.get(env_id, (-1.0, 1.0))
    return rng.uniform(lo, hi, size=(n, *space.shape)).astype(np.float32)


def _same(a, b) -> bool:
    if isinstance(b, np.ndarray):  # an array-valued signal (the contouring commands)
        return bool(np.array_equal(a, b))
    if isinstance(a, float) and np.isnan(a):
        return isinstance(b, (float, np.floating)) and np.isnan(b)
    return a == b


def _assert_lane(obs, info, i, o, inf, where) -> None:
    """Lane ``i`` of a vector env's ``obs`` and ``info`` is the single env's ``o``, ``inf``."""
    np.testing.assert_array_equal(obs[i], o, err_msg=str(where))
    for k, v in inf.items():
        assert info["_" + k][i] and _same(info[k][i], v), (where, k)


def _run_beside_singles(venv, singles, env_id: str, rng, steps: int) -> int:
    """Step a same-step vector env and each lane's single env with the same random actions
    for ``steps`` steps, comparing every lane with its single env (an ended lane's
    ``final_obs`` and ``final_info`` with the single env's last step, then its new episode
    with the single env's next); returns the number of episodes that ended."""
    ends = 0
    for step in range(steps):
        actions = _actions(rng, env_id, venv.single_action_space, len(singles))
        obs, reward, terminated, truncated, info = venv.step(actions)
        for i, env in enumerate(singles):
            o, r, te, tr, inf = env.step(actions[i])
            assert (r, te, tr) == (reward[i], terminated[i], truncated[i]), (step, i)
            if te or tr:
                ends += 1
                _assert_lane(info["final_obs"], info["final_info"], i, o, inf, (step, i))
                o, inf = env.reset()
            _assert_lane(obs, info, i, o, inf, (step, i))
    return ends


def test_turning_has_a_native_vector_env():
    assert "machining_envs/Turning-v0" in VECTOR_IDS
    venv = make_vec("machining_envs/Turning-v0", num_envs=3)
    assert isinstance(venv, gym.vector.VectorEnv)
    assert type(venv).__name__ == "TurningVectorEnv"


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_every_lane_is_the_single_env_across_autoresets(env_id):
    """Lane i after reset(seed=s) runs what the single env runs after reset(seed=s + i):
    observations, rewards, terminations and every info signal, bit for bit, for 2000 steps;
    a lane that ends is compared with the single env's last step (``final_obs``,
    ``final_info``) and then with the single env's next episode."""
    n, seed = 4, 11
    kwargs = ENV_KWARGS.get(env_id, {})
    venv = make_vec(env_id, num_envs=n, **kwargs)
    singles = [gym.make(env_id, **kwargs) for _ in range(n)]
    obs, info = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        _assert_lane(obs, info, i, *env.reset(seed=seed + i), ("reset", i))
    ends = _run_beside_singles(venv, singles, env_id, np.random.default_rng(0), N_STEPS)
    assert ends >= 10, "the comparison should cross several autoresets"


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_an_autoreset_changes_the_info_of_the_ended_lanes_only(env_id):
    """At a step where some lanes end, ``final_info`` holds the step's info of every lane
    with the masks of the ended ones, and the returned info of the lanes that go on is that
    same step's info; a key every reset and step gives is held by every lane
    (``test_every_lane_is_the_single_env_...`` compares the ended lanes' values with the
    single env). The time limits of ``ENV_KWARGS`` end all lanes at once; turning and milling
    lanes end at different steps."""
    n = 8
    kwargs = ENV_KWARGS.get(env_id, {})
    venv = make_vec(env_id, num_envs=n, **kwargs)
    _, info = venv.reset(seed=3)
    always = [k for k in info if k[0] != "_" and info["_" + k].all()]
    assert len(always) >= 5
    rng = np.random.default_rng(1)
    checked = partial = 0
    for _ in range(1300):
        actions = _actions(rng, env_id, venv.single_action_space, n)
        _, _, terminated, truncated, info = venv.step(actions)
        done = terminated | truncated
        if not done.any():
            continue
        checked += 1
        final = info["final_info"]
        np.testing.assert_array_equal(info["_final_info"], done)
        np.testing.assert_array_equal(info["_final_obs"], done)
        going = ~done
        for key, values in final.items():
            if key[0] == "_":
                continue
            assert not (final["_" + key] & going).any(), key  # final values: ended lanes only
            assert info[key].shape == values.shape, key
            held = going & info["_" + key]  # lanes that go on and hold the key
            same = values[held] == info[key][held]
            if values.dtype.kind == "f":
                same |= np.isnan(values[held]) & np.isnan(info[key][held])
            assert np.asarray(same).all(), key
        for key in always:  # a key of every step and reset: every lane holds it
            assert info["_" + key].all(), key
        partial += bool(going.any())
        if checked >= 5:
            break
    assert checked >= 3, "the run should cross several autoresets"
    if env_id in ("machining_envs/Turning-v0", "machining_envs/EndMilling-v0"):
        assert partial >= 3, "some steps should end some lanes and not others"


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_vector_conventions(env_id):
    """Batched spaces, declared autoreset mode, dtypes, info as a dict of arrays with masks,
    observations inside the space."""
    n = 5
    venv = make_vec(env_id, num_envs=n)
    single = gym.make(env_id)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert venv.num_envs == n
    assert venv.single_observation_space == single.observation_space
    assert venv.single_action_space == single.action_space
    assert venv.observation_space == batch_space(single.observation_space, n)
    assert venv.action_space == batch_space(single.action_space, n)
    obs, info = venv.reset(seed=3)
    assert obs.dtype == venv.single_observation_space.dtype and obs.shape[0] == n
    assert venv.observation_space.contains(obs)
    for key, value in info.items():
        assert isinstance(value, np.ndarray) and value.shape[0] == n, key
    rng = np.random.default_rng(1)
    for _ in range(300):
        obs, reward, terminated, truncated, info = venv.step(
            _actions(rng, env_id, venv.single_action_space, n)
        )
        assert venv.observation_space.contains(obs)
        assert reward.shape == terminated.shape == truncated.shape == (n,)
        assert terminated.dtype == truncated.dtype == np.bool_
        assert np.all(np.isfinite(reward))
        for key, value in info.items():
            if key not in ("final_obs", "final_info"):
                assert isinstance(value, np.ndarray) and value.shape[0] == n, key
                if not key.startswith("_"):
                    assert info["_" + key].dtype == np.bool_


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_seeding_reproduces_and_distinguishes(env_id):
    def run(seed):
        venv = make_vec(env_id, num_envs=3)
        obs, _ = venv.reset(seed=seed)
        out = [obs]
        rng = np.random.default_rng(5)
        for _ in range(100):
            out.append(venv.step(_actions(rng, env_id, venv.single_action_space, 3))[0])
        return np.array(out)

    np.testing.assert_array_equal(run(7), run(7))
    assert not np.array_equal(run(7), run(8))


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_a_non_finite_action_names_its_lane_and_nothing_is_stepped(env_id):
    a_env = make_vec(env_id, num_envs=3)
    b_env = make_vec(env_id, num_envs=3)
    a_env.reset(seed=0)
    b_env.reset(seed=0)
    good = np.zeros((3, *a_env.single_action_space.shape), dtype=np.float32)
    bad = good.copy()
    bad[2] = np.nan
    with pytest.raises(ValueError, match="lane 2"):
        a_env.step(bad)
    bad[2] = 0.0
    bad[1] = np.inf
    with pytest.raises(ValueError, match="lane 1"):
        a_env.step(bad)
    for _ in range(5):  # the failed calls changed nothing: the two envs still agree
        np.testing.assert_array_equal(a_env.step(good)[0], b_env.step(good)[0])


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_reset_options_apply_to_every_lane_and_are_checked(env_id):
    venv = make_vec(env_id, num_envs=3)
    name = "paper_405" if "Turning" in env_id else "ood"
    _, info = venv.reset(seed=0, options={"scenario": name})
    assert list(info["scenario"]) == [name] * 3
    with pytest.raises(TypeError, match="options"):
        venv.reset(options="train")
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed=[1, 2])
    with pytest.raises((TypeError, ValueError), match="num_envs"):
        make_vec(env_id, num_envs=0)


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_sb3_trains_and_evaluates_through_the_adapter(env_id):
    """SB3VecEnv over the native env works under VecMonitor, VecNormalize, PPO and
    evaluate_policy."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from agents.rl.vec import SB3VecEnv

    venv = VecNormalize(VecMonitor(SB3VecEnv(make_vec(env_id, num_envs=4))))
    venv.seed(0)
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(256)
    mean, _ = evaluate_policy(model, venv, n_eval_episodes=2)
    assert np.isfinite(mean)


#: Time limits that end every lane's episode within the 160 steps of the comparison on
#: threads (Turning-v0's tools break sooner).
THREAD_KWARGS = {
    "machining_envs/EndMilling-v0": {"max_episode_time_s": 8.0},
    "machining_envs/MicroDrilling-v0": {"max_episode_time_s": 0.5},
    "machining_envs/Contouring-v0": {"max_episode_time_s": 0.01},
    "machining_envs/ContouringFeed-v0": {"max_episode_time_s": 0.5},
}


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_lanes_on_threads_step_as_on_one(env_id):
    """``num_threads``: 300 lanes on two threads (blocks of 128 and 172 lanes) give every
    lane's observations, rewards, ends and info, final ones included, bit for bit as on one
    thread, across autoresets and a pickle round trip."""
    import pickle

    n = 300
    kwargs = THREAD_KWARGS.get(env_id, {})
    one = make_vec(env_id, num_envs=n, **kwargs)
    two = make_vec(env_id, num_envs=n, num_threads=2, **kwargs)
    assert one.unwrapped.lane_blocks.edges == [(0, n)]
    assert two.unwrapped.lane_blocks.edges == [(0, 128), (128, n)]

    def same(a, b, where):
        for x, y in zip(a[:4], b[:4], strict=True):
            np.testing.assert_array_equal(x, y, err_msg=where)
        assert a[4].keys() == b[4].keys()
        for k, v in a[4].items():
            w = b[4][k]
            if k == "final_info":
                same((0, 0, 0, 0, v), (0, 0, 0, 0, w), where)
            elif v.dtype == object:  # names, final observations
                assert all(_same(p, q) for p, q in zip(v, w, strict=True)), (where, k)
            else:
                np.testing.assert_array_equal(v, w, err_msg=f"{where}: {k}")

    o1, i1 = one.reset(seed=4)
    o2, i2 = two.reset(seed=4)
    same((o1, 0, 0, 0, i1), (o2, 0, 0, 0, i2), "reset")
    rng = np.random.default_rng(2)
    ends = 0
    for step in range(160):
        if step == 80:
            two = pickle.loads(pickle.dumps(two))
        a = _actions(rng, env_id, one.single_action_space, n)
        r1, r2 = one.step(a), two.step(a)
        same(r1, r2, f"step {step}")
        ends += int(np.sum(r1[2] | r1[3]))
    assert ends >= n, "the comparison should cross autoresets"
    one.close()
    two.close()


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_a_bad_thread_count_is_refused_naming_it(env_id):
    with pytest.raises(ValueError, match=r"num_threads must be an integer in \[1, 256\], got 0"):
        make_vec(env_id, num_envs=2, num_threads=0)
    with pytest.raises(TypeError, match="num_threads"):
        make_vec(env_id, num_envs=2, num_threads=1.5)


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_a_render_mode_is_refused_pointing_to_the_single_env(env_id):
    """The vector envs keep no lane's history to draw: asking for a render mode is an error
    that says so and names the single env's reset that replays a lane (before, Python's
    "unexpected keyword argument"); None (no rendering) is taken."""
    with pytest.raises(ValueError, match=r"render_mode='rgb_array'.*reset\(seed=s \+ i\)"):
        make_vec(env_id, num_envs=2, render_mode="rgb_array")
    env = make_vec(env_id, num_envs=2, render_mode=None)
    assert env.render_mode is None and env.metadata["render_modes"] == []
    env.close()


def test_a_start_that_raises_part_way_leaves_the_batch_to_reset():
    """As for the single env: lane 0 started on the list's first scenario, lane 1's (a limit
    above the tool's breakage force) raised in its start; nothing steps until reset()."""
    env = make_vec("machining_envs/Turning-v0", num_envs=2, breakage_force_N=1500.0)
    action = np.zeros((2, 1), dtype=np.float32)
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(action)
    env.reset(seed=0, options={"scenario": "paper_405"})  # 1 kN limits
    env.step(action)
    high = dataclasses.replace(env._core.scenarios[0], force_limit_N=2000.0)
    with pytest.raises(ValueError, match="^lane 1: .* below the tool's breakage_force_N"):
        env.reset(options={"scenario": ["paper_405", high]})
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(action)
    env.reset(seed=1, options={"scenario": "paper_405"})
    env.step(action)
    env.close()


@pytest.mark.parametrize("mode", ["SAME_STEP", "NEXT_STEP"])
def test_an_autoreset_that_raises_leaves_the_batch_to_reset(mode):
    """A lane's next scenario drawn in a step can be one its parameters refuse (here an
    ``ood`` force limit above a 1 kN breakage force): the step raises naming it, and the
    batch, with that lane half-started, steps no further until reset()."""
    env = make_vec(
        "machining_envs/Turning-v0",
        num_envs=1,
        scenario="ood",
        breakage_force_N=1000.0,
        max_episode_time_s=0.3,
        autoreset_mode=mode,
    )
    env.reset(seed=1)  # its first limit is below 1 kN
    action = np.zeros((1, 1), dtype=np.float32)
    with pytest.raises(ValueError, match="^lane 0: .*force_limit_N .* below the tool's breakage"):
        for _ in range(20):  # three steps an episode
            env.step(action)
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(action)
    env.close()


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_a_vector_env_has_the_single_envs_attributes_and_command_map(env_id):
    """What agents and users read of an env, the same on both (the contouring vector envs
    had no max_episode_time_s nor action_to_command)."""
    single = gym.make(env_id).unwrapped
    vec = make_vec(env_id, num_envs=2)
    assert vec.params == single.params
    assert vec.max_episode_time_s == single.max_episode_time_s
    for a in (-1.0, -0.3, 0.0, 0.7):
        action = np.full(single.action_space.shape, a)
        command = single.action_to_command(action)
        np.testing.assert_array_equal(vec.action_to_command(action), command)
        np.testing.assert_array_equal(
            vec.command_to_action(command), single.command_to_action(command)
        )
    vec.close()


def _lane_specs(env_id: str, n: int) -> list:
    """n different scenario names of the env (its own list, in order)."""
    names = sorted(make_vec(env_id, num_envs=1)._core.scenario_types[1])
    return [names[i % len(names)] for i in range(n)]


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_a_list_of_scenarios_gives_each_lane_its_own(env_id):
    """``scenario=[...]`` (constructor or reset option): lane i runs the single env on the
    i-th scenario with seed s + i, and a lane that ends restarts on the constructor's."""
    n, seed = 3, 4
    kwargs = ENV_KWARGS.get(env_id, {})
    if env_id == "machining_envs/EndMilling-v0":  # a time limit ends its long cuts
        kwargs = {"max_episode_time_s": 20.0}
    first = _lane_specs(env_id, n)
    later = first[::-1]
    venv = make_vec(env_id, num_envs=n, scenario=first, **kwargs)
    singles = [gym.make(env_id, scenario=first[i], **kwargs) for i in range(n)]
    obs, info = venv.reset(seed=seed, options={"scenario": later})
    for i, env in enumerate(singles):
        o, inf = env.reset(seed=seed + i, options={"scenario": later[i]})
        _assert_lane(obs, info, i, o, inf, ("reset", i))
    # A single env's reset() without options restarts on its own scenario, first[i].
    ends = _run_beside_singles(venv, singles, env_id, np.random.default_rng(5), 600)
    assert ends >= 1, "a lane should restart on its own scenario"


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_what_a_step_returned_never_changes_later(env_id):
    """The info (and observation) of a reset or a step are the env's no longer: later steps
    and resets, which give lanes new scenarios (and with them new names), leave them as
    they were returned (the scenario names are handed out without a copy, read-only)."""
    n = 4
    kwargs = ENV_KWARGS.get(env_id, {})
    if env_id == "machining_envs/EndMilling-v0":  # a time limit ends its long cuts
        kwargs = {"max_episode_time_s": 20.0}
    first = _lane_specs(env_id, n)
    venv = make_vec(env_id, num_envs=n, scenario=first, **kwargs)
    returned = [venv.reset(seed=1, options={"scenario": first[::-1]})]
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(400):
        obs, _, terminated, truncated, info = venv.step(
            _actions(rng, env_id, venv.single_action_space, n)
        )
        returned.append((obs, info))
        ends += int(np.count_nonzero(terminated | truncated))
    snapshot = copy.deepcopy(returned)
    venv.reset(seed=2, options={"scenario": first[::-1]})
    venv.step(_actions(rng, env_id, venv.single_action_space, n))
    assert ends >= 2, "the run should cross resets"
    names = {tuple(info["scenario"]) for _, info in returned}
    assert len(names) >= 2, "the lanes' scenario names should change at the resets"
    for (obs, info), (obs0, info0) in zip(returned, snapshot, strict=True):
        np.testing.assert_array_equal(obs, obs0)
        for key, value in info0.items():
            if isinstance(value, np.ndarray) and value.dtype != object:
                np.testing.assert_array_equal(info[key], value, err_msg=key)
        assert list(info["scenario"]) == list(info0["scenario"])
    with pytest.raises(ValueError, match="read-only"):
        returned[-1][1]["scenario"][0] = "mine"


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_a_bad_list_of_scenarios_is_refused_naming_the_lane(env_id):
    with pytest.raises(ValueError, match="one per lane \\(3\\), got 2"):
        make_vec(env_id, num_envs=3, scenario=["train", "train"])
    with pytest.raises(ValueError, match="scenario of lane 1"):
        make_vec(env_id, num_envs=2, scenario=["train", "no such scenario"])
    venv = make_vec(env_id, num_envs=2)
    venv.reset(seed=0)
    twin = pickle.loads(pickle.dumps(venv))
    with pytest.raises(ValueError, match="scenario of lane 1"):
        venv.reset(options={"scenario": ["validation", 7]})
    with pytest.raises(ValueError, match="one per lane"):
        venv.reset(options={"scenario": ["validation"]})
    a = np.zeros(venv.action_space.shape, venv.action_space.dtype)
    np.testing.assert_array_equal(venv.step(a)[0], twin.step(a)[0])  # no lane was reset
