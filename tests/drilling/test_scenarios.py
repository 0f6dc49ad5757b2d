"""Drilling scenarios: training and held-out sets, bad scenarios refused (by name
or object: ``tests/envs/test_scenarios.py``)."""

import pytest

from machining_envs import DrillingScenario
from tests.helpers import DRILLING, train_and_ood_values


def test_ood_has_deeper_holes_worse_chips_and_other_limits():
    fields = ("aspect_ratio", "chip_scale", "torque_limit_scale", "diameter_mm")
    ar, chips, scales, d = train_and_ood_values(DRILLING, 200, *fields).values()
    assert max(ar["train"]) <= 12.0 and max(ar["ood"]) > 12.0
    assert max(chips["train"]) <= 1.6 and max(chips["ood"]) > 1.6
    assert set(scales["train"]) == {1.0} and min(scales["ood"]) < 0.85 < 1.15 < max(scales["ood"])
    assert 0.5 <= min(d["train"] + d["ood"]) and max(d["train"] + d["ood"]) <= 0.8


def test_bad_scenarios_name_the_field():
    with pytest.raises(ValueError, match="diameter_mm"):
        DrillingScenario("x", diameter_mm=3.0)
    with pytest.raises(ValueError, match="aspect_ratio"):
        DrillingScenario("x", 0.6, aspect_ratio=0.0)
    with pytest.raises(ValueError, match="chip_scale"):
        DrillingScenario("x", 0.6, chip_scale=float("nan"))


def test_drawn_scenarios_pass_their_checks():
    """The split factories build scenarios without checking them again: every value they
    draw must lie in the checked ranges."""
    from machining_envs.drilling.scenarios import DRILLING_SCENARIOS
    from tests.helpers import assert_drawn_scenarios_pass_their_checks

    assert_drawn_scenarios_pass_their_checks(DRILLING_SCENARIOS)
