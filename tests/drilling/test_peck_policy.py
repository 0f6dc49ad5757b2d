"""A policy that decides when to peck: the peck cycle's depth as a residual knob, tuned
peck drilling by the benchmark's protocol, and a smoke training of the pecking policy."""

import gymnasium as gym
import numpy as np
import pytest

from agents.drilling import PeckDrilling

pytest.importorskip("stable_baselines3")

DRILLING_ID = "machining_envs/MicroDrilling-v0"
BASE = "agents.drilling.PeckDrilling"
PARAMS = {"peck_diameters": 2.0, "feed_scale": 0.6}


def _drill_until(agent, env, depth_d, seed=3):
    """Run ``agent`` until the hole is ``depth_d`` diameters deep; returns obs and state."""
    obs, _ = env.reset(seed=seed, options={"scenario": "paper_0.6"})
    state = None
    for _ in range(20000):
        a, state = agent.predict(obs, state)
        obs, _, te, tr, _ = env.step(a)
        assert not (te or tr)
        _, depth, _ = agent.io.lengths_mm(np.asarray(obs, dtype=np.float64)[None, :])
        if depth[0] >= depth_d * 0.6:
            return obs, state
    raise AssertionError("the hole never got that deep")


def test_lowering_the_peck_depth_mid_feed_pecks_at_once_raising_it_cuts_on():
    env = gym.make(DRILLING_ID, control="feed")
    agent = PeckDrilling.from_env(env, peck_diameters=4.0)
    obs, state = _drill_until(agent, env, 1.5)  # 1.5 D into a 4 D peck: still feeding
    a, st = agent.predict(obs, state.copy())
    assert float(np.asarray(a)[0]) > 0.0  # feeding
    feed = np.asarray(a).copy()
    agent.peck_diameters = 1.0  # now below the 1.5 D cut since the peck began
    a, _ = agent.predict(obs, state.copy())
    assert float(np.asarray(a)[0]) < float(feed[0])  # the feed turned into a retract
    assert float(np.asarray(a)[0]) < 0.0
    agent.peck_diameters = np.array([4.0])  # the knob as the residual sets it, per lane
    a, _ = agent.predict(obs, state.copy())
    assert float(np.asarray(a)[0]) == pytest.approx(float(feed[0]))


def test_the_feed_scale_is_checked_and_scales_the_cutting_feed():
    env = gym.make(DRILLING_ID, control="feed")
    with pytest.raises(ValueError, match="feed_scale"):
        PeckDrilling.from_env(env, feed_scale=100.0)
    with pytest.raises(ValueError, match="feed_scale"):
        PeckDrilling.from_env(env, feed_scale=float("nan"))
    slow = PeckDrilling.from_env(env, feed_scale=0.5)
    obs, _ = env.reset(seed=0)
    a1, _ = PeckDrilling.from_env(env).predict(obs)
    a2, _ = slow.predict(obs)
    p = env.unwrapped.params
    v = lambda a: float(a[0]) * p.feed_speed_max_mm_s  # the feed action's affine map  # noqa: E731
    assert v(a2) == pytest.approx(0.5 * v(a1), rel=1e-5)


def test_a_zero_residual_is_the_peck_cycle_step_for_step():
    from agents.rl.residual import SetpointResidual

    env = SetpointResidual(
        gym.make(DRILLING_ID, control="feed"),
        BASE,
        params=PARAMS,
        knob="peck_diameters",
        span=1.0,
        lo=0.1,
        hi=5.0,
    )
    plain = gym.make(DRILLING_ID, control="feed")
    agent = PeckDrilling.from_env(plain, **PARAMS)
    retracts, info = _zero_residual_is(agent, env, plain, {}, feed=0, max_steps=3000)
    assert retracts > 0  # the cycle pecked within the run compared
    assert info["setpoint"] == 2.0


def _zero_residual_is(agent, env, plain, options, feed, max_steps=100_000):
    """Step the residual wrapper ``env`` with zero actions and ``plain`` with ``agent``'s
    actions from the same seed: the same observations, rewards and ends at every step.
    Returns the cycle's retracts (action ``feed`` below 0) and the wrapper's last info."""
    o, _ = env.reset(seed=5, options=options)
    p, _ = plain.reset(seed=5, options=options)
    st, retracts = None, 0
    for _ in range(max_steps):
        a, st = agent.predict(p, st)
        retracts += float(a[feed]) < 0.0
        o, r, te, tr, info = env.step(np.zeros(1, np.float32))
        p, rp, tep, trp, _ = plain.step(a)
        np.testing.assert_array_equal(o, p)
        assert (r, te, tr) == (rp, tep, trp)
        if te or tr:
            break
    return retracts, info


