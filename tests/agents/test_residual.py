"""Residual setpoint policies: the wrapper, its vector form and the replaying agent agree, and
a zero policy is the tuned regulator."""

import csv

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from agents.bench.tune import tuned_factory  # noqa: E402
from agents.rl import ConfigError, load_config  # noqa: E402
from agents.rl.residual import (  # noqa: E402
    ResidualAgent,
    ResidualSpec,
    SetpointResidual,
    vec_setpoint_residual,
)
from agents.rl.vec import SB3VecEnv  # noqa: E402
from agents.turning import VariableGainPI  # noqa: E402
from tests.helpers import TURNING, train_quietly  # noqa: E402

BASE = "agents.turning.VariableGainPI"


class _Policy:
    """A deterministic stand-in for a trained policy: the setpoint action from the force."""

    name = "stand-in"

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        obs = np.atleast_2d(obs).astype(np.float32)  # as SB3 sees observations
        return np.tanh(np.float32(3.0) * (np.float32(0.6) - obs[:, :1])), state


def _zero_policy_runs_the_tuned_agent(env_id, cls, steps, **residual):
    """Step the residual env with zero actions beside the tuned agent on the plain env;
    every observation, reward and end flag must agree. Returns the two envs, the last
    observation, the tuned agent and the last info."""
    env = SetpointResidual(gym.make(env_id), f"{cls.__module__}.{cls.__name__}", **residual)
    plain = gym.make(env_id)
    agent = tuned_factory(cls, env_id)(plain)
    o, _ = env.reset(seed=5)
    p, _ = plain.reset(seed=5)
    st, info = None, {}
    for _ in range(steps):
        a, st = agent.predict(p, st)
        o, r, te, tr, info = env.step(np.zeros(env.action_space.shape, np.float32))
        p, rp, tep, trp, _ = plain.step(a)
        np.testing.assert_array_equal(o, p)
        assert (r, te, tr) == (rp, tep, trp)
        if te or tr:
            break
    return env, plain, o, agent, info


def test_a_zero_policy_is_the_tuned_regulator_step_for_step():
    *_, agent, info = _zero_policy_runs_the_tuned_agent(TURNING, VariableGainPI, 600)
    assert info["setpoint"] == pytest.approx(agent.setpoint)


def test_over_the_tuned_afc_a_zero_policy_is_the_afc_and_a_raised_cap_cuts_faster():
    from agents.afc import AdaptiveFeedControl

    kw = {"knob": "fmax", "span": 1.0, "lo": 1.0, "hi": 4.0}
    env, *_, agent, info = _zero_policy_runs_the_tuned_agent(
        TURNING, AdaptiveFeedControl, 600, **kw
    )
    assert info["setpoint"] == pytest.approx(agent.fmax)
    # the policy's cap reaches the AFC: at the top of the span the workpiece is cut sooner
    steps = {}
    for a in (0.0, 1.0):
        env.reset(seed=5)
        te = tr = False
        steps[a] = 0
        while not (te or tr):
            *_, te, tr, _ = env.step(np.full(env.action_space.shape, a, np.float32))
            steps[a] += 1
    assert steps[1.0] < 0.95 * steps[0.0]


def test_the_replaying_agent_runs_what_the_wrapper_ran():
    policy = _Policy()
    wrapped = SetpointResidual(gym.make(TURNING), BASE, span=0.3)
    plain = gym.make(TURNING)
    agent = ResidualAgent(policy, wrapped.residual, wrapped.residual.make_base(plain))
    o, _ = wrapped.reset(seed=11)
    p, _ = plain.reset(seed=11)
    st, setpoints = None, set()
    for _ in range(300):
        u, st = agent.predict(p, st)
        o, r, te, tr, info = wrapped.step(policy.predict(o)[0][0])
        p, rp, *_ = plain.step(u)
        np.testing.assert_array_equal(o, p)
        setpoints.add(round(info["setpoint"], 6))
        if te or tr:
            break
    assert len(setpoints) > 10  # the stand-in moves the setpoint: a real test of the replay


def test_the_vector_form_runs_each_lane_as_the_wrapper_does_across_resets():
    n, policy = 3, _Policy()
    spec = ResidualSpec(BASE, span=0.3)
    venv = vec_setpoint_residual(
        SB3VecEnv(gym.make_vec(TURNING, num_envs=n, autoreset_mode="SAME_STEP")), spec, TURNING, {}
    )
    venv.seed(20)
    obs = venv.reset()
    singles = [SetpointResidual(gym.make(TURNING), BASE, span=0.3) for _ in range(n)]
    single_obs = [e.reset(seed=20 + i)[0] for i, e in enumerate(singles)]
    ends = 0
    for _ in range(700):
        np.testing.assert_array_equal(obs, np.stack(single_obs))
        actions = policy.predict(obs)[0]
        obs, _, dones, _ = venv.step(actions)
        for i, e in enumerate(singles):
            single_obs[i], _, te, tr, _ = e.step(actions[i])
            if te or tr:
                single_obs[i] = e.reset()[0]
                ends += 1
        assert list(dones) == [bool(x) for x in dones]
    assert ends >= 1  # at least one lane finished and was reset on both sides


