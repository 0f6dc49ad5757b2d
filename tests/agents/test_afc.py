"""The industrial adaptive feed control agent against its documented rules."""

import numpy as np
import pytest

from agents import AdaptiveFeedControl, ConstantFeed
from agents.afc import AFC_LOG_FIELDS
from agents.base import Agent
from agents.eval.harness import evaluate
from machining_envs.core.actions import ActionMap

PROGRAMMED = 50.0  # the programmed command, counts of [0, 100]


class _Programmed(Agent):
    """A constant programmed feed (the NC program's)."""

    obs_dim = 7

    def _act(self, obs, state):
        return np.full((obs.shape[0], 1), ActionMap(0.0, 100.0).command_to_action(PROGRAMMED))


def _afc(**kw):
    m = ActionMap(0.0, 100.0)

    def load_units(obs):
        return obs[:, 0], obs[:, 1]

    return AdaptiveFeedControl(_Programmed(), m, load_units, 0.1, **kw), m


def _run(afc, m, loads, limit=1.0):
    """Commands and states for a stream of loads (the first is the reset's)."""
    state, commands, states = None, [], []
    for k, load in enumerate(loads):
        obs = np.array([load, limit, 0.0, 0.5, load, load, load])
        a, state = afc.predict(obs, state, np.array([k == 0]))
        commands.append(float(m.action_to_command(float(a[0]))))
        states.append(state.copy())
    return np.array(commands), state, states


def test_hand_checked_episode_and_its_log():
    afc, m = _afc(teach_in_s=0.2, gain=0.5, fidl=1.5, fent=1.0, fmin=0.7, fmax=1.3)
    loads = [0.0, 0.0, 0.4, 0.6, 0.5, 0.9, 0.9, 0.0]
    commands, state, _ = _run(afc, m, loads)
    # air at the idle factor; teach-in at 100 %; control: 1 + 0.5 (1 - 0.5/0.6); then
    # 0.5 (1 - 0.9/0.6) less twice, bounded below by fmin; air again
    factors = [1.5, 1.5, 1.0, 1.0, 1.0 + 0.5 / 6, 1.0 + 0.5 / 6 - 0.25, 0.7, 1.5]
    np.testing.assert_allclose(commands, PROGRAMMED * np.array(factors), rtol=1e-6)
    log = afc.episode_log(state)[0]
    assert tuple(log) == AFC_LOG_FIELDS
    assert log["teach_in_time_s"] == pytest.approx(0.2)
    assert log["control_time_s"] == pytest.approx(0.5)
    assert log["peak_load"] == pytest.approx(0.9)
    assert log["reference_load"] == pytest.approx(0.6)  # the teach-in's largest load
    assert log["min_feed_factor"] == pytest.approx(0.7)
    assert (log["stop"], log["wear"], log["breakage"]) == (0.0, 1.0, 0.0)  # 0.9 > 1.1 x 0.6


def test_never_leaves_its_bounds():
    afc, m = _afc(gain=0.8, fmin=0.7, fmax=1.3, fidl=2.0, fent=0.9, overload_s=100.0)
    rng = np.random.default_rng(0)
    loads = np.where(rng.random(600) < 0.1, 0.0, rng.uniform(0.0, 2.0, 600))
    loads[0] = 0.0
    commands, _, states = _run(afc, m, loads)
    factors = commands / PROGRAMMED
    in_air = np.array([s[0, 12] for s in states]) == 1.0
    assert np.all(np.isclose(factors[in_air], 2.0))
    assert np.all(
        (factors[~in_air] >= 0.7 - 1e-6) & (factors[~in_air] <= 1.3 + 1e-6)
    )  # float32 actions
    assert (~in_air).sum() > 400 and in_air.sum() > 20
    assert factors[~in_air].min() < 0.75 and factors[~in_air].max() > 1.25  # reached both


def test_idles_in_air():
    afc, m = _afc(fidl=1.8, pout=0.08, reference=0.5)
    # the idle load (the first, 0.2) is subtracted: the cutting reference is 0.5 - 0.2, and
    # below pout x 0.3 = 0.024 of cutting load the tool is in air
    commands, _, _ = _run(afc, m, [0.2, 0.2, 0.22, 0.2, 0.2235, 0.23], limit=1.0)
    np.testing.assert_allclose(commands[:5], PROGRAMMED * 1.8, rtol=1e-6)
    assert commands[5] == pytest.approx(PROGRAMMED)  # in the material: FENT, 100 %