def test_peck_drilling_is_tuned_by_the_protocol_on_its_feed_control():
    """``tune_agent`` makes PeckDrilling's env with its ``ENV_KWARGS`` (it commands the
    feed) and records them; before, tuning it raised on the voltage-controlled env."""
    from agents.bench.tune import TuningBudget, tune_agent

    entry = tune_agent(PeckDrilling, DRILLING_ID, TuningBudget(trials=1, episodes=1, startup=0))
    assert entry["env_kwargs"] == {"control": "feed"}
    assert set(entry["params"]) == set(PeckDrilling.TUNABLE)
    assert entry["params"] == entry["paper_params"]  # one trial: the defaults
    assert np.isfinite(entry["validation_score"])


def test_the_pecking_config_loads():
    from agents.rl import load_config
    from agents.rl.config import CONFIG_DIR

    cfg = load_config(DRILLING_ID, "ppo", CONFIG_DIR / "ppo_peck.yml")
    assert cfg.residual["base"] == BASE and cfg.residual["knob"] == "peck_diameters"
    assert cfg.env_kwargs["control"] == "feed"
    assert cfg.env_kwargs["reward"]["progress"] > 0.0  # a peck costs time


@pytest.mark.slow
def test_a_pecking_policy_trains_and_replays_over_the_peck_cycle(tmp_path):
    from agents.rl import load_policy
    from agents.rl.config import CONFIG_DIR
    from agents.rl.residual import ResidualAgent
    from tests.helpers import train_quietly

    wrapper = [
        {
            "agents.rl.residual.SetpointResidual": {
                "base": BASE,
                "params": PARAMS,
                "knob": "peck_diameters",
                "span": 1.0,
                "lo": 0.1,
                "hi": 5.0,
            }
        }
    ]
    cb = [
        {
            "agents.rl.callbacks.ValidationCallback": {
                "eval_freq": 1024,
                "n_episodes": 2,
                "scenarios": ["validation"],
            }
        }
    ]
    out = train_quietly(
        DRILLING_ID,
        tmp_path / "run",
        CONFIG_DIR / "ppo_peck.yml",
        n_timesteps=2048,
        overrides={"env_wrapper": wrapper, "callback": cb, "n_envs": 2},
    )
    agent = load_policy(out / "best_model.zip")
    assert isinstance(agent, ResidualAgent) and agent.base.name.startswith("peck")
    rows = (out / "eval.csv").read_text().splitlines()
    assert len(rows) >= 2  # a header and at least one validation evaluation


def test_the_fast_spindle_pecking_config_loads_and_its_zero_residual_is_the_cycle():
    """``ppo_peck_voltage.yml``: the torque trigger of the tuned ``VoltageTorquePeck`` on
    ``control="voltage_feed"``, kept at or under the limit; a policy that outputs 0 drives
    the env exactly as the tuned cycle does (both components of its action)."""
    from agents.drilling import VoltageTorquePeck
    from agents.rl import load_config
    from agents.rl.config import CONFIG_DIR
    from agents.rl.residual import ResidualSpec, SetpointResidual

    cfg = load_config(DRILLING_ID, "ppo", CONFIG_DIR / "ppo_peck_voltage.yml")
    res = cfg.residual
    assert res["base"] == "agents.drilling.VoltageTorquePeck" and res["knob"] == "torque_share"
    assert cfg.env_kwargs["control"] == "voltage_feed" and res["hi"] <= 1.0
    spec = ResidualSpec(**res).checked()
    env = SetpointResidual(gym.make(DRILLING_ID, **{"control": "voltage_feed"}), **res)
    plain = gym.make(DRILLING_ID, control="voltage_feed")
    agent = VoltageTorquePeck.from_env(plain, **spec.settings(DRILLING_ID))
    retracts, info = _zero_residual_is(agent, env, plain, {"scenario": "validation"}, feed=1)
    assert retracts > 0 and info["finished"]
