"""What several test files share: the env ids, random rollouts and runs to the end of an
episode, a fresh interpreter, scenario draws, and the agent-protocol checks (SB3's
``evaluate_policy``, batched ``predict``, design from nominal parameters)."""

from __future__ import annotations

import functools
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

import machining_envs  # noqa: F401  (registers the env ids)

TURNING = "machining_envs/Turning-v0"
MILLING = "machining_envs/EndMilling-v0"
DRILLING = "machining_envs/MicroDrilling-v0"
CONTOURING = "machining_envs/Contouring-v0"
CONTOURING_FEED = "machining_envs/ContouringFeed-v0"
#: The random scenario sets every env has: training draws and held-out ones.
#: The training split and the out-of-distribution one, whose ranges reach beyond it.
TRAIN_OOD = ("train", "ood")


def random_action(rng: np.random.Generator, env: gym.Env, bound: float = 1.0) -> np.ndarray:
    """A uniform action in ``[-bound, bound]`` of the env's action shape (float32)."""
    return rng.uniform(-bound, bound, size=env.action_space.shape).astype(np.float32)


def run_cut(
    env_id: str,
    agent_or_action,
    scenario,
    keys: Sequence[str],
    steps: int,
    max_episode_time_s: float,
) -> tuple[np.ndarray, gym.Env]:
    """One episode of ``env_id`` on ``scenario`` (seed 0), driven by a constant action (a
    float) or an agent's ``predict``, for at most ``steps`` steps: the ``info[key]`` of every
    step for ``keys`` as rows of an array, and the unwrapped env."""
    env = gym.make(env_id, max_episode_time_s=max_episode_time_s).unwrapped
    obs, _ = env.reset(seed=0, options={"scenario": scenario})
    state, rows = None, []
    for _ in range(steps):
        if isinstance(agent_or_action, float):
            action = np.array([agent_or_action])
        else:
            action, state = agent_or_action.predict(obs, state)
        obs, _, terminated, truncated, info = env.step(action)
        rows.append([info[k] for k in keys])
        if terminated or truncated:
            break
    return np.array(rows), env


def random_rollout(env: gym.Env, n_steps: int, seed: int, signal: str):
    """Random in-box actions from a seeded generator, resetting on episode end.

    Returns the observations, rewards and the ``info[signal]`` of every step as arrays.
    """
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    out_obs, out_rew, out_signal = [obs], [], []
    for _ in range(n_steps):
        obs, r, term, trunc, info = env.step(random_action(rng, env))
        out_obs.append(obs)
        out_rew.append(r)
        out_signal.append(info[signal])
        if term or trunc:
            obs, _ = env.reset()
            out_obs.append(obs)
    return np.array(out_obs), np.array(out_rew), np.array(out_signal)


def random_steps(env: gym.Env, n_steps: int, seed: int, scenarios: Sequence[str]):
    """Random actions in [-1.5, 1.5] (so sometimes clipped), a random scenario at each reset.

    Returns ``(bad, resets)``: the steps whose observation, reward or a numeric info value
    was not finite or whose observation left the observation space, and the resets made.
    """
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    bad = resets = 0
    for _ in range(n_steps):
        obs, r, term, trunc, info = env.step(random_action(rng, env, 1.5))
        nums = [v for v in info.values() if isinstance(v, (float, int, np.number))]
        if not (
            np.all(np.isfinite(obs))
            and env.observation_space.contains(obs)
            and np.isfinite(r)
            and np.all(np.isfinite(nums))
        ):
            bad += 1
        if term or trunc:
            env.reset(options={"scenario": scenarios[int(rng.integers(len(scenarios)))]})
            resets += 1
    return bad, resets


def run_until_done(env: gym.Env, action) -> tuple[int, bool, bool, dict, float]:
    """Step ``action`` until the episode ends: ``(steps, terminated, truncated, info, reward)``
    of the last step."""
    action = np.asarray(action, dtype=np.float32)
    n, done = 0, False
    while not done:
        _, r, term, trunc, info = env.step(action)
        n += 1
        done = term or trunc
    return n, term, trunc, info, r


