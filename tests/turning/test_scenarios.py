"""Turning scenarios: training and held-out sets, bad scenarios refused (by name
or object: ``tests/envs/test_scenarios.py``)."""

import gymnasium as gym

from machining_envs.core.workpieces import DepthProfile
from tests.helpers import (
    TURNING,
    split_draws,
    train_and_ood_values,
)


def test_ood_reaches_limits_training_never_does():
    """(And speeds: ``tests/envs/test_scenarios.py``.)"""
    limits = train_and_ood_values(TURNING, 200, "force_limit_N")["force_limit_N"]
    assert set(limits["train"]) == {1000.0}
    assert min(limits["ood"]) < 800.0 and max(limits["ood"]) > 1200.0


def test_split_draws_are_numpys_scalar_draws_in_order():
    """The split scenarios are drawn as one scalar draw per field, in a fixed order (the
    split's episodes must never change): the factories compute the same numbers from fewer
    calls, and skip the checks of values drawn from checked ranges."""
    import numpy as np

    from machining_envs.turning.scenarios import TURNING_SCENARIOS

    for split, sc, rng in split_draws(TURNING_SCENARIOS, ("train", "ood", "wear", "shopfloor")):
        ood = split == "ood"
        rpm = (200.0, 800.0) if ood else (245.0, 700.0)
        assert sc.spindle_rpm == float(np.exp(rng.uniform(np.log(rpm[0]), np.log(rpm[1]))))
        prof = DepthProfile.random(
            rng, (0.5, 3.5) if ood else (0.5, 3.0), (2, 6) if ood else (2, 5), (4.0, 12.0)
        )
        assert sc.profile.edges_mm == prof.edges_mm
        assert sc.profile.end_depths_mm == prof.end_depths_mm
        assert sc.force_coefficient_scale == rng.uniform(0.8, 1.2)
        assert sc.feed_exponent_scale == rng.uniform(0.8, 1.2)
        assert sc.noise_scale == rng.uniform(0.5, 2.0)
        assert sc.force_limit_N == (rng.uniform(700.0, 1300.0) if ood else 1000.0)
        assert sc.wear_per_100mm == (rng.uniform(0.3, 1.0) if split == "wear" else 0.0)


def test_the_envs_score_bound_is_machining_time_bound():
    """A lane's score bound, computed by the compiled start for a sharp tool, is
    ``machining_time_bound`` of its scenario and true parameters to the last bit: on every
    split that draws its cuts, with and without the spindle's power limit."""
    from machining_envs.turning.scenarios import machining_time_bound

    venv = gym.make_vec("machining_envs/Turning-v0", num_envs=8)
    for split in ("train", "ood", "shopfloor", "wear", "paper_405", "taper_405"):
        venv.reset(seed=3, options={"scenario": split})
        core = venv.unwrapped._core
        for k in range(8):
            sc = core.scenarios[k]
            assert core.bound[k] == machining_time_bound(sc, sc.true_params(core.params))
    venv.close()
