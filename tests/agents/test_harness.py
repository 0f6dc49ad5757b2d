"""The evaluation harness (``agents.eval``): tables and files, the same workpieces for every agent."""

import csv
from collections.abc import Mapping

import gymnasium as gym
import numpy as np
import pytest

from agents import ConstantFeed, FixedGainPI, VariableGainPI
from agents.contouring import ConstantOverride, HInf2DOF, PIPosition
from agents.drilling import PD, NoControl, PeckDrilling, SlidingMode
from agents.eval import Evaluation, evaluate
from agents.milling import FixedGainIntegral, IntegralACC, MillingConstantFeed
from agents.rl import pretrained
from tests.helpers import TURNING


def test_evaluate_table_and_csv(tmp_path):
    ev = Evaluation.concat(
        evaluate(f, TURNING, ["paper_700"], n_episodes=2, seed=0)
        for f in (FixedGainPI.from_env, VariableGainPI.from_env)
    )
    assert len(ev.rows) == 4
    assert {r["agent"] for r in ev.rows} == {"fixed PI Kh=0.02", "adaptive PI K=0.5"}
    md = ev.to_markdown(["iae", "breakage"])
    assert md.count("\n") == 3 and "0/2" in md
    path = tmp_path / "m.csv"
    ev.to_csv(path)
    rows = list(csv.DictReader(open(path)))
    assert len(rows) == 4 and float(rows[0]["iae"]) == pytest.approx(ev.rows[0]["iae"])
    with pytest.raises(ValueError, match="n_episodes"):
        evaluate(FixedGainPI.from_env, TURNING, ["paper_700"], n_episodes=0)


def test_bad_arguments_are_refused_naming_them_and_one_scenario_is_a_list_of_one():
    f = FixedGainPI.from_env
    for kwargs, error, match in (
        ({"n_episodes": True}, ValueError, "n_episodes must be an integer >= 1, got True"),
        ({"seed": -1}, ValueError, "seed must be an integer >= 0, got -1"),
        ({"seed": "a"}, ValueError, "seed must be an integer >= 0"),
        ({"env_kwargs": "x"}, TypeError, "env_kwargs must be a dict"),
        ({"batched": "yes"}, TypeError, "batched must be True, False or None"),
        ({"scenarios": []}, ValueError, "scenarios must hold at least one"),
    ):
        with pytest.raises(error, match=match):
            evaluate(f, TURNING, **{"scenarios": ["paper_700"], **kwargs})
    # A name alone was iterated letter by letter ("scenario of lane 0: ... 'p'").
    one = evaluate(f, TURNING, "paper_700", n_episodes=2)
    assert one.rows == evaluate(f, TURNING, ["paper_700"], n_episodes=2).rows


def test_a_table_of_a_metric_the_rows_lack_names_it_and_the_metrics_there_are():
    ev = evaluate(FixedGainPI.from_env, TURNING, ["paper_700"], n_episodes=2)
    with pytest.raises(ValueError, match=r"'iea' is not a column of 2 of the 2 rows.*'iae'"):
        ev.to_markdown(["iea"])  # a bare KeyError: 'iea'
    assert ev.to_markdown("iae") == ev.to_markdown(["iae"])  # was the letters i, a, e


def test_same_seeds_give_every_agent_the_same_workpieces():
    a = evaluate(
        FixedGainPI.from_env, TURNING, ["ood"], n_episodes=3, seed=5, keep_trajectories=True
    )
    b = evaluate(
        VariableGainPI.from_env, TURNING, ["ood"], n_episodes=3, seed=5, keep_trajectories=True
    )
    for ta, tb in zip(a.trajectories, b.trajectories, strict=True):
        assert ta["workpiece_length_mm"][0] == tb["workpiece_length_mm"][0]
        assert ta["spindle_rpm"][0] == tb["spindle_rpm"][0]


def test_batched_evaluation_needs_a_native_vector_env():
    with pytest.raises(ValueError, match="no native vector env"):
        evaluate(ConstantFeed.from_env, "Pendulum-v1", [None], n_episodes=2, batched=True)


