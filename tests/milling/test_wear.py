"""Tool wear within the cut (EndMilling-v0): the torque follows the documented law under a
fixed feed, the adaptive controller holds its setpoint, the bound accounts for it, and a
sharp tool is the papers' plant to the last bit."""

import gymnasium as gym
import numpy as np
import pytest

from agents.bench.tune import tuned_factory
from agents.milling import IntegralACC
from machining_envs.core.workpieces import DepthProfile
from machining_envs.milling.scenarios import MillingScenario, machining_time_bound
from tests.helpers import MILLING, held_out_draws, run_cut


def _cut(wear):
    prof = DepthProfile.steps((2.0,), 60.0, name="2 mm")
    return MillingScenario("worn", prof, noise_scale=0.0, wear_per_100mm=wear)


def _run(agent_or_action, scenario, steps=600):
    keys = ("position_mm", "torque_Nmm", "feed_velocity_mm_s", "cost")
    return run_cut(MILLING, agent_or_action, scenario, keys, steps, 1e4)


@pytest.mark.parametrize("wear", [0.5, 1.5])
def test_a_fixed_feed_sees_the_torque_grow_as_the_law_says(wear):
    """T(x) = Ks (1 + w x / 100) d^l f_t^m D behind the process lag tau: at a steady feed
    ``v`` the static torque is a ramp in time, which the first-order lag follows exactly
    ``v tau`` behind; so the torque ratio between two points is the ratio of the wear
    factors at the positions ``v tau`` back (the rest of the law cancels)."""
    rows, env = _run(-0.3, _cut(wear))
    x, torque, v = rows[:, 0], rows[:, 1], rows[:, 2]
    tau = env.params.process_lag_s()
    i, j = len(rows) // 3, len(rows) - 5  # both past the start-up transient
    law = (1 + wear * (x[j] - v[j] * tau) / 100) / (1 + wear * (x[i] - v[i] * tau) / 100)
    assert torque[j] / torque[i] == pytest.approx(law, rel=1e-6)
    assert torque[j] / torque[i] > 1.0 + 0.5 * wear * (x[j] - x[i]) / 100  # it grew


def test_a_sharp_tool_is_bit_for_bit_the_papers_plant():
    sharp, _ = _run(-0.3, _cut(0.0), steps=200)
    plain = MillingScenario("plain", DepthProfile.steps((2.0,), 60.0, name="2 mm"), noise_scale=0.0)
    rows, _ = _run(-0.3, plain, steps=200)
    np.testing.assert_array_equal(sharp, rows)


def test_the_adaptive_controller_holds_its_setpoint_as_the_tool_dulls():
    agent = tuned_factory(IntegralACC, MILLING)(gym.make(MILLING))
    rows, env = _run(agent, _cut(1.5), steps=20000)
    x, torque, _, cost = rows.T
    assert x[-1] >= 59.0  # the whole cut
    late = x > 0.5 * x[-1]
    target = agent.setpoint * env.params.torque_limit_Nmm
    assert np.mean(torque[late]) == pytest.approx(target, rel=0.03)
    assert cost.mean() < 0.02


def test_the_bound_counts_the_wear_and_meets_the_closed_form_without_it():
    nominal = gym.make(MILLING).unwrapped.params
    rpm = nominal.spindle_rpm
    closed = machining_time_bound(_cut(0.0), _cut(0.0).true_params(nominal), rpm)
    tiny = machining_time_bound(_cut(1e-9), _cut(1e-9).true_params(nominal), rpm)
    assert tiny == pytest.approx(closed, rel=1e-4)
    assert machining_time_bound(_cut(1.0), _cut(1.0).true_params(nominal), rpm) > 1.2 * closed


def test_the_wear_split_draws_worn_tools_and_is_held_out():
    rates = held_out_draws(MILLING, "wear", "wear_per_100mm")
    assert min(rates) >= 0.5 and max(rates) <= 1.5 and len(set(rates)) == 20