def test_two_knobs_a_zero_policy_is_the_afc_and_each_knob_reaches_it():
    """``knob`` a list: one action component per knob, each moving its own setting."""
    from agents.afc import AdaptiveFeedControl

    kw = {"knob": ["fmax", "reference"], "span": [1.0, 0.1], "lo": [1.0, 0.5], "hi": [4.0, 0.95]}
    env, *_, agent, info = _zero_policy_runs_the_tuned_agent(
        TURNING, AdaptiveFeedControl, 600, **kw
    )
    assert env.action_space.shape == (2,)
    assert info["setpoint"] == pytest.approx([agent.fmax, agent.reference])
    spec = env.residual
    got = spec.setpoints(env.base, np.array([[1.0, -1.0], [-1.0, 0.5]]))
    np.testing.assert_allclose(
        got,
        [
            [min(agent.fmax + 1.0, 4.0), agent.reference - 0.1],
            [agent.fmax - 1.0, agent.reference + 0.05],
        ],
    )
    steps = {}
    for a in ((0.0, 0.0), (1.0, 0.0), (0.0, -1.0)):
        env.reset(seed=5)
        te = tr = False
        steps[a] = 0
        while not (te or tr):
            *_, te, tr, _ = env.step(np.array(a, np.float32))
            steps[a] += 1
    assert steps[(1.0, 0.0)] < 0.95 * steps[(0.0, 0.0)]  # a higher cap cuts sooner
    assert steps[(0.0, -1.0)] > steps[(0.0, 0.0)]  # a lower reference later


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"base": "agents.drilling.NoControl"}, "no tunable .setpoint."),
        ({"base": BASE, "knob": "voltage"}, "no tunable .voltage."),
        ({"base": "agents.turning.Nope"}, "cannot import"),
        ({"base": BASE, "span": 0.0}, "span must be in"),
        (
            {"base": BASE, "knob": ["setpoint", "setpoint"], "span": [0.1]},
            r"span must be a number or a list of 2",
        ),
        ({"base": BASE, "knob": []}, "knob must be a setting's name or a list"),
        (
            {"base": BASE, "span": 0.8, "lo": 0.3, "hi": 1.0},
            r"span must be in \(0, 0.7\] \(hi - lo\)",
        ),
        (
            {"base": BASE, "span": 2.5, "mode": "add"},
            r"span must be in \(0, 2\] \(the action range\)",
        ),
        ({"base": BASE, "lo": 0.8, "hi": 0.5}, "lo and hi"),
        ({"base": BASE, "params": 3}, "params must be"),
        ({"base": BASE, "spam": 1}, "spam"),
    ],
)
def test_bad_residual_settings_are_refused_naming_them(tmp_path, kwargs, match):
    import yaml

    cfg = {
        TURNING: {
            "policy": "MlpPolicy",
            "env_wrapper": [{"agents.rl.residual.SetpointResidual": kwargs}],
        }
    }
    path = tmp_path / "c.yml"
    path.write_text(yaml.safe_dump(cfg))
    with pytest.raises(ConfigError, match=match):
        load_config(TURNING, "ppo", path)


def test_a_trained_residual_run_reloads_as_a_residual_agent_and_reproduces_its_score(tmp_path):
    from agents.rl import load_policy
    from agents.rl.config import CONFIG_DIR
    from agents.rl.train import evaluate_policy_file
    from machining_envs.core.splits import split_seeds

    out = train_quietly(
        TURNING, tmp_path / "run", CONFIG_DIR / "ppo_residual.yml", n_timesteps=2048
    )
    agent = load_policy(out / "best_model.zip")
    assert isinstance(agent, ResidualAgent) and agent.base.name.startswith("AFC")  # its base
    with open(out / "eval.csv") as fh:
        rows = list(csv.DictReader(fh))
    best = min(float(r["score"]) for r in rows)
    _, score, _ = evaluate_policy_file(
        out / "best_model.zip", TURNING, ["validation"], 10, split_seeds("validation", 10)[0]
    )
    assert score["score"] == pytest.approx(best, rel=1e-12)


def test_an_added_correction_of_zero_is_the_tuned_hinf_loop_and_is_bounded():
    from agents.contouring import HInf2DOF
    from tests.helpers import CONTOURING

    env, plain, o, *_ = _zero_policy_runs_the_tuned_agent(
        CONTOURING, HInf2DOF, 2000, mode="add", span=0.05
    )
    assert env.action_space.shape == (2,)
    # a full correction moves each axis's command by exactly span (inside the range)
    base = env.residual.make_base(plain)
    obs = np.asarray(o, dtype=np.float64)[None, :]
    st0 = base.initial_state(1, obs)
    u0 = env.residual.act(base, obs, st0.copy(), np.zeros((1, 2)))
    u1 = env.residual.act(base, obs, st0.copy(), np.ones((1, 2)))
    inside = np.abs(u0) < 0.95
    np.testing.assert_allclose((u1 - u0)[inside], 0.05, rtol=1e-5)
