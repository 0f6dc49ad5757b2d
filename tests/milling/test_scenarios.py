"""Milling scenarios: training and held-out sets, the cut area of a profile, bad scenarios
refused (by name or object: ``tests/envs/test_scenarios.py``)."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

from machining_envs import MillingScenario
from machining_envs.core.workpieces import DepthProfile
from machining_envs.milling.scenarios import cut_area_mm2
from tests.helpers import (
    MILLING,
    split_draws,
    train_and_ood_values,
)


def test_ood_reaches_depths_training_never_does():
    """(And speeds: ``tests/envs/test_scenarios.py``.)"""
    depth = train_and_ood_values(MILLING, 200, "profile.max_depth_mm")["profile.max_depth_mm"]
    assert max(depth["train"]) <= 3.5 < max(depth["ood"])


def test_ood_strictly_contains_train_in_every_field():
    """Every range ``ood`` draws from reaches beyond ``train``'s at both ends (the number of
    segments: at the top); ``validation`` draws from ``train``'s ranges, and ``test``, ``wear``
    and ``shopfloor`` from ranges inside them."""
    from machining_envs.milling.scenarios import MILLING_SCENARIOS

    train, ood = MILLING_SCENARIOS["train"], MILLING_SCENARIOS["ood"]
    assert ood.depth[0] < train.depth[0] and ood.depth[1] > train.depth[1]
    assert ood.segments[0] <= train.segments[0] and ood.segments[1] > train.segments[1]
    fields = (
        "spindle_scale",
        "torque_limit_scale",
        "torque_coefficient_scale",
        "feed_exponent_scale",
    )
    for field in fields:
        (t_lo, t_hi), (o_lo, o_hi) = ([getattr(s, field) for s in f.extremes] for f in (train, ood))
        assert o_lo < t_lo < t_hi < o_hi, field
    same = MILLING_SCENARIOS["validation"]
    assert (same.depth, same.segments, same.lows, same.spans) == (
        train.depth,
        train.segments,
        train.lows,
        train.spans,
    )
    for split in ("test", "wear", "shopfloor"):
        inner = MILLING_SCENARIOS[split]
        assert train.depth[0] <= inner.depth[0] < inner.depth[1] <= train.depth[1], split
        assert inner.segments == train.segments, split
        for field in fields:
            (t_lo, t_hi), (i_lo, i_hi) = (
                [getattr(s, field) for s in f.extremes] for f in (train, inner)
            )
            assert t_lo <= i_lo < i_hi <= t_hi, (split, field)
        assert [dataclasses.replace(s, name="") for s in same.extremes] == [
            dataclasses.replace(s, name="") for s in train.extremes
        ]


def test_cut_area_is_the_integral_of_the_profile():
    prof = DepthProfile((0.0, 3.0, 7.0, 12.0), (1.0, 0.5, 2.0), (2.0, 0.5, 3.0))
    for end in (0.0, 1.7, 3.0, 6.2, 12.0, 20.0):
        stop = min(end, 12.0)
        mid = (np.arange(200_000) + 0.5) * stop / 200_000  # midpoint rule
        numeric = float(np.sum(prof(mid)) * stop / 200_000)
        # The midpoint rule errs by up to a cell times a jump of depth (6e-5 mm x 1.5 mm).
        assert cut_area_mm2(prof, end) == pytest.approx(numeric, abs=1e-4)


def test_bad_scenarios_name_the_field():
    with pytest.raises(ValueError, match="spindle_scale"):
        MillingScenario("x", DepthProfile.steps(), spindle_scale=-1.0)
    with pytest.raises(ValueError, match="profile"):
        MillingScenario("x", [1.0, 2.0])


def test_split_draws_are_numpys_scalar_draws_in_order():
    """The split scenarios are drawn as one scalar draw per field, in a fixed order (the
    split's episodes must never change): the factories compute the same numbers from one
    call, and skip the checks of values drawn from checked ranges."""
    from machining_envs.milling.scenarios import MILLING_SCENARIOS

    for split, sc, rng in split_draws(MILLING_SCENARIOS, ("train", "ood", "wear")):
        ood = split == "ood"
        ks, m, d_range, s_range = {
            "train": (0.3, 0.2, (0.5, 3.5), (0.67, 1.6)),
            "ood": (0.4, 0.25, (0.4, 4.0), (0.6, 1.8)),
            "wear": (0.2, 0.2, (0.5, 3.0), (0.8, 1.25)),  # the benchmark's ranges
        }[split]
        l_range = (0.7, 1.4) if ood else (0.8, 1.25)
        prof = DepthProfile.random(rng, d_range, (2, 6) if ood else (2, 5), (5.0, 12.0), 0.3)
        assert sc.profile.edges_mm == prof.edges_mm
        assert sc.profile.end_depths_mm == prof.end_depths_mm
        assert sc.spindle_scale == float(np.exp(rng.uniform(*np.log(s_range))))
        assert sc.torque_limit_scale == float(np.exp(rng.uniform(*np.log(l_range))))
        assert sc.torque_coefficient_scale == rng.uniform(1 - ks, 1 + ks)
        assert sc.feed_exponent_scale == rng.uniform(1 - m, 1 + m)
        assert sc.noise_scale == rng.uniform(0.5, 2.0)
        assert sc.wear_per_100mm == (rng.uniform(0.5, 1.5) if split == "wear" else 0.0)


def test_the_envs_score_bound_and_volume_are_the_scenarios():
    """A lane's score bound and workpiece volume, computed by the compiled start, are
    ``machining_time_bound`` and the axial depth times ``CutArea``'s total of its scenario
    and true parameters to the last bit, on the splits that draw their cuts and the paper's
    workpieces, with either force model."""
    from machining_envs.milling.scenarios import CutArea, machining_time_bound

    for overrides in ({}, {"force_model": "average_force"}):
        venv = gym.make_vec("machining_envs/EndMilling-v0", num_envs=6, **overrides)
        for split in ("train", "ood", "wear", "paper_step", "paper_taper"):
            venv.reset(seed=5, options={"scenario": split})
            core = venv.unwrapped._core
            for k in range(6):
                sc, truth = core.scenarios[k], core.truths[k]
                rpm = sc.spindle_rpm(core.params)
                assert core.bound[k] == machining_time_bound(sc, truth, rpm)
                assert core.volume[k] == truth.axial_depth_mm * CutArea(sc.profile).total
        venv.close()
