"""Turning scenarios: by name or object, training and held-out sets, bad scenarios refused."""

import gymnasium as gym
import numpy as np
import pytest

from machining_envs import TurningScenario
from machining_envs.core.workpieces import DepthProfile
from machining_envs.turning.scenarios import machining_time_bound
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


def _bound_by_quadrature(sc, truth, n=200_000):
    """The floor by the midpoint rule on a fine grid (independent of the closed form)."""
    x = (np.arange(n) + 0.5) * sc.profile.length_mm / n
    a = np.asarray(sc.profile(x), dtype=float)
    feed = np.where(a > 0, (sc.force_limit_N / (truth.force_coefficient * np.maximum(a, 1e-300)))
                    ** (1.0 / truth.feed_exponent), np.inf)  # fmt: skip
    v = np.minimum(truth.max_feed_velocity_mm_s, feed * sc.spindle_rpm / 60.0)
    return float(np.sum(1.0 / v) * sc.profile.length_mm / n)


@pytest.mark.parametrize("name", ["paper_245", "paper_700", "taper_405", "train", "ood"])
def test_machining_time_bound_matches_a_fine_quadrature(name):
    """The closed form against the midpoint rule on 200 000 points. The rule is exact on
    plateaus and second order on tapers; at each depth step it errs by at most one cell
    (length / 200 000) times the jump in 1/v, about 5e-6 of the total per step: hence 2e-5."""
    env = gym.make(TURNING)
    for seed in range(3):
        env.reset(seed=seed, options={"scenario": name})
        sc = env.unwrapped.scenario
        truth = sc.true_params(env.unwrapped.params)
        assert machining_time_bound(sc, truth) == pytest.approx(
            _bound_by_quadrature(sc, truth), rel=2e-5
        )


def test_bad_scenario_names_the_field():
    with pytest.raises(ValueError, match="spindle_rpm"):
        TurningScenario("x", DepthProfile.steps(), spindle_rpm=-1.0)
