"""Turning scenarios: by name or object, training and held-out sets, bad scenarios refused."""

import gymnasium as gym
import pytest

from machining_envs import TurningScenario
from machining_envs.core.workpieces import DepthProfile
from tests.helpers import TRAIN_TEST, TURNING, assert_test_reaches_beyond_train, drawn_scenarios


def test_scenarios_by_name_and_object():
    env = gym.make(TURNING)
    _, info = env.reset(seed=0, options={"scenario": "taper_405"})
    assert info["scenario"] == "taper_405" and info["workpiece_length_mm"] == 45.0
    sc = TurningScenario("mine", DepthProfile.steps((0.5, 1.5), 5.0), spindle_rpm=600.0)
    _, info = env.reset(options={"scenario": sc})
    assert info["scenario"] == "mine" and info["spindle_rpm"] == 600.0
    # train and test differ: the held-out set reaches speeds the training set never does.
    rpms = {name: [s.spindle_rpm for s in drawn_scenarios(env, name, 200)] for name in TRAIN_TEST}
    assert_test_reaches_beyond_train(rpms, 245.0, 700.0)


def test_bad_scenario_names_the_field():
    with pytest.raises(ValueError, match="spindle_rpm"):
        TurningScenario("x", DepthProfile.steps(), spindle_rpm=-1.0)