def test_stops_on_overload():
    afc, m = _afc(reference=0.5, gain=0.2, fmin=0.7, overload_s=1.0, wear_margin=None)
    loads = [0.0] + [1.0] * 40 + [0.3] * 10
    commands, state, states = _run(afc, m, loads)
    factors = commands / PROGRAMMED
    # entry at FENT (100 %), then down by 0.2 a period to fmin after 2 periods
    np.testing.assert_allclose(factors[1:4], [1.0, 0.8, 0.7])
    # above the reference at fmin for more than one second: NC stop (feed zero) from then on
    at_min = 3
    # the sample at fmin above the reference that makes it 1.1 s (> 1 s): the 11th
    stop_at = at_min + 10
    assert np.all(factors[at_min:stop_at] == pytest.approx(0.7))
    assert np.all(factors[stop_at:] == 0.0)
    assert [s[0, 9] for s in states][stop_at - 1 : stop_at + 1] == [0.0, 1.0]
    log = afc.episode_log(state)[0]
    assert log["stop"] == 1.0 and log["breakage"] == 0.0 and log["wear"] == 0.0


def test_load_monitoring_stops_and_disables_wear():
    afc, m = _afc(reference=0.5, breakage_margin=0.5, wear_margin=0.1)
    commands, state, _ = _run(afc, m, [0.0, 0.5, 0.5, 0.8, 0.5])
    assert commands[-2:].tolist() == [0.0, 0.0]
    log = afc.episode_log(state)[0]
    assert (log["stop"], log["breakage"], log["wear"]) == (1.0, 1.0, 0.0)