def servo_step_response(params, design, n: int, axis: str | None = None):
    """Positions after each of ``n`` periods and the commands during them of ``design``'s
    discrete closed loop (``machining_envs.contouring.servo.closed_loop``) for a unit step
    of the set point from rest."""
    from machining_envs.contouring.servo import closed_loop

    a, b, cy, cu, du = closed_loop(params, design, axis)
    z = np.zeros(a.shape[0])
    y, u = np.empty(n), np.empty(n)
    for k in range(n):
        u[k] = cu[0] @ z + du[0, 0]
        z = a @ z + b[:, 0]
        y[k] = cy[0] @ z
    return y, u


def run_python(code: str) -> str:
    """Run ``code`` in a fresh interpreter (nothing imported beforehand); return its stdout."""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.strip()


def assert_sb3_evaluate_policy_runs(factory: Callable, env_id: str, env_kwargs: dict) -> None:
    """SB3's ``evaluate_policy`` runs the agent unchanged on a two-env VecEnv."""
    venv = make_vec_env(env_id, n_envs=2, seed=0, env_kwargs=env_kwargs)
    try:
        agent = factory(venv.envs[0])
        mean, std = evaluate_policy(agent, venv, n_eval_episodes=2, deterministic=True)
        assert np.isfinite(mean) and np.isfinite(std)
    finally:
        venv.close()


def assert_batched_predict_equals_single(
    agent, make_env: Callable[[], gym.Env], n_steps: int, rtol: float = 0.0, atol: float = 0.0
) -> None:
    """Three envs (seeds 0, 1, 2) driven by one batched ``predict``: each row of the batch
    equals what the agent returns for that env alone (bit for bit unless a tolerance is
    given), episode starts and states included."""
    envs = [make_env() for _ in range(3)]
    obs = [e.reset(seed=s)[0] for s, e in enumerate(envs)]
    singles = [None] * 3
    batch_state = None
    for k in range(n_steps):
        starts = np.full(3, k == 0)
        batch_act, batch_state = agent.predict(
            np.stack(obs), state=batch_state, episode_start=starts
        )
        for i in range(3):
            act, singles[i] = agent.predict(
                obs[i], state=singles[i], episode_start=np.array([k == 0])
            )
            np.testing.assert_allclose(act, batch_act[i], rtol=rtol, atol=atol)
            obs[i] = envs[i].step(act)[0]


def drawn_scenarios(env: gym.Env, name: str, n: int) -> list:
    """The scenarios ``env`` draws for the random set ``name`` on resets with seeds 0 to n-1."""
    drawn = []
    for seed in range(n):
        env.reset(seed=seed, options={"scenario": name})
        drawn.append(env.unwrapped.scenario)
    return drawn


def train_and_ood_values(env_id: str, n: int, *fields: str) -> dict:
    """``{field: {"train": [...], "ood": [...]}}``: each field (a dotted attribute path) of
    the scenarios an ``env_id`` env draws for ``train`` and ``ood`` on resets with seeds 0 to
    ``n``-1."""
    from operator import attrgetter

    env = gym.make(env_id)
    draws = {name: drawn_scenarios(env, name, n) for name in TRAIN_OOD}
    env.close()
    return {f: {k: [attrgetter(f)(s) for s in v] for k, v in draws.items()} for f in fields}


def split_draws(factories: dict, splits: Sequence[str], seeds: int = 40):
    """``(split, scenario, rng)`` for each split and seed 0 to ``seeds``-1: the scenario
    that ``factories[split]`` builds from ``default_rng(seed)``, and the split's stream
    ``split_rng(default_rng(seed), split)`` from which a test draws the same numbers again,
    field by field, to check the factory's order of draws. The factories' scenarios must
    also pass their class's checks (:func:`assert_drawn_scenarios_pass_their_checks`)."""
    from machining_envs.core.splits import split_rng

    assert_drawn_scenarios_pass_their_checks(factories)
    for split in splits:
        for seed in range(seeds):
            scenario = factories[split](np.random.default_rng(seed))
            yield split, scenario, split_rng(np.random.default_rng(seed), split)


