"""Many lanes started at once (``TurningCore.start_lanes``): the same episodes as lane by
lane, for every scenario name, with each lane's scenario and truth built when read."""

import numpy as np
import pytest

from machining_envs.core.lanes import LaneObjects
from machining_envs.turning.scenarios import TURNING_SCENARIOS
from tests.helpers import TURNING, assert_cores_alike, started_together_and_one_by_one

N = 12


def _cores(spec, **kwargs):
    return started_together_and_one_by_one(TURNING, spec, N, **kwargs)


@pytest.mark.parametrize("spec", sorted(TURNING_SCENARIOS))
def test_lanes_started_together_start_as_one_by_one(spec):
    """Every array of the env and the plant, every lane's scenario, truth, name and
    episode info, and the generators' states: the same, bit for bit."""
    one, many, lanes = _cores(spec)
    batched = {"train", "validation", "test", "ood", "shopfloor"}  # wear: bound in Python
    assert many._batch_ok.get(TURNING_SCENARIOS[spec], False) == (spec in batched)
    assert_cores_alike(one, many)
    assert one.power_lanes == many.power_lanes
    for k in range(N):
        if spec in batched:  # left to lane_info, which builds it from the arrays
            assert many.episode_info[k] is None
        one.lane_info(k), many.lane_info(k)
        assert repr(one.episode_info[k]) == repr(many.episode_info[k]), k


def test_lane_objects_build_once_and_setting_wins():
    calls = []

    def build(x, i):
        calls.append((x, i))
        return [x, i]

    objs = LaneObjects(4)
    objs.defer(np.array([3, 1]), build, 5)
    assert objs[0] is None and calls == []
    assert objs[1] == [5, 1] and objs[1] is objs[1] and calls == [(5, 1)]
    objs.defer(np.array([2]), build, 6)
    objs[2] = "set"
    assert objs[2] == "set" and calls == [(5, 1)] and len(objs) == 4
    objs.defer(np.array([1]), build, 7)  # the last word wins: a new recipe, or a set object
    assert objs[1] == [7, 0] and objs[3] == [5, 0]


def test_lane_objects_keep_only_the_recipes_lanes_are_left_to():
    """Every batch of starts leaves a recipe; those no lane is left to any more are
    forgotten (steady stepping starts a batch a step), and an error while building leaves
    the lane to build again."""
    failing = [True]

    def build(x, i):
        if failing[0]:
            raise RuntimeError("not now")
        return (x, i)

    objs = LaneObjects(8)
    for step in range(1000):
        objs.defer(np.array([step % 8]), build, step)
    assert len(objs._recipes) <= 2 * 8 + 64
    with pytest.raises(RuntimeError):
        objs[3]
    failing[0] = False
    assert objs[3] == (995, 0) and objs[7] == (999, 0)
