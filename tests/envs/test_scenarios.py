"""The cutting envs' scenarios: chosen by name or given as an object, and held-out splits
that draw from the training distribution but never its episodes."""

from operator import attrgetter

import gymnasium as gym
import pytest

from machining_envs import (
    ContouringScenario,
    DrillingScenario,
    MillingScenario,
    Path,
    TurningScenario,
)
from machining_envs.core.workpieces import DepthProfile
from tests.helpers import (
    CONTOURING,
    DRILLING,
    MILLING,
    TURNING,
    assert_ood_reaches_beyond_train,
    assert_splits_share_a_distribution_not_episodes,
    train_and_ood_values,
)

_STEPS = DepthProfile.steps((0.5, 1.5), 5.0)

# (env id, a named scenario and its info, a scenario object and its info)
BY_NAME_AND_OBJECT = [
    (
        TURNING,
        ("taper_405", {"workpiece_length_mm": 45.0}),
        (TurningScenario("mine", _STEPS, spindle_rpm=600.0), {"spindle_rpm": 600.0}),
    ),
    (
        MILLING,
        (
            "paper_taper",
            {
                "workpiece_length_mm": 40.0,
                "workpiece_volume_mm3": pytest.approx(32.0 * 40.0 * 1.5),
            },
        ),
        (MillingScenario("mine", _STEPS, spindle_scale=1.5), {"spindle_rpm": 600.0}),
    ),
    (
        DRILLING,
        ("paper_0.7", {"target_depth_mm": pytest.approx(7.0)}),
        (
            DrillingScenario("mine", 0.55, aspect_ratio=4.0, torque_limit_Nmm=0.3),
            {"diameter_mm": 0.55, "torque_limit_Nmm": 0.3, "target_depth_mm": pytest.approx(2.2)},
        ),
    ),
    (
        CONTOURING,
        ("paper_corner", {"path_length_mm": pytest.approx(100.0)}),
        (
            ContouringScenario("mine", Path.line((1.0, 1.0), (5.0, 4.0)), feed_mm_s=20.0),
            {"x_mm": 1.0, "y_mm": 1.0},
        ),
    ),
]


@pytest.mark.parametrize("env_id, named, given", BY_NAME_AND_OBJECT)
def test_scenarios_by_name_and_object(env_id, named, given):
    """``reset(options={"scenario": ...})`` takes a split's or paper's scenario by name, or
    a scenario object; the info names it and shows its values."""
    env = gym.make(env_id)
    (name, expected), (scenario, expected_given) = named, given
    _, info = env.reset(seed=0, options={"scenario": name})
    assert info["scenario"] == name and {k: info[k] for k in expected} == expected
    _, info = env.reset(options={"scenario": scenario})
    assert info["scenario"] == scenario.name
    assert {k: info[k] for k in expected_given} == expected_given


@pytest.mark.parametrize(
    "env_id, field, inside",
    [
        (TURNING, "spindle_rpm", ()),
        (MILLING, "spindle_scale", ("test",)),
        (DRILLING, "aspect_ratio", ()),
    ],
)
def test_splits_share_a_distribution_but_not_episodes(env_id, field, inside):
    assert_splits_share_a_distribution_not_episodes(
        gym.make(env_id), attrgetter(field), inside=inside
    )


@pytest.mark.parametrize(
    "env_id, field, n, train_low, train_high",
    [
        (TURNING, "spindle_rpm", 200, 245.0, 700.0),
        (MILLING, "spindle_scale", 200, 0.67, 1.6),
        (CONTOURING, "feed_mm_s", 100, 20.0, 60.0),
    ],
)
def test_ood_reaches_beyond_train(env_id, field, n, train_low, train_high):
    """The ``ood`` split reaches speeds (feeds) the training set, within ``[train_low,
    train_high]``, never does."""
    values = train_and_ood_values(env_id, n, field)[field]
    assert_ood_reaches_beyond_train(values, train_low, train_high)
