"""Tool wear within the cut (Turning-v0): the force follows the documented law under a fixed
feed, the adaptive controller holds its setpoint, the bound accounts for it, and a sharp
tool is the papers' plant to the last bit."""

import gymnasium as gym
import numpy as np
import pytest

from agents.bench.tune import tuned_factory
from agents.turning import VariableGainPI
from machining_envs.core.workpieces import DepthProfile
from machining_envs.turning.scenarios import TurningScenario, machining_time_bound
from tests.helpers import TURNING, held_out_draws, run_cut


def _cut(wear, rpm=405.0):
    prof = DepthProfile.steps((1.5,), 60.0, name="1.5 mm")
    return TurningScenario("worn", prof, rpm, 1000.0, noise_scale=0.0, wear_per_100mm=wear)


def _run(agent_or_action, scenario, steps=400):
    keys = ("position_mm", "force_N", "cost")
    return run_cut(TURNING, agent_or_action, scenario, keys, steps, 1e3)


@pytest.mark.parametrize("wear", [0.4, 1.0])
def test_a_fixed_feed_sees_the_force_grow_as_the_law_says(wear):
    """F(x) = Kf (1 + w x / 100) a f^p: at a steady feed the force ratio between two points
    of the cut is the ratio of the wear factors (the rest of the law cancels)."""
    rows, _ = _run(-0.5, _cut(wear))
    x, f = rows[:, 0], rows[:, 1]
    i, j = len(rows) // 3, len(rows) - 5  # both past the start-up transient
    assert f[j] / f[i] == pytest.approx((1 + wear * x[j] / 100) / (1 + wear * x[i] / 100), rel=1e-9)
    assert f[j] / f[i] > 1.05


def test_a_sharp_tool_is_bit_for_bit_the_papers_plant():
    sharp, _ = _run(-0.5, _cut(0.0))
    plain = TurningScenario(
        "plain", DepthProfile.steps((1.5,), 60.0, name="1.5 mm"), 405.0, 1000.0, noise_scale=0.0
    )
    rows, _ = _run(-0.5, plain)
    np.testing.assert_array_equal(sharp, rows)


def test_the_adaptive_pi_holds_its_setpoint_as_the_tool_dulls():
    agent = tuned_factory(VariableGainPI, TURNING)(gym.make(TURNING))
    rows, _ = _run(agent, _cut(1.0))
    x, f, cost = rows.T
    late = x > 0.5 * x[-1]
    target = agent.setpoint * 1000.0
    assert np.mean(f[late]) == pytest.approx(target, rel=0.03)
    assert cost.mean() < 0.02
    # a fixed feed that starts at the same force ends well above it
    fixed, _ = _run(-0.5, _cut(1.0))
    assert fixed[-5, 1] / fixed[len(fixed) // 3, 1] > 1.1


def test_the_bound_counts_the_wear_and_meets_the_closed_form_without_it():
    env = gym.make(TURNING).unwrapped
    nominal = env.params
    closed = machining_time_bound(_cut(0.0), _cut(0.0).true_params(nominal))
    tiny = machining_time_bound(_cut(1e-9), _cut(1e-9).true_params(nominal))
    assert tiny == pytest.approx(closed, rel=1e-4)
    assert machining_time_bound(_cut(1.0), _cut(1.0).true_params(nominal)) > 1.1 * closed


def test_the_wear_split_is_held_out_and_draws_worn_tools():
    rates = held_out_draws(TURNING, "wear", "wear_per_100mm")
    assert 0.3 <= min(rates) and max(rates) <= 1.0 and np.ptp(rates) > 0.3
