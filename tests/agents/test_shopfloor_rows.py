"""The benchmark's shop-floor rows: the classical agents tuned for the shop-floor machine
run on the ``shopfloor`` split only, with the machine's env options, labelled as such, and
are judged against the constant feed tuned for that machine."""

import dataclasses
import json

from agents import AdaptiveFeedControl, ConstantFeed
from agents.bench.declarations import BENCHMARKS, benchmark_spec
from agents.bench.results import machine_reference, reference, split_results
from agents.bench.run import jobs_of, run_env
from agents.bench.tune import SHOPFLOOR_TUNED_FILE, load_tuned, paper_settings
from agents.eval.stats import allowance_sweep
from machining_envs.core.machine import SHOPFLOOR_MACHINE

TURNING = "machining_envs/Turning-v0"


def _machine_file(spec, env):
    """A tuned-for-the-machine file holding the classes' default settings."""
    entries = {}
    for cls in spec.machine_classes:
        entries[cls.__name__] = {"params": paper_settings(cls, env), "validation_score": 1.0}
    return {
        "envs": {spec.env_id: entries},
        "env_kwargs": {spec.env_id: SHOPFLOOR_MACHINE.env_kwargs(spec.env_id)},
    }


def test_every_shopfloor_env_declares_its_machine_rows_and_reference():
    for spec in BENCHMARKS:
        if "shopfloor" not in spec.extra_splits:
            continue
        assert spec.machine_tuned, spec.env_id
        assert spec.machine_reference in spec.machine_tuned, spec.env_id
    assert AdaptiveFeedControl in benchmark_spec("machining_envs/EndMilling-v0").machine_tuned


def test_jobs_run_on_the_shopfloor_split_with_the_machine():
    import gymnasium as gym

    spec = benchmark_spec(TURNING)
    env = gym.make(TURNING)
    data = _machine_file(spec, env)
    env.close()
    jobs = [j for j in jobs_of(spec, {}, False, machine_tuned=data) if j.machine_cls]
    assert [j.machine_cls for j in jobs] == list(spec.machine_tuned)
    for j in jobs:
        assert j.splits == ("shopfloor",)
        assert j.env_kwargs == SHOPFLOOR_MACHINE.env_kwargs(TURNING)
        assert j.tuned_cls is None  # not a candidate for the ideal rows' reference
    # No machine file: no such rows.
    assert not [j for j in jobs_of(spec, {}, False) if j.machine_cls]


def test_a_spec_naming_no_machine_classes_runs_its_tuned_ones_as_tune_tunes_them():
    import gymnasium as gym

    spec = dataclasses.replace(benchmark_spec(TURNING), machine_tuned=())
    assert spec.machine_classes == spec.tuned
    env = gym.make(TURNING)
    data = _machine_file(spec, env)
    env.close()
    assert set(data["envs"][TURNING]) == {cls.__name__ for cls in spec.tuned}
    jobs = [j for j in jobs_of(spec, {}, False, machine_tuned=data) if j.machine_cls]
    assert [j.machine_cls for j in jobs] == list(spec.tuned)


def test_rows_labelled_and_judged_against_the_machine_constant_feed():
    import gymnasium as gym

    full = benchmark_spec(TURNING)
    spec = dataclasses.replace(
        full,
        paper_agents=(),
        learned=(),
        oracle=None,
        tuned=(ConstantFeed,),
        machine_tuned=(ConstantFeed, AdaptiveFeedControl),
        extra_splits=("shopfloor",),
    )
    env = gym.make(TURNING)
    data = _machine_file(spec, env)
    ideal = {
        "envs": {
            TURNING: {
                "ConstantFeed": {
                    "params": paper_settings(ConstantFeed, env),
                    "validation_score": 1.0,
                }
            }
        }
    }
    env.close()
    run = run_env(spec, 2, 3, 0, ideal, False, 0.0, machine_tuned=data)
    shop = [n for n in run.machine_cls]
    assert len(shop) == 2 and all(n.endswith("(tuned, shop floor)") for n in shop)
    for n in shop:  # the shopfloor split only, with the machine's options
        assert set(run.rows[n]) == {"shopfloor"} and len(run.rows[n]["shopfloor"]) == 3
    ref, shop_ref = reference(run, ideal), machine_reference(run)
    assert (
        ref.endswith("(tuned)") and shop_ref in shop and run.machine_cls[shop_ref] is ConstantFeed
    )
    sr = split_results(run, "shopfloor", ref)
    assert sr.agents[shop_ref].verdict == "reference (shop floor)"
    afc = next(n for n in shop if n != shop_ref)
    assert sr.agents[afc].verdict.endswith("(vs the shop-floor reference)")
    assert (
        sr.agents[afc].diffs
        == allowance_sweep(
            run.rows[shop_ref]["shopfloor"], run.rows[afc]["shopfloor"], run.score, run.failed, 0
        )[0]
    )
    assert len(sr.agents[afc].diffs) == 3
    assert sr.agents[ref].verdict == "reference"
    # Not run where the split is not (test only: the quick run has no extra split).
    quick = run_env(spec, 2, 0, 0, ideal, False, 0.0, machine_tuned=data)
    assert not quick.machine_cls