def agents_built_on_train_and_test(factory: Callable, env_id: str) -> tuple:
    """The agents ``factory`` builds from one env reset to a training draw, then to a
    held-out one: an agent designed from nominal parameters only builds the same twice."""
    env = gym.make(env_id)
    env.reset(seed=0, options={"scenario": "train"})
    a = factory(env)
    env.reset(seed=5, options={"scenario": "ood"})
    return a, factory(env)


def assert_ood_reaches_beyond_train(values: dict, low: float, high: float) -> None:
    """``values["train"]`` stay within ``[low, high]``; ``values["ood"]`` (the
    out-of-distribution draws) reach below ``low`` and above ``high``."""
    assert low <= min(values["train"]) and max(values["train"]) <= high
    assert min(values["ood"]) < low and max(values["ood"]) > high


def assert_splits_share_a_distribution_not_episodes(
    env: gym.Env, key, n: int = 60, inside: tuple[str, ...] = ()
) -> None:
    """``train``, ``validation`` and ``test`` draw different scenarios for the same seed,
    from one distribution: ``key(scenario)`` spans the same range in each (within 10 % of
    the training span at ``n`` draws); a split in ``inside`` draws from a range inside the
    training one (EndMilling-v0's ``test``: the benchmark's narrower ranges)."""
    draws = {
        s: [key(sc) for sc in drawn_scenarios(env, s, n)] for s in ("train", "validation", "test")
    }
    assert draws["train"] != draws["validation"] != draws["test"] != draws["train"]
    lo, hi = min(draws["train"]), max(draws["train"])
    span = hi - lo
    for s in ("validation", "test"):
        if s in inside:
            assert lo <= min(draws[s]) and max(draws[s]) <= hi, s
            assert max(draws[s]) - min(draws[s]) < 0.9 * span, s  # narrower, not the same
        else:
            assert abs(min(draws[s]) - lo) < 0.1 * span and abs(max(draws[s]) - hi) < 0.1 * span, s


def held_out_draws(env_id: str, split: str, field: str, n: int = 20) -> list:
    """``scenario.<field>`` of the first ``n`` seeds' draws of the held-out ``split`` of
    ``env_id``, after checking that training and tuning refuse the split."""
    import pytest

    from machining_envs.core.splits import HELD_OUT, check_not_held_out

    assert split in HELD_OUT
    with pytest.raises(ValueError, match=split):
        check_not_held_out([split], "training")
    env = gym.make(env_id).unwrapped
    draws = []
    for seed in range(n):
        env.reset(seed=seed, options={"scenario": split})
        draws.append(getattr(env.scenario, field))
    return draws


def assert_actuated(commands, actuation, command_range: float, period_s: float) -> None:
    """``commands``, the commands the drives got from the episode's start, obey
    ``actuation``: nothing before the delay, on the grid of quanta, rate and change of rate
    within their limits."""
    c = np.asarray(commands, dtype=np.float64)
    a = actuation
    np.testing.assert_array_equal(c[: a.delay_steps], 0.0)
    if a.quantum:
        grid = c / (a.quantum * command_range)
        np.testing.assert_allclose(grid, np.round(grid), atol=1e-9)
    steps = np.diff(np.concatenate([[0.0, 0.0], c]))
    assert np.abs(steps).max() <= a.max_rate_per_s * command_range * period_s + 1e-9
    assert np.abs(np.diff(steps)).max() <= a.max_accel_per_s2 * command_range * period_s**2 + 1e-9


def assert_drawn_scenarios_pass_their_checks(factories: dict, seeds: int = 150) -> None:
    """Every factory of ``factories`` (name -> factory) builds scenarios that its scenario
    class's checked constructor accepts unchanged: the factories build them without the
    checks (``machining_envs.core.checks.drawn_instance``), which is right only if every
    value they draw lies in the checked ranges. Numbers are Python floats, as the
    constructor's callers give them."""
    import dataclasses

    for name, make in factories.items():
        rng = np.random.default_rng(12345)
        for _ in range(seeds):
            sc = make(rng)
            assert dataclasses.replace(sc) == sc, name  # runs __post_init__'s checks
            for field in dataclasses.fields(sc):
                value = getattr(sc, field.name)
                assert not isinstance(value, np.generic), (name, field.name, type(value))


