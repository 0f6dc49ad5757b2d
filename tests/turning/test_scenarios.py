"""Turning scenarios: by name or object, training and held-out sets, bad scenarios refused."""

import gymnasium as gym

from machining_envs import TurningScenario
from machining_envs.core.workpieces import DepthProfile
from tests.helpers import (
    TRAIN_OOD,
    TURNING,
    assert_ood_reaches_beyond_train,
    assert_splits_share_a_distribution_not_episodes,
    drawn_scenarios,
)


def test_scenarios_by_name_and_object():
    env = gym.make(TURNING)
    _, info = env.reset(seed=0, options={"scenario": "taper_405"})
    assert info["scenario"] == "taper_405" and info["workpiece_length_mm"] == 45.0
    sc = TurningScenario("mine", DepthProfile.steps((0.5, 1.5), 5.0), spindle_rpm=600.0)
    _, info = env.reset(options={"scenario": sc})
    assert info["scenario"] == "mine" and info["spindle_rpm"] == 600.0
    # ood reaches speeds and limits the training set never does.
    rpms = {name: [s.spindle_rpm for s in drawn_scenarios(env, name, 200)] for name in TRAIN_OOD}
    assert_ood_reaches_beyond_train(rpms, 245.0, 700.0)
    limits = {n: [s.force_limit_N for s in drawn_scenarios(env, n, 100)] for n in TRAIN_OOD}
    assert set(limits["train"]) == {1000.0}
    assert min(limits["ood"]) < 800.0 and max(limits["ood"]) > 1200.0


def test_splits_share_a_distribution_but_not_episodes():
    assert_splits_share_a_distribution_not_episodes(gym.make(TURNING), lambda s: s.spindle_rpm)
