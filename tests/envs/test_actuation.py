"""CNC actuation on Turning-v0, EndMilling-v0 (the feed command) and ContouringFeed-v0 (the
feed override): each option changes the command as documented, the vector env does the
same per lane, and the default is the ideal actuator. The limits are set per control
period (``RATE``, ``ACCEL``), so one test reads the same on a 10 Hz and a 100 Hz loop."""

import math

import gymnasium as gym
import numpy as np
import pytest

from machining_envs.core.actuation import Actuation
from machining_envs.core.workpieces import DepthProfile
from machining_envs.milling.scenarios import MillingScenario
from tests.helpers import CONTOURING_FEED, MILLING, TURNING

ACTIONS = np.random.default_rng(3).uniform(-1.0, 0.2, size=60)  # below breakage (see _make)
ENVS = (TURNING, MILLING, CONTOURING_FEED)
#: The rate limit and the acceleration limit of the tests, as shares of the command range
#: per control period and per period squared.
RATE, ACCEL = 0.1, 0.02


def _kwargs(env_id) -> dict:
    """A cut whose force (torque) stays below breakage for every command of ``ACTIONS``: the
    paper's 405 rpm bar; for milling a 0.1 mm radial depth with the linear action map, so
    that the commands span 60 % of the range as in turning."""
    if env_id == TURNING:
        return {"scenario": "paper_405"}
    if env_id == CONTOURING_FEED:
        return {"scenario": "paper_involute"}  # the overrides of ACTIONS never finish it
    light = MillingScenario("light", DepthProfile.steps((0.1,), 500.0, name="0.1 mm"))
    return {"scenario": light, "action_map": "linear"}


def _make(env_id, **kwargs):
    return gym.make(env_id, **_kwargs(env_id), **kwargs)


def _period(env_id) -> float:
    """The control period of ``env_id``, s (its decision interval)."""
    env = gym.make(env_id).unwrapped
    return getattr(env, "decision_interval_s", None) or env.params.sample_time_s


def _per_s(env_id, rate=RATE, accel=ACCEL) -> dict:
    """``RATE`` and ``ACCEL`` (per period) as the per-second settings of ``env_id``."""
    ts = _period(env_id)
    return {"max_rate_per_s": rate / ts, "max_accel_per_s2": accel / ts**2}


def _commands(env_id=TURNING, **actuation):
    """The commands (overrides) the drives got for ``ACTIONS``, and the command range."""
    env = _make(env_id, actuation=actuation or None)
    env.reset(seed=0)
    key = "feed_override" if env_id == CONTOURING_FEED else "command"
    out = []
    for a in ACTIONS:
        *_, terminated, truncated, info = env.step(np.array([a], dtype=np.float32))
        out.append(info[key])
        assert not (terminated or truncated)
    u = env.unwrapped
    return np.array(out), getattr(u, "override_max", None) or u.params.command_max


@pytest.mark.parametrize("env_id", ENVS)
def test_off_by_default_the_servo_gets_the_action(env_id):
    plain, cmax = _commands(env_id)
    np.testing.assert_allclose(plain, (ACTIONS.astype(np.float32) + 1) / 2 * cmax, rtol=1e-6)
    same, _ = _commands(env_id, quantum=0.0, max_rate_per_s=math.inf, delay_steps=0)
    np.testing.assert_array_equal(same, plain)


@pytest.mark.parametrize("env_id", ENVS)
def test_the_delay_is_exactly_n_periods(env_id):
    plain, _ = _commands(env_id)
    delayed, _ = _commands(env_id, delay_steps=3)
    np.testing.assert_array_equal(delayed[:3], 0.0)
    np.testing.assert_array_equal(delayed[3:], plain[:-3])


@pytest.mark.parametrize("env_id", ENVS)
@pytest.mark.parametrize("quantum", [0.01, 0.1])
def test_quantised_commands_lie_on_the_grid(env_id, quantum):
    plain, cmax = _commands(env_id)
    q, _ = _commands(env_id, quantum=quantum)
    steps = q / (quantum * cmax)
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    assert np.max(np.abs(q - plain)) <= quantum * cmax / 2 + 1e-9
    assert len(np.unique(q)) <= 1 / quantum + 1