def started_together_and_one_by_one(env_id: str, spec, n: int = 12, **kwargs):
    """Two vector envs' cores after one ``reset(seed=5)``: lanes 0, 3, 4, 7 and 11 started
    again one by one (the per-lane path, ``core.start``) in the first and all at once
    (``core.start_lanes``) in the second; ``(one, many, lanes)``."""
    one, many = (gym.make_vec(env_id, num_envs=n, **kwargs).unwrapped for _ in range(2))
    for venv in (one, many):
        venv.reset(seed=5, options={"scenario": spec})
    lanes = np.array([0, 3, 4, 7, 11])
    for k in lanes.tolist():
        one._core.start(k, spec, one.lane_rngs[k])
    many._core.start_lanes(lanes, spec, many.lane_rngs)
    return one._core, many._core, lanes


def _arrays(obj) -> dict:
    return {k: v for k, v in vars(obj).items() if isinstance(v, np.ndarray)}


def assert_cores_alike(one, many) -> None:
    """Two cores (``started_together_and_one_by_one``) alike to the last bit: every array
    of theirs and of their plants, every lane's scenario, true parameters and name, the
    lanes' generators' states and the CNC's actuation."""
    for a, b in ((one, many), (one.lanes, many.lanes)):
        arrays_a, arrays_b = _arrays(a), _arrays(b)
        assert arrays_a.keys() == arrays_b.keys()
        for name, arr in arrays_a.items():
            np.testing.assert_array_equal(arr, arrays_b[name], err_msg=name, strict=True)
    for k in range(len(one.scenarios)):
        assert one.scenarios[k] == many.scenarios[k], k
        assert one.truths[k] == many.truths[k], k
        assert one.names[k] == many.names[k]
        state = one.rngs.generators[k].bit_generator.state
        assert state == many.rngs.generators[k].bit_generator.state, k
    acts = [c.act_lanes for c in (one, many)]
    assert (acts[0] is None) == (acts[1] is None)
    if acts[0] is not None:
        for name, arr in _arrays(acts[0]).items():
            np.testing.assert_array_equal(arr, _arrays(acts[1])[name], err_msg=name)


def train_quietly(env_id: str, out, config_path, algo: str = "ppo", **kwargs):
    """``agents.rl.train`` of ``algo`` on ``env_id`` into ``out`` with the config file
    ``config_path``, without progress bar or printing (``kwargs``: train's other keywords)."""
    from agents.rl import train

    return train(
        env_id, algo, out, config_path=config_path, progress_bar=False, verbose=False, **kwargs
    )


def refuses_file(
    path: Path, text: str, read: Callable[[Path], object], error: type[Exception], match: str
) -> None:
    """Write ``text`` to ``path``: ``read(path)`` must raise ``error`` with a message that
    matches ``match`` (the key or value of the file it refuses)."""
    path.write_text(text)
    with pytest.raises(error, match=match):
        read(path)


def refuses_config(tmp_path: Path, text: str, message: str) -> None:
    """Training Turning-v0 on a config file of ``text`` raises ``ConfigError`` matching
    ``message`` before it writes anything (no run folder, nor the folder above it)."""
    from agents.rl import ConfigError

    train = functools.partial(train_quietly, TURNING, tmp_path / "runs" / "r")
    refuses_file(tmp_path / "bad.yml", text, train, ConfigError, message)
    assert not (tmp_path / "runs").exists()


def episode_rows(times, over=None, policy_seed=None, overloaded: float = 0.0) -> list[dict]:
    """Synthetic benchmark rows, one an episode (``seed`` its index): machining time ``times``,
    share of steps over the limit ``over`` (none by default), every episode finished without
    breakage and with a score bound of 10 s; ``policy_seed`` where a learned row's seed."""
    over = np.zeros(len(times)) if over is None else over
    out = []
    for i, (t, o) in enumerate(zip(times, over, strict=True)):
        r = {
            "seed": i,
            "machining_time_s": float(t),
            "finished": 1.0,
            "breakage": 0.0,
            "time_over_limit": float(o),
            "overloaded": overloaded,
            "score_bound": 10.0,
        }
        if policy_seed is not None:
            r["policy_seed"] = policy_seed
        out.append(r)
    return out