def test_batched_evaluation_of_a_network_policy_agrees_to_float32_rounding():
    """A torch policy evaluated on a batch multiplies its matrices in another order than on
    one observation (float32), so its actions agree to float32 rounding, not to the last
    bit (checked here on the observations of real episodes). A closed loop running near its
    limit can grow such differences over hundreds of steps, so batched and sequential
    episodes are not compared metric by metric; both run and count the same episodes."""
    agent = pretrained("turning_ppo")(None)
    env = gym.make(TURNING)
    obs = []
    for seed in (5000, 5001):
        o, _ = env.reset(seed=seed, options={"scenario": "validation"})
        for _ in range(100):
            obs.append(o)
            o, _, term, trunc, _ = env.step(env.action_space.sample())
            if term or trunc:
                break
    obs = np.array(obs)
    batch, _ = agent.predict(obs)
    one = np.array([agent.predict(o)[0] for o in obs])
    np.testing.assert_allclose(batch, one, rtol=1e-5, atol=1e-6)
    kw = dict(n_episodes=4, seed=5000)
    a = evaluate(agent, TURNING, ["validation"], batched=False, **kw)
    b = evaluate(agent, TURNING, ["validation"], batched=True, **kw)
    assert [r["seed"] for r in a.rows] == [r["seed"] for r in b.rows]
    assert all(np.isfinite(r["machining_time_s"]) for r in a.rows + b.rows)


TURNING_ID, MILLING_ID = TURNING, "machining_envs/EndMilling-v0"
DRILLING_ID, CONTOURING_ID = "machining_envs/MicroDrilling-v0", "machining_envs/Contouring-v0"
#: (env id, env kwargs, agent factory, scenarios, episodes per scenario): every classical
#: agent of every process, on the held-out distribution and one paper scenario.
BATCHED_CASES = [
    (TURNING_ID, {}, VariableGainPI.from_env, ["ood", "paper_405"], 6),
    (TURNING_ID, {}, FixedGainPI.from_env, ["ood", "paper_405"], 6),
    (TURNING_ID, {}, ConstantFeed.from_env, ["ood", "paper_405"], 6),
    (MILLING_ID, {}, IntegralACC.from_env, ["ood", "paper_taper"], 5),
    (MILLING_ID, {}, FixedGainIntegral.from_env, ["ood", "paper_taper"], 5),
    (MILLING_ID, {}, MillingConstantFeed.from_env, ["ood", "paper_taper"], 5),
    (DRILLING_ID, {}, NoControl.from_env, ["ood", "paper_0.6"], 4),
    (DRILLING_ID, {}, PD.from_env, ["ood", "paper_0.6"], 4),
    (DRILLING_ID, {}, SlidingMode.from_env, ["ood", "paper_0.6"], 4),
    (DRILLING_ID, {"control": "feed"}, PeckDrilling.from_env, ["ood", "paper_0.6"], 4),
    (CONTOURING_ID, {}, PIPosition.from_env, ["ood", "paper_step_load"], 3),
    (CONTOURING_ID, {}, HInf2DOF.from_env, ["ood", "paper_circle_load"], 3),
    (
        "machining_envs/ContouringFeed-v0",
        {},
        ConstantOverride.from_env,
        ["ood", "paper_involute"],
        3,
    ),
]


@pytest.mark.parametrize(
    "env_id, env_kwargs, factory, scenarios, n",
    BATCHED_CASES,
    ids=[f"{c[2].__qualname__.split('.')[0]}-{c[0].split('/')[1]}" for c in BATCHED_CASES],
)
def test_batched_evaluation_gives_the_episode_by_episode_rows(
    env_id, env_kwargs, factory, scenarios, n
):
    """N episodes of one agent as the lanes of the native vector env: the same metrics and
    trajectories (values and dtypes, to the last bit) as one episode after another with the
    same seeds, for every classical agent (drilling on voltage and on feed control)."""
    kw = dict(n_episodes=n, seed=1000, keep_trajectories=True, env_kwargs=env_kwargs)
    one = evaluate(factory, env_id, scenarios, batched=False, **kw)
    batch = evaluate(factory, env_id, scenarios, batched=True, **kw)
    assert len(one.rows) == len(batch.rows) == n * len(scenarios)
    for a, b in zip(one.rows, batch.rows, strict=True):
        assert a.keys() == b.keys()
        for k in a:
            assert a[k] == b[k] or (a[k] != a[k] and b[k] != b[k]), k
    for a, b in zip(one.trajectories, batch.trajectories, strict=True):
        assert a.keys() == b.keys()
        for k, v in a.items():
            if isinstance(v, np.ndarray):
                assert v.dtype == b[k].dtype, k
                np.testing.assert_array_equal(v, b[k], err_msg=k)
            else:
                assert v == b[k], k


def _same_rows(a, b):
    assert len(a.rows) == len(b.rows)
    for ra, rb in zip(a.rows, b.rows, strict=True):
        assert ra.keys() == rb.keys()
        for k in ra:
            assert ra[k] == rb[k] or (ra[k] != ra[k] and rb[k] != rb[k]), k


