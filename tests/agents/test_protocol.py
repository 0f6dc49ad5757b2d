"""The benchmark protocol: tuning and training never evaluate on the held-out splits, the
splits are fixed and disjoint, the statistics behave, the tuned settings reload."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import machining_envs.core.env as core_env
import machining_envs.core.vector as core_vector
from agents.bench.tune import (
    TuningBudget,
    agent_env_kwargs,
    load_tuned,
    paper_settings,
    tune_agent,
    tuned_factory,
)
from agents.rl import ConfigError
from agents.turning import FixedGainPI
from machining_envs.core.score import REGULATION_SCORE
from machining_envs.core.splits import HELD_OUT, SPLITS, check_not_held_out, split_seeds
from tests.helpers import TURNING, episode_rows, train_quietly


@pytest.fixture
def scenarios_seen(monkeypatch):
    """Every scenario any Turning-v0 reset (single env or vector lane) asks for."""
    seen: list = []
    real = core_env.scenario_option

    def spy(options, default):
        spec = real(options, default)
        for one in spec if isinstance(spec, list) else [spec]:  # a list: one per lane
            seen.append(one if isinstance(one, str) else getattr(one, "name", one))
        return spec

    monkeypatch.setattr(core_env, "scenario_option", spy)  # the single envs' resets (LaneEnv)
    monkeypatch.setattr(core_vector, "scenario_option", spy)  # the vector envs' lanes
    return seen


def test_tuning_never_evaluates_on_held_out_splits(scenarios_seen):
    entry = tune_agent(FixedGainPI, TURNING, TuningBudget(trials=2, episodes=2, startup=1))
    assert set(scenarios_seen) == {"train", "validation"}, set(scenarios_seen)
    assert entry["params"].keys() == FixedGainPI.TUNABLE.keys()
    # The first trial is the paper's settings: tuning never reports worse on train.
    assert entry["train_score"] <= entry["paper_train_score"]


TINY = """
machining_envs/Turning-v0:
  n_timesteps: 128
  n_envs: 2
  normalize: true
  env_kwargs: {scenario: train}
  eval_freq: 64
  eval_episodes: 1
  checkpoint_freq: 128
  n_steps: 64
  batch_size: 64
  n_epochs: 1
"""


def test_training_selects_on_validation_and_never_touches_held_out(tmp_path, scenarios_seen):
    path = tmp_path / "tiny.yml"
    path.write_text(TINY)
    run = train_quietly(TURNING, tmp_path / "run", path)
    assert set(scenarios_seen) == {"train", "validation"}, set(scenarios_seen)
    cfg = json.loads((run / "config.json").read_text())["config"]
    assert cfg["eval_scenarios"] == ["validation"]


@pytest.mark.parametrize("split", HELD_OUT)
@pytest.mark.parametrize("where", ["eval_scenarios: [{}]", "env_kwargs: {{scenario: {}}}"])
def test_training_refuses_held_out_splits(tmp_path, split, where):
    text = TINY + f"  {where.format(split)}\n"
    if where.startswith("env_kwargs"):
        text = TINY.replace("env_kwargs: {scenario: train}", where.format(split))
    path = tmp_path / "bad.yml"
    path.write_text(text)
    with pytest.raises(ConfigError, match="held-out"):
        train_quietly(TURNING, tmp_path / "run", path)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("split", HELD_OUT)
def test_tuning_refuses_held_out_splits(split):
    with pytest.raises(ValueError, match="held-out"):
        tune_agent(FixedGainPI, TURNING, TuningBudget(trials=1, episodes=1), {"scenario": split})
    with pytest.raises(ValueError, match="held-out"):
        check_not_held_out(["validation", split], "tuning")


def test_split_seeds_are_fixed_and_disjoint():
    blocks = [set(split_seeds(s, 1000)) for s in SPLITS]
    assert all(a.isdisjoint(b) for i, a in enumerate(blocks) for b in blocks[i + 1 :])
    assert list(split_seeds("test", 2)) == [10000, 10001]
    with pytest.raises(ValueError, match="n .* must be an integer in"):
        split_seeds("test", 0)
    with pytest.raises(ValueError, match="split must be one of"):
        split_seeds("dev", 3)


def test_tuned_file_ships_settings_for_every_tuned_agent():
    """``agents/bench/tuned.json`` holds settings for every ``tuned`` class of every
    benchmark, within the class's ranges, and the factories rebuild those agents."""
    from agents.bench.declarations import BENCHMARKS

    data = load_tuned()
    assert data.get("command", "").startswith("machining-bench tune")
    for spec in BENCHMARKS:
        for cls in spec.tuned:
            entry = data["envs"][spec.env_id][cls.__name__]
            env = gym.make(spec.env_id, **agent_env_kwargs(cls, spec.env_kwargs))
            assert entry["paper_params"] == paper_settings(cls, env)
            for k, (lo, hi, _) in cls.TUNABLE.items():
                assert lo <= entry["params"][k] <= hi
            assert entry["train_score"] <= entry["paper_train_score"]
            assert tuned_factory(cls, spec.env_id, data) is not None


