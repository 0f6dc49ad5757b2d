"""Drilling scenarios: by name or object, training and held-out sets, bad scenarios refused."""

import gymnasium as gym
import pytest

from machining_envs import DrillingScenario
from tests.helpers import (
    DRILLING,
    TRAIN_OOD,
    assert_splits_share_a_distribution_not_episodes,
    drawn_scenarios,
    reset_by_name_and_object,
)


def test_scenarios_by_name_and_object():
    env = gym.make(DRILLING)
    sc = DrillingScenario("mine", 0.55, aspect_ratio=4.0, torque_limit_Nmm=0.3)
    info, mine = reset_by_name_and_object(env, "paper_0.7", sc)
    assert info["target_depth_mm"] == pytest.approx(7.0) and mine["diameter_mm"] == 0.55
    assert mine["torque_limit_Nmm"] == 0.3 and mine["target_depth_mm"] == pytest.approx(2.2)
    # ood has deeper holes, worse chips and other limits.
    draws = {name: drawn_scenarios(env, name, 200) for name in TRAIN_OOD}
    ar = {k: [s.aspect_ratio for s in v] for k, v in draws.items()}
    chips = {k: [s.chip_scale for s in v] for k, v in draws.items()}
    assert max(ar["train"]) <= 12.0 and max(ar["ood"]) > 12.0
    assert max(chips["train"]) <= 1.6 and max(chips["ood"]) > 1.6
    scales = {k: [s.torque_limit_scale for s in v] for k, v in draws.items()}
    assert set(scales["train"]) == {1.0} and min(scales["ood"]) < 0.85 < 1.15 < max(scales["ood"])
    d = [s.diameter_mm for v in draws.values() for s in v]
    assert 0.5 <= min(d) and max(d) <= 0.8


def test_bad_scenarios_name_the_field():
    with pytest.raises(ValueError, match="diameter_mm"):
        DrillingScenario("x", diameter_mm=3.0)
    with pytest.raises(ValueError, match="aspect_ratio"):
        DrillingScenario("x", 0.6, aspect_ratio=0.0)
    with pytest.raises(ValueError, match="chip_scale"):
        DrillingScenario("x", 0.6, chip_scale=float("nan"))


def test_splits_share_a_distribution_but_not_episodes():
    assert_splits_share_a_distribution_not_episodes(gym.make(DRILLING), lambda s: s.aspect_ratio)


def test_drawn_scenarios_pass_their_checks():
    """The split factories build scenarios without checking them again: every value they
    draw must lie in the checked ranges."""
    from machining_envs.drilling.scenarios import DRILLING_SCENARIOS
    from tests.helpers import assert_drawn_scenarios_pass_their_checks

    assert_drawn_scenarios_pass_their_checks(DRILLING_SCENARIOS)
