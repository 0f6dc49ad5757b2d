"""ContouringFeed-v0's adaptive feed control on the contour error against its documented
rules: the factor's law (fast down above the reference, ``rise`` of the gain below it),
its bounds, the override as the factor times the look-ahead planner's."""

import numpy as np
import pytest

from agents.contouring import ContourAFC, LookAheadFeed

OMAX = 2.0


def _obs(errors, left_mm=500.0):
    """Observations on a straight path (no turn ahead, ``left_mm`` to go, 50 mm/s
    programmed) with the largest contour errors ``errors`` (multiples of the tolerance)."""
    obs = np.zeros((len(errors), 16))
    obs[:, 1] = errors
    obs[:, 6] = left_mm / 100.0
    obs[:, 12] = 0.5
    return obs


def _run(agent, errors):
    """The overrides the agent commands for a stream of largest contour errors."""
    state, out = None, []
    for k, row in enumerate(_obs(errors)):
        a, state = agent.predict(row, state, np.array([k == 0]))
        out.append((float(a[0]) + 1.0) * OMAX / 2.0)
    return np.array(out), state


def test_hand_checked_factor():
    afc = ContourAFC(
        OMAX, override_cap=0.8, reference=0.5, gain=0.2, rise=0.1, fmin=0.3, fmax=1.1, fent=0.9
    )
    overrides, state = _run(afc, [0.0, 0.25, 1.0, 2.0, 0.0, 0.5])
    # on a straight the planner gives its cap, 0.8; the factor from fent = 0.9:
    k = [0.9 + 0.02]  # error 0: up by rise x gain x 1
    k.append(k[-1] + 0.2 * 0.1 * 0.5)  # 0.25 of 0.5: up by rise x gain x 0.5
    k.append(k[-1] - 0.2 * 1.0)  # 1.0: twice the reference, down by the full gain
    k.append(max(k[-1] - 0.2 * 3.0, 0.3))  # 2.0: down by 3 x gain, bounded by fmin
    k.append(k[-1] + 0.02)
    k.append(k[-1])  # at the reference: unchanged
    np.testing.assert_allclose(overrides, 0.8 * np.array(k), rtol=1e-6)
    assert state[0, 0] == pytest.approx(k[-1])


def test_never_leaves_its_bounds_and_follows_the_planner():
    afc = ContourAFC(OMAX, override_cap=1.0, reference=0.6, gain=0.5, rise=0.5, fmin=0.4, fmax=1.2)
    rng = np.random.default_rng(0)
    errors = np.where(rng.random(400) < 0.5, 0.0, rng.uniform(0.0, 3.0, 400))
    overrides, _ = _run(afc, errors)
    assert np.all(overrides >= 0.4 - 1e-6) and np.all(overrides <= 1.2 + 1e-6)
    assert overrides.min() < 0.45 and overrides.max() > 1.15  # reached both
    # with the path's end near, the planner slows and the override with it
    near = _obs([0.0], left_mm=0.5)
    planner = LookAheadFeed(OMAX, override_cap=1.0)
    plan = (float(planner.predict(near[0])[0][0]) + 1.0) * OMAX / 2.0
    a, _ = ContourAFC(OMAX, override_cap=1.0, fent=1.0, fmax=1.0).predict(near[0])
    assert (float(a[0]) + 1.0) * OMAX / 2.0 == pytest.approx(plan, rel=1e-5)
    assert plan < 0.7  # sqrt(2 x 1000 mm/s2 x 0.5 mm) / 50 mm/s, below the cap


@pytest.mark.parametrize(
    "bad",
    [
        {"reference": 0.0},
        {"gain": 3.0},
        {"rise": 0.0},
        {"rise": 1.5},
        {"fmin": 1.5},
        {"fmax": 0.5},
        {"fent": 0.0},
        {"override_cap": 3.0},
    ],
)
def test_settings_are_checked(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        ContourAFC(OMAX, **bad)


def test_runs_an_episode_on_the_shop_floor_machine():
    import gymnasium as gym

    from machining_envs.core.machine import SHOPFLOOR_MACHINE

    env_id = "machining_envs/ContouringFeed-v0"
    env = gym.make(env_id, **SHOPFLOOR_MACHINE.env_kwargs(env_id))
    afc = ContourAFC.from_env(env, override_cap=1.0)
    assert afc.override_max == env.unwrapped.override_max
    obs, _ = env.reset(seed=1, options={"scenario": "validation"})
    state, first, done, factors = None, True, False, []
    while not done:
        a, state = afc.predict(obs, state, np.array([first]))
        first = False
        factors.append(float(state[0, 0]))
        assert -1.0 <= float(a[0]) <= 1.0
        obs, _, term, trunc, info = env.step(a)
        done = term or trunc
    assert info["finished"] and min(factors) >= afc.fmin and max(factors) <= afc.fmax
    env.close()
