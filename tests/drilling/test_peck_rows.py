"""The peck rows of MicroDrilling-v0's benchmark: the tuned peck cycles and the pecking
policy run with control="feed" on the benchmark's episodes, scored by the same task."""

import gymnasium as gym
import numpy as np
import pytest

from agents.bench.drilling import ENV_ID
from agents.bench.run import jobs_of
from agents.bench.tune import load_tuned
from agents.drilling import (
    NoControl,
    PeckDrilling,
    SlidingMode,
    TorquePeck,
    VoltagePeck,
    VoltageTorquePeck,
)
from agents.eval import task_of
from machining_envs.core.splits import split_seeds

FEED = {"control": "feed"}
VOLTAGE_FEED = {"control": "voltage_feed"}
PECK_POLICY = "micro_drilling_ppo_peck"


def _spec():
    from agents.bench.declarations import BENCHMARKS

    return next(s for s in BENCHMARKS if s.env_id == ENV_ID)


def test_the_drilling_benchmark_has_tuned_peck_rows_and_the_peck_policy():
    from agents.rl import SUPERSEDED

    spec = _spec()
    assert {PeckDrilling, TorquePeck, VoltagePeck, VoltageTorquePeck} <= set(spec.tuned)
    # the policy over the fast-spindle cycle replaced the one over the feed cycle
    assert spec.learned == (SUPERSEDED[PECK_POLICY],)
    assert spec.env_kwargs == {}  # the other rows keep the paper's voltage loop


def test_the_peck_rows_drill_the_same_holes_under_the_same_rules():
    """Paired differences between a voltage row and a feed row mean something: the same
    seed draws the same hole (drill, depth, hidden cutting and chip constants, limit,
    breakage torque, overload ceiling), the same time limit is charged for a hole that does
    not count, and one task computes the metrics and the score."""
    plain, feed = gym.make(ENV_ID), gym.make(ENV_ID, **FEED)
    for seed in split_seeds("validation", 3):
        _, a = plain.reset(seed=seed, options={"scenario": "validation"})
        _, b = feed.reset(seed=seed, options={"scenario": "validation"})
        assert plain.unwrapped.scenario == feed.unwrapped.scenario
        for key in ("diameter_mm", "target_depth_mm", "torque_limit_Nmm", "breakage_torque_Nmm"):
            assert a[key] == b[key]
        assert a["overload_ratio"] == b["overload_ratio"]
    assert task_of(plain) is task_of(feed)
    score = task_of(plain).score
    assert score.failed_value(plain) == score.failed_value(feed) == 150.0


def test_the_peck_rows_run_on_the_feed_env_the_others_on_the_spec_s():
    spec = _spec()
    pytest.importorskip("stable_baselines3")
    jobs = jobs_of(spec, load_tuned(), verbose=False, one_seed=True)
    by_cls = {j.tuned_cls: j for j in jobs if j.kind == "tuned"}
    assert by_cls[PeckDrilling].env_kwargs == FEED
    assert by_cls[TorquePeck].env_kwargs == FEED
    for cls in (VoltagePeck, VoltageTorquePeck):  # the spindle commanded beside the cycle
        assert by_cls[cls].env_kwargs == {"control": "voltage_feed"}
    assert by_cls[NoControl].env_kwargs is None and by_cls[SlidingMode].env_kwargs is None
    learned = [j for j in jobs if j.kind == "learned"]
    # the peck policy over VoltageTorquePeck
    assert [j.env_kwargs for j in learned] == [VOLTAGE_FEED]
    env = gym.make(spec.env_id, **{**spec.env_kwargs, **by_cls[PeckDrilling].env_kwargs})
    assert by_cls[PeckDrilling].factory(env).name.endswith("(tuned)")


def test_the_peck_policy_loads_for_its_env_and_refuses_the_voltage_loop():
    """The shipped policy acts on control="feed" (its run's options); on the paper's voltage
    env its feed velocities would be read as valve voltages: refused, naming the option."""
    pytest.importorskip("stable_baselines3")
    from agents.rl.policy import load_policy, policy_env_kwargs, pretrained_seeds

    seed, path = pretrained_seeds(PECK_POLICY)[0]
    assert policy_env_kwargs(path) == FEED
    env = gym.make(ENV_ID, **FEED)
    agent = load_policy(path, env=env)
    obs, _ = env.reset(seed=split_seeds("validation", 1)[0], options={"scenario": "validation"})
    state = None
    for _ in range(400):
        a, state = agent.predict(obs, state)
        assert np.all(np.isfinite(a)) and a.shape == (1,)
        obs, r, te, tr, info = env.step(a)
        assert np.isfinite(r)
        assert not (te and info["breakage"])
    with pytest.raises(ValueError, match="control='feed'"):
        load_policy(path, env=gym.make(ENV_ID))