def test_a_sweep_of_scenarios_runs_as_one_batch_with_the_same_rows():
    """Scenarios of one episode each (a sweep over spindle speeds) run batched by default,
    each lane on its own scenario, and give the episode-by-episode rows in the same order."""
    from machining_envs.core.workpieces import DepthProfile
    from machining_envs.turning.scenarios import TurningScenario

    bar = DepthProfile.steps((1.0, 2.0), 8.0)
    sweep = [TurningScenario(f"rpm {rpm:g}", bar, rpm) for rpm in (300.0, 450.0, 600.0)]
    scenarios = [*sweep, "validation", None]  # None: the env's default
    kw = dict(n_episodes=1, seed=5000)
    batch = evaluate(FixedGainPI.from_env, TURNING, scenarios, **kw)
    one = evaluate(FixedGainPI.from_env, TURNING, scenarios, batched=False, **kw)
    assert [r["scenario"] for r in batch.rows][:3] == ["rpm 300", "rpm 450", "rpm 600"]
    _same_rows(one, batch)


def test_an_evaluation_larger_than_a_batch_runs_in_several(monkeypatch):
    import agents.eval.harness as harness

    made = []
    real = gym.make_vec
    monkeypatch.setattr(harness, "MAX_BATCH_LANES", 3)
    monkeypatch.setattr(
        harness.gym, "make_vec", lambda *a, **k: made.append(k["num_envs"]) or real(*a, **k)
    )
    kw = dict(n_episodes=4, seed=1000)
    batch = evaluate(ConstantFeed.from_env, TURNING, ["ood", "paper_405"], batched=True, **kw)
    assert made == [3, 2]  # batches of 3, 3 and 2 lanes: one env for the first two
    one = evaluate(ConstantFeed.from_env, TURNING, ["ood", "paper_405"], batched=False, **kw)
    _same_rows(one, batch)


def test_a_batch_needs_the_same_step_autoreset():
    """A batch reads each lane's last step from ``final_info``: another mode is refused."""
    from agents.eval.harness import rollout_batch

    venv = gym.make_vec(TURNING, num_envs=2, autoreset_mode="NEXT_STEP")
    with pytest.raises(ValueError, match="same-step"):
        rollout_batch(ConstantFeed.from_env(gym.make(TURNING)), venv, "train", [0, 1])


class _Recording(Mapping):
    """A trajectory that notes every key read from it or tested with ``in``."""

    def __init__(self, traj: dict):
        self.traj, self.read = traj, set()

    def __getitem__(self, key):
        self.read.add(key)
        return self.traj[key]

    def __contains__(self, key):
        self.read.add(key)
        return key in self.traj

    def __iter__(self):
        raise AssertionError("a metrics function that declares its keys lists them all")

    def __len__(self):
        return len(self.traj)


KEYS_CASES = [BATCHED_CASES[i] for i in (2, 3, 8, 9, 11, 12)]


@pytest.mark.parametrize(
    "env_id, env_kwargs, factory, scenarios, n",
    KEYS_CASES,
    ids=[f"{c[2].__qualname__.split('.')[0]}-{c[0].split('/')[1]}" for c in KEYS_CASES],
)
def test_metrics_read_only_the_info_keys_they_declare(env_id, env_kwargs, factory, scenarios, n):
    """The envs' metrics declare the info keys they read (``reads_info``): on whole
    trajectories they read no other, and an evaluation that records only those keys (the
    default where trajectories are not kept), batched or not, gives the rows of one that
    records every key."""
    from agents.eval import task_of

    metrics = task_of(gym.make(env_id, **env_kwargs)).metrics
    declared = metrics.info_keys | {"reward", "scenario"}
    kw = dict(n_episodes=n, seed=2000, env_kwargs=env_kwargs)
    full = evaluate(factory, env_id, scenarios, keep_trajectories=True, **kw)
    read = set()
    for traj in full.trajectories:
        rec = _Recording(traj)
        metrics(rec)
        read |= rec.read
    assert read <= declared, sorted(read - declared)
    _same_rows(full, evaluate(factory, env_id, scenarios, **kw))
    _same_rows(full, evaluate(factory, env_id, scenarios, batched=False, **kw))


def test_only_the_declared_keys_are_recorded():
    """What the harness keeps of an episode it scores: the metrics' keys, with the reward
    and the scenario; a metrics function that declares none gets every numeric key."""
    from agents.eval.harness import rollout

    env = gym.make(TURNING)
    agent = ConstantFeed.from_env(env)
    some = rollout(agent, env, "validation", 3, keys={"t_s", "force_N", "no_such_key"})
    assert set(some) == {"t_s", "force_N", "reward", "scenario"}
    every = rollout(agent, env, "validation", 3)
    assert {"t_s", "force_N", "depth_mm", "segment", "cost"} <= set(every)
    np.testing.assert_array_equal(some["force_N"], every["force_N"])