def test_the_benchmark_warns_when_the_tuned_settings_are_missing(tmp_path, monkeypatch):
    """Without ``tuned.json`` (an install that lost it) the benchmark's table would hold no
    tuned classical agent: it says so instead of dropping them quietly."""
    import warnings

    from agents.bench import benchmark, tune

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the shipped file: no warning
        assert benchmark._tuned_settings()["envs"]
    monkeypatch.setattr(tune, "TUNED_FILE", tmp_path / "tuned.json")
    with pytest.warns(UserWarning, match="tuned.json not found: the benchmark runs no tuned"):
        assert benchmark._tuned_settings() == {}


def test_statistics_pair_episodes_and_bracket_the_truth():
    from agents.eval.stats import agent_stats, paired_difference

    rng = np.random.default_rng(0)
    base = 30.0 + rng.normal(0.0, 3.0, 100)
    ref = episode_rows(base)
    better = episode_rows(base - 2.0)  # exactly 2 s better on every episode
    d = paired_difference(ref, better, REGULATION_SCORE, 200.0)
    assert d["diff"] == pytest.approx(2.0) and d["low"] == d["high"] == pytest.approx(2.0)
    assert d["p_improve"] == 1.0
    s = agent_stats(ref, REGULATION_SCORE, 200.0)
    assert s.iqm_low <= s.iqm <= s.iqm_high and s.count_rate == 1.0
    assert s.efficiency == pytest.approx(np.mean(10.0 / base))
    # Five policy seeds are five columns of the same episodes.
    seeds = [r for k in range(5) for r in episode_rows(base + k, policy_seed=k)]
    s5 = agent_stats(seeds, REGULATION_SCORE, 200.0)
    assert s5.n_seeds == 5 and s5.n_episodes == 100 and s5.mean == pytest.approx(base.mean() + 2)
    # An episode that does not count is charged the failure cost.
    broken = episode_rows(base)
    broken[0]["breakage"] = 1.0
    assert agent_stats(broken, REGULATION_SCORE, 200.0).count_rate == 0.99


def test_iqm_is_rliables_to_the_last_bit():
    """The benchmark's IQM (``agents.eval.stats.iqm``) is rliable's ``aggregate_iqm`` to the
    last bit, NaN, infinities, ties and every size from 1 included; so are the bootstrap
    intervals built on it."""
    import warnings

    from rliable import library, metrics

    from agents.eval.stats import iqm, iqm_interval, rliable_seed

    rng = np.random.default_rng(5)
    for n in [*range(1, 40), 97, 100, 500]:
        for cols in (1, 3):
            m = rng.normal(30.0, 5.0, (n, cols)).round(rng.integers(0, 3))  # ties too
            if n > 4 and rng.random() < 0.3:
                m.flat[rng.integers(m.size)] = rng.choice([np.inf, -np.inf, np.nan])
            want = metrics.aggregate_iqm(m)
            got = iqm(m)
            assert (np.isnan(want) and np.isnan(got)) or got.tobytes() == want.tobytes(), (n, m)
    assert np.isnan(iqm(np.zeros((0, 3))))
    m = rng.normal(30.0, 5.0, (40, 2))
    with warnings.catch_warnings(), rliable_seed(3):
        warnings.simplefilter("ignore", FutureWarning)
        point, ci = library.get_interval_estimates(
            {"a": m},
            lambda x: np.array([metrics.aggregate_iqm(x)]),
            reps=2000,
            random_state=np.random.RandomState(3),
        )
    assert iqm_interval(m, 3) == (point["a"][0], ci["a"][0, 0], ci["a"][1, 0])


def test_bootstrap_intervals_are_reproducible_and_leave_numpys_global_state_alone():
    """rliable resamples from numpy's global generator whatever ``random_state`` it is
    given; the benchmark seeds that generator for the call (``rliable_seed``): the same
    seed gives the same interval, another seed another one, and the caller's global
    state is as it was."""
    from agents.eval.stats import iqm_interval

    m = np.random.default_rng(1).normal(30.0, 5.0, (60, 1))
    np.random.seed(123)  # noqa: NPY002 - the state a user's code may hold
    before = np.random.get_state()[1].copy()  # noqa: NPY002
    first = iqm_interval(m, 0)
    np.random.random(7)  # noqa: NPY002 - the caller moves the global generator on
    assert iqm_interval(m, 0) == first
    assert iqm_interval(m, 1)[1:] != first[1:]
    np.random.seed(123)  # noqa: NPY002
    iqm_interval(m, 0)
    assert np.array_equal(np.random.get_state()[1], before)  # noqa: NPY002


def _tuned_cases():
    from agents.bench.declarations import BENCHMARKS

    return [(spec, cls) for spec in BENCHMARKS for cls in spec.tuned]


@pytest.mark.parametrize(
    "spec, cls", _tuned_cases(), ids=lambda v: getattr(v, "__name__", getattr(v, "env_id", v))
)
def test_tuned_agents_run_under_sb3_evaluate_policy(spec, cls):
    """The benchmark's tuned rows are plain agents: SB3's ``evaluate_policy`` runs them."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    scenario = spec.paper_scenarios[0]
    venv = DummyVecEnv(
        [
            lambda: Monitor(
                gym.make(spec.env_id, scenario=scenario, **agent_env_kwargs(cls, spec.env_kwargs))
            )
        ]
    )
    agent = tuned_factory(cls, spec.env_id)(venv.envs[0])
    assert agent.name.endswith("(tuned)")
    mean, _ = evaluate_policy(agent, venv, n_eval_episodes=1)
    assert np.isfinite(mean)
