"""Drill wear within the hole (MicroDrilling-v0): the torque follows the documented law, kept
apart from the chip friction; the sliding-mode controller holds its setpoint while its
spindle has speed in hand; a sharp drill is the paper's plant to the last bit."""

import gymnasium as gym
import numpy as np
import pytest

from agents.bench.tune import tuned_factory
from agents.drilling import SlidingMode
from machining_envs.drilling.plant import DrillingParams
from machining_envs.drilling.scenarios import DrillingScenario
from tests.helpers import DRILLING, held_out_draws, run_cut

KEYS = (
    "torque_Nmm",
    "spindle_hz",
    "chip_ratio",
    "depth_mm",
    "feed_velocity_mm_s",
    "engagement",
    "voltage_V",
    "torque_limit_Nmm",
    "cost",
)


def _hole(wear, **kw):
    return DrillingScenario("worn", 0.7, 10.0, noise_scale=0.0, wear_per_mm=wear, **kw)


def _run(agent_or_action, scenario):
    return run_cut(DRILLING, agent_or_action, scenario, KEYS, 20000, 1e3)


@pytest.mark.parametrize("wear", [0.03, 0.1])
def test_a_fixed_voltage_sees_the_torque_grow_as_the_law_says(wear):
    """k4 = 2 pi c_T v eps(z) (1 + w z + g(L)) at a fixed voltage, fluctuations off: the
    torque is k4 / omega at the end of every period, so (torque x speed) of the worn drill
    over that of the sharp one, on the same hole, is (1 + w z + g) / (1 + g) with z the
    middle of the period's cut; the chip friction g is the same in both (it depends on
    the path alone, and a peck would clear it but not the wear)."""
    worn, env = _run(0.0, _hole(wear, fluctuation_scale=0.0))
    sharp, _ = _run(0.0, _hole(0.0, fluctuation_scale=0.0))
    assert worn.shape == sharp.shape  # the feed is fixed: the same path, the same steps
    np.testing.assert_array_equal(worn[:, 2:6], sharp[:, 2:6])  # chips, depth, feed, engagement
    tq, hz, g, depth, feed, eng = worn[:, :6].T
    cut = eng > 0.0
    mid = depth - 0.5 * feed * env.params.sample_time_s
    law = (1.0 + wear * mid + g) / (1.0 + g)
    ratio = tq * hz / (sharp[:, 0] * sharp[:, 1])
    np.testing.assert_allclose(ratio[cut], law[cut], rtol=1e-12)
    assert law[cut][-1] > 1.0 + 0.5 * wear * depth[-1] / (1.0 + g[cut][-1])  # it grew
    assert worn[cut, 0][-1] > sharp[cut, 0][-1]


def test_a_sharp_drill_is_bit_for_bit_the_papers_plant():
    sharp, _ = _run(0.0, _hole(0.0))
    plain, _ = _run(0.0, DrillingScenario("plain", 0.7, 10.0, noise_scale=0.0))
    np.testing.assert_array_equal(sharp, plain)


def test_sliding_mode_holds_its_setpoint_while_the_spindle_has_speed_in_hand():
    """The tuned sliding-mode controller speeds the spindle up as the drill dulls: on the
    fully engaged hole, wherever the valve is not yet fully open, its mean torque stays
    within 1 % of its setpoint at +5 % per mm. Deeper, the valve saturates (10 V, about
    1700 Hz) and no spindle-speed controller can hold the torque: that is the physics."""
    agent = tuned_factory(SlidingMode, DRILLING)(gym.make(DRILLING))
    rows, _ = _run(agent, _hole(0.05))
    tq, _, _, depth, _, eng, volts, limit, _ = rows.T
    held = (eng >= 1.0) & (volts < 9.9) & (depth > 1.5)  # past the entry transient
    assert held.sum() > 500  # over 5 s of the hole
    assert np.mean(tq[held] / limit[held]) == pytest.approx(agent.setpoint, rel=0.01)
    assert np.all(volts[held] > 5.0)  # it did speed the spindle up to hold it


def test_the_wear_split_draws_worn_drills_and_is_held_out():
    rates = held_out_draws(DRILLING, "wear", "wear_per_mm")
    assert min(rates) >= 0.03 and max(rates) <= 0.10 and len(set(rates)) == 20


@pytest.mark.parametrize("bad", [-0.1, 11.0, float("nan")])
def test_a_bad_wear_rate_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match="wear_per_mm"):
        DrillingParams(wear_per_mm=bad)
    with pytest.raises(ValueError, match="wear_per_mm"):
        _hole(bad)