def test_torque_peck_retracts_when_the_torque_reaches_its_share_of_the_limit():
    env = gym.make(ENV_ID, **FEED)
    with pytest.raises(ValueError, match="torque_share"):
        TorquePeck.from_env(env, torque_share=0.0)
    with pytest.raises(ValueError, match="torque_share"):
        TorquePeck.from_env(env, torque_share=float("nan"))
    with pytest.raises(ValueError, match="control='feed'"):
        TorquePeck.from_env(gym.make(ENV_ID))
    agent = TorquePeck.from_env(env, torque_share=0.5, feed_scale=0.7)
    obs, _ = env.reset(seed=0, options={"scenario": "paper_0.6"})
    state, seen = None, []
    for _ in range(3000):
        a, state = agent.predict(obs, state)
        x = np.asarray(obs, dtype=np.float64)[None, :]
        torque, limit = agent.io.torque(x)
        depth = agent.io.lengths_mm(x)[1][0]
        if float(a[0]) < 0.0:  # the first retract
            break
        seen.append((float(torque[0] / limit[0]), depth))
        obs, _, te, tr, _ = env.step(a)
        assert not (te or tr)
    else:
        raise AssertionError("it never pecked")
    assert torque[0] >= 0.5 * limit[0]  # it retracted on the torque,
    assert depth >= 0.25 * 0.6  # once the peck was a quarter diameter deep,
    assert all(t < 0.5 for t, d in seen if d >= 0.25 * 0.6)  # and not before either
    assert depth < 8 * 0.6  # far above the (disabled) depth trigger and the hole's bottom


def test_peck_cycles_with_a_voltage_refuse_the_other_modes_and_bad_voltages():
    for cls in (VoltagePeck, VoltageTorquePeck):
        for control in ("voltage", "feed"):
            with pytest.raises(ValueError, match="control='voltage_feed', got"):
                cls.from_env(gym.make(ENV_ID, control=control))
        env = gym.make(ENV_ID, **VOLTAGE_FEED)
        for bad in (-0.1, 10.5, float("nan")):
            with pytest.raises(ValueError, match="voltage"):
                cls.from_env(env, voltage=bad)
    with pytest.raises(ValueError, match="voltage applies to control='voltage_feed' only"):
        PeckDrilling.from_env(gym.make(ENV_ID, **FEED), voltage=8.0)


def test_the_feed_mode_is_the_voltage_feed_mode_at_the_nominal_voltage():
    """PeckDrilling on control="voltage_feed" at its default voltage (the nominal 5 V) drills
    the hole of control="feed" to the last bit: the new mode only adds the spindle."""
    seed = split_seeds("validation", 1)[0]
    runs = []
    for kwargs in (FEED, VOLTAGE_FEED):
        env = gym.make(ENV_ID, **kwargs)
        agent = PeckDrilling.from_env(env, peck_diameters=1.5, feed_scale=0.7)
        obs, _ = env.reset(seed=seed, options={"scenario": "validation"})
        state, rows, done = None, [], False
        while not done:
            a, state = agent.predict(obs, state)
            obs, r, te, tr, info = env.step(a)
            done = te or tr
            o = obs.tolist()
            if len(o) == 13:  # the feed's previous action is entry 12 there, not 4
                o[4] = o.pop(12)
            rows.append((r, o, info["torque_Nmm"], info["position_mm"]))
        runs.append(rows)
    assert len(runs[0]) > 1000 and runs[0] == runs[1]


def test_voltage_peck_holds_its_voltage_and_pecks_out_of_the_hole():
    env = gym.make(ENV_ID, **VOLTAGE_FEED)
    for agent in (
        VoltagePeck.from_env(env, voltage=9.0, peck_diameters=1.0, feed_scale=1.5),
        VoltageTorquePeck.from_env(env, voltage=9.0, torque_share=0.9, feed_scale=2.0),
    ):
        assert agent.name.endswith(", 9 V") and agent.obs_dim == 13
        obs, _ = env.reset(seed=0, options={"scenario": "paper_0.6"})
        state, done, outside = None, False, 0
        while not done:
            a, state = agent.predict(obs, state)
            assert a.shape == (2,) and float(a[0]) == pytest.approx(0.8)  # 9 V
            obs, _, te, tr, info = env.step(a)
            done = te or tr
            outside += info["position_mm"] < 0.0 < info["depth_mm"]
            assert info["voltage_V"] == pytest.approx(9.0)
        assert info["finished"] and outside > 0, agent.name


def test_the_bound_row_is_the_reference_s_floor_which_no_voltage_row_sets():
    """The tuned rows on control="voltage_feed" drill faster than the voltage rows' floor
    (the travel at the programmed feed); the physical bound row is the floor on the
    reference's own episodes, the fast spindle's floor when the reference pecks there.
    (Two ``validation`` episodes through ``split_results``; ``test`` is not run.)"""
    from agents.bench.results import reference, split_results
    from agents.bench.run import EnvRun
    from agents.bench.tune import agent_env_kwargs, tuned_factory
    from agents.eval import evaluate
    from agents.eval.stats import iqm

    tuned = load_tuned()
    run = EnvRun(_spec())
    for cls in (NoControl, VoltageTorquePeck):
        factory = tuned_factory(cls, ENV_ID, tuned)
        name = factory(gym.make(ENV_ID, **agent_env_kwargs(cls))).name
        ev = evaluate(
            factory,
            ENV_ID,
            ["validation"],
            n_episodes=2,
            seed=split_seeds("validation", 2)[0],
            env_kwargs=agent_env_kwargs(cls),
        )
        run.add(name, "tuned", "validation", ev.rows)
        run.tuned_cls[name] = cls
    ref = reference(run, tuned)
    assert run.tuned_cls[ref] is VoltageTorquePeck  # the lowest validation score
    sr = split_results(run, "validation", ref)
    floors = [r["score_bound"] for r in run.rows[ref]["validation"]]
    voltage = next(n for n, c in run.tuned_cls.items() if c is NoControl)
    programmed = [r["score_bound"] for r in run.rows[voltage]["validation"]]
    assert sr.bound_iqm == pytest.approx(float(iqm(np.array(floors))))
    assert all(f < p for f, p in zip(floors, programmed, strict=True))
    assert all(r["drilling_time_s"] >= r["score_bound"] for r in run.rows[ref]["validation"])