def test_shipped_file_covers_every_machine_row():
    data = load_tuned(SHOPFLOOR_TUNED_FILE)
    assert data, f"{SHOPFLOOR_TUNED_FILE} ships with the package and must hold the settings"
    assert data["command"].startswith("machining-bench tune")
    for spec in BENCHMARKS:
        if not spec.machine_tuned:
            continue
        assert set(data["envs"][spec.env_id]) == {c.__name__ for c in spec.machine_tuned}
        assert data["env_kwargs"][spec.env_id] == SHOPFLOOR_MACHINE.env_kwargs(spec.env_id)
    json.dumps(data)


def test_full_run_judges_the_shopfloor_split_on_100_episodes():
    import gymnasium as gym

    from agents.bench.benchmark import EXTRA_SIZES, SIZES

    assert EXTRA_SIZES["full"]["shopfloor"] == SIZES["full"][0] == 100
    assert EXTRA_SIZES["quick"] == {} and SIZES["quick"][1] == 0  # --quick runs no extra split
    spec = dataclasses.replace(
        benchmark_spec(TURNING),
        paper_agents=(),
        learned=(),
        oracle=None,
        tuned=(),
        machine_tuned=(ConstantFeed,),
        extra_splits=("wear", "shopfloor"),
    )
    env = gym.make(TURNING)
    data = _machine_file(spec, env)
    env.close()
    run = run_env(spec, 1, 2, 0, {}, False, 0.0, machine_tuned=data, n_extra={"shopfloor": 4})
    assert run.n_episodes == {"test": 1, "ood": 2, "wear": 2, "shopfloor": 4}
    (name,) = run.machine_cls
    assert len(run.rows[name]["shopfloor"]) == 4
    # without ood (the quick run) no extra split runs, whatever n_extra says
    quick = run_env(spec, 1, 0, 0, {}, False, 0.0, machine_tuned=data, n_extra={"shopfloor": 4})
    assert quick.n_episodes == {"test": 1}


def test_machine_search_space_and_the_shipped_settings_within_it():
    """Tuned for a machine, a class searches its ``MACHINE_TUNABLE`` (the AFC: also
    ``fmin``), else its ``TUNABLE``; the shipped Turning-v0 and ContouringFeed-v0 entries
    hold a value within range for every key of that space."""
    import gymnasium as gym

    from agents import ContourAFC
    from agents.bench.tune import TuningBudget, search_space, tune_agent

    assert search_space(AdaptiveFeedControl) == AdaptiveFeedControl.TUNABLE
    assert set(search_space(AdaptiveFeedControl, machine=True)) == {
        *AdaptiveFeedControl.TUNABLE,
        "fmin",
    }
    assert search_space(ConstantFeed, machine=True) == ConstantFeed.TUNABLE
    kwargs = SHOPFLOOR_MACHINE.env_kwargs(TURNING)
    entry = tune_agent(AdaptiveFeedControl, TURNING, TuningBudget(1, 1, 0), kwargs, machine=True)
    assert (
        set(entry["params"])
        == set(entry["paper_params"])
        == set(AdaptiveFeedControl.MACHINE_TUNABLE)
    )
    assert entry["paper_params"]["fmin"] == 0.7
    data = load_tuned(SHOPFLOOR_TUNED_FILE)
    for env_id in (TURNING, "machining_envs/ContouringFeed-v0"):
        spec = benchmark_spec(env_id)
        env = gym.make(env_id, **data["env_kwargs"][env_id])
        for cls in spec.machine_tuned:
            e = data["envs"][env_id][cls.__name__]
            space = search_space(cls, machine=True)
            assert set(e["params"]) == set(space), (env_id, cls.__name__)
            assert all(lo <= e["params"][k] <= hi for k, (lo, hi, _) in space.items())
            assert e["paper_params"] == paper_settings(cls, env, machine=True)
        env.close()
    assert ContourAFC in benchmark_spec("machining_envs/ContouringFeed-v0").machine_tuned