@pytest.mark.parametrize(
    "bad", [{"fmin": 1.2}, {"fmax": 0.9}, {"fent": 1.5}, {"gain": 0.0}, {"pout": 0.9}]
)
def test_settings_are_checked(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        _afc(**bad)


def test_harness_records_the_log_on_the_env():
    ev, ev1 = (
        evaluate(
            AdaptiveFeedControl.from_env,
            "machining_envs/Turning-v0",
            ["validation"],
            n_episodes=2,
            env_kwargs={"power_sensor": True},
            batched=batched,
        )
        for batched in (None, False)
    )
    for row, row1 in zip(ev.rows, ev1.rows, strict=True):
        for f in AFC_LOG_FIELDS:
            assert row["afc_" + f] == row1["afc_" + f]
        assert row["finished"]
        assert 0.7 <= row["afc_min_feed_factor"] <= 1.3
        assert row["afc_control_time_s"] > 0 and row["afc_reference_load"] > 0


def test_programmed_feed_is_the_constant_feed():
    import gymnasium as gym

    env = gym.make("machining_envs/Turning-v0", scenario="validation")
    afc = AdaptiveFeedControl.from_env(env, design_depth_mm=2.0, teach_in_s=1.0)
    cf = ConstantFeed.from_env(env, design_depth_mm=2.0)
    obs, _ = env.reset(seed=0)
    a, state = afc.predict(obs)
    b, _ = cf.predict(obs)
    # in air at the start: the idle factor (1.0 by default) times the programmed feed
    assert a == pytest.approx(b)


def test_end_milling_on_the_shop_floor_machine_keeps_its_rules():
    """EndMilling-v0 on the shop-floor machine (delay, 1 % steps, rate limits), a whole
    `validation` workpiece: the commanded override is the programmed feed times the factor,
    within [fmin, fmax] in the material, at the entry factor before the first contact (the
    machine delays the override) and at the idle factor in air after it; the log's peak load
    and smallest factor are those of the episode as recomputed from the observations."""
    import gymnasium as gym

    from machining_envs.core.machine import SHOPFLOOR_MACHINE

    env_id = "machining_envs/EndMilling-v0"
    env = gym.make(env_id, **SHOPFLOOR_MACHINE.env_kwargs(env_id))
    afc = AdaptiveFeedControl.from_env(
        env, fmin=0.5, fmax=1.6, fidl=2.0, gain=0.3, wear_margin=None
    )
    obs, _ = env.reset(seed=3, options={"scenario": "validation"})
    state, first, idle = None, True, None
    cmap = afc.command_map
    cut_loads, factors_in = [], []
    done = False
    while not done:
        a, state = afc.predict(obs, state, np.array([first]))
        load = float(afc.load_units(obs[None, :].astype(np.float64))[0][0])
        idle = load if first else idle
        first = False
        ovr = float(state[0, 0])
        prog = afc.programmed._act(obs[None, :].astype(np.float64), np.zeros((1, 0)))[0, 0]
        expected = np.clip(cmap.action_to_command(prog) * ovr, cmap.command_min, cmap.command_max)
        assert float(cmap.action_to_command(float(a[0]))) == pytest.approx(expected, rel=1e-5)
        if state[0, 3] == 3.0:  # stopped (overload): the feed held at zero
            assert ovr == 0.0 and state[0, 9] == 1.0
        elif state[0, 12] == 1.0:  # in air: approaching at FENT (100 %), later at FIDL
            assert ovr == pytest.approx(1.0 if state[0, 3] == 0.0 else 2.0)
        else:
            assert 0.5 - 1e-12 <= ovr <= 1.6 + 1e-12
            factors_in.append(ovr)
        cut_loads.append(load - idle)
        obs, _, term, trunc, _ = env.step(a)
        done = term or trunc
    log = afc.episode_log(state)[0]
    assert factors_in and log["control_time_s"] > 0
    assert log["peak_load"] == pytest.approx(max(cut_loads))
    assert log["min_feed_factor"] == pytest.approx(min(factors_in))
    assert log["breakage"] == 0.0
    env.close()


def test_reference_moved_between_steps_applies_from_the_next_step():
    """A supervisor (a residual policy) that moves the given reference is obeyed: the
    integral action then acts on the error to the new reference, per lane."""
    afc, m = _afc(reference=0.5, gain=0.5, fmin=0.5, fmax=2.0)
    obs = np.array([[0.0, 1.0, 0.0, 0.5, 0.0, 0.0, 0.0]] * 2)
    state = afc.initial_state(2, obs)
    afc.predict(obs, state.copy())  # in air
    cut = obs.copy()
    cut[:, 0] = 0.5  # at the reference 0.5: no change of the override
    a, st = afc.predict(cut, state)
    np.testing.assert_allclose(m.action_to_command(a[:, 0]), PROGRAMMED * 1.0, rtol=1e-6)
    afc.reference = np.array([0.5, 0.8])  # lane 1's setpoint raised, lane 0's kept
    a, st = afc.predict(cut, st)
    # lane 0: error 0 -> override 1; lane 1: 1 + 0.5 (1 - 0.5/0.8)
    np.testing.assert_allclose(
        m.action_to_command(a[:, 0]), PROGRAMMED * np.array([1.0, 1.0 + 0.5 * 0.375]), rtol=1e-6
    )
    afc.reference = 0.5  # back to the value it was made with: the stored reference again
    a2, _ = afc.predict(cut, st.copy())  # at the reference 0.5 again: overrides held
    np.testing.assert_allclose(
        m.action_to_command(a2[:, 0]), PROGRAMMED * np.array([1.0, 1.0 + 0.5 * 0.375]), rtol=1e-6
    )


def test_approaches_at_fapp_then_idles_at_fidl():
    afc, m = _afc(fidl=1.8, fapp=0.9, fent=1.0, pout=0.08, reference=0.5)
    # before the first contact: the approach factor; in the material: FENT; in air after
    # the cut: the idle factor
    commands, _, _ = _run(afc, m, [0.0, 0.0, 0.0, 0.3, 0.0, 0.0])
    np.testing.assert_allclose(commands / PROGRAMMED, [0.9, 0.9, 0.9, 1.0, 1.8, 1.8], rtol=1e-6)
    assert _afc(fidl=1.8)[0].fapp == 1.8  # by default the approach is at the idle factor
    with pytest.raises(ValueError, match="fapp"):
        _afc(fapp=6.0)


def test_from_env_approaches_at_fent_on_a_delayed_machine():
    import gymnasium as gym

    for env_id in ("machining_envs/Turning-v0", "machining_envs/EndMilling-v0"):
        delayed = gym.make(env_id, actuation={"delay_steps": 2})
        ideal = gym.make(env_id, actuation={"quantum": 0.01})  # no delay
        assert AdaptiveFeedControl.from_env(delayed, fidl=2.0, fent=0.8).fapp == 0.8
        assert AdaptiveFeedControl.from_env(delayed, fidl=2.0, fapp=1.5).fapp == 1.5  # given
        assert AdaptiveFeedControl.from_env(ideal, fidl=2.0).fapp == 2.0
        assert AdaptiveFeedControl.from_env(gym.make(env_id), fidl=2.0).fapp == 2.0