@pytest.mark.parametrize("env_id", ENVS)
def test_the_rate_never_exceeds_its_limit_even_on_the_grid(env_id):
    rate = {"max_rate_per_s": _per_s(env_id)["max_rate_per_s"]}
    for actuation in (rate, {**rate, "quantum": 0.01}):
        c, cmax = _commands(env_id, **actuation)
        steps = np.abs(np.diff(np.concatenate([[0.0], c])))
        assert steps.max() <= RATE * cmax + 1e-9, actuation
        assert steps.max() >= 0.9 * RATE * cmax  # the limit binds on these commands


@pytest.mark.parametrize("env_id", ENVS)
@pytest.mark.parametrize("quantum", [0.0, 0.01])
def test_the_acceleration_never_exceeds_its_limit_and_the_ramp_brakes_on_target(env_id, quantum):
    act = {**_per_s(env_id, rate=3 * RATE), "quantum": quantum}
    c, cmax = _commands(env_id, **act)
    steps = np.diff(np.concatenate([[0.0, 0.0], c]))
    dv = ACCEL * cmax
    assert np.abs(np.diff(steps)).max() <= dv + 1e-9
    assert np.abs(np.diff(steps)).max() >= 0.99 * dv  # the limit binds on these commands
    assert np.abs(steps).max() <= 3 * RATE * cmax + 1e-9
    if quantum:
        grid = c / (quantum * cmax)
        np.testing.assert_allclose(grid, np.round(grid), atol=1e-9)
    # A step to a constant command: the ramp accelerates, cruises, brakes and stops on it
    # (no overshoot of its own), and every change of rate stays within the limit.
    from machining_envs.core.actuation import ActuationLanes

    ts = _period(env_id)
    lanes = ActuationLanes(1, cmax, 0.0, ts, Actuation(max_accel_per_s2=ACCEL / ts**2))
    out = np.array([lanes.apply(np.array([0.8 * cmax]))[0] for _ in range(40)])
    assert out.max() <= 0.8 * cmax + 1e-9
    assert out[-1] == pytest.approx(0.8 * cmax)
    assert np.abs(np.diff(np.diff(np.concatenate([[0.0, 0.0], out])))).max() <= dv + 1e-9


@pytest.mark.parametrize("env_id", ENVS)
def test_every_vector_lane_runs_the_same_actuation(env_id):
    act = {"quantum": 0.05, "delay_steps": 2, **_per_s(env_id, rate=0.2, accel=0.1)}
    key = "feed_override" if env_id == CONTOURING_FEED else "command"
    vec = gym.make_vec(env_id, num_envs=3, actuation=act, **_kwargs(env_id))
    vec.reset(seed=0)
    singles = [_make(env_id, actuation=act) for _ in range(3)]
    for i, e in enumerate(singles):
        e.reset(seed=i)
    for a in ACTIONS[:40]:
        _, _, _, _, info = vec.step(np.full((3, 1), a, dtype=np.float32))
        for i, e in enumerate(singles):
            assert e.step(np.array([a], dtype=np.float32))[4][key] == info[key][i]


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"quantum": 0.3}, "quantum must divide"),
        ({"quantum": -0.1}, "quantum"),
        ({"max_rate_per_s": 0.0}, "max_rate_per_s"),
        ({"delay_steps": 1.5}, "delay_steps"),
        ({"quantum": 0.1, "max_rate_per_s": 0.5}, "less than one quantum"),
        ({"max_accel_per_s2": -1.0}, "max_accel_per_s2"),
        ({"quantum": 0.1, "max_accel_per_s2": 5.0}, "less than one quantum"),
    ],
)
@pytest.mark.parametrize("env_id", ENVS)
def test_bad_actuation_is_refused_naming_it(env_id, kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make(env_id, actuation=kwargs)
    if "less than" not in match:
        with pytest.raises(ValueError, match=match):
            Actuation(**kwargs)


@pytest.mark.parametrize("env_id", ENVS)
def test_unknown_actuation_settings_are_refused(env_id):
    with pytest.raises(TypeError, match="delay"):
        gym.make(env_id, actuation={"delay": 2})


def test_a_limit_of_whole_quanta_up_to_rounding_counts_whole():
    """0.3 / 0.1 s is 2.9999999999999996 in floating point: still three quanta a period."""
    from machining_envs.core.actuation import ActuationLanes

    act = Actuation(quantum=0.1, max_rate_per_s=0.3 / 0.1, max_accel_per_s2=0.2 / 0.1**2)
    lanes = ActuationLanes(1, 1.0, 0.0, 0.1, act)
    assert lanes.max_step[0] == pytest.approx(0.3)
    assert lanes.max_dstep[0] == pytest.approx(0.2)
