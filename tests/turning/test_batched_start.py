"""Many lanes started at once (``_TurningCore.start_lanes``): the same episodes as lane by
lane, for every scenario name, with each lane's scenario and truth built when read."""

import gymnasium as gym
import pytest

from machining_envs.core.env import LaneObjects
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
        assert one.episode_info[k] == many.episode_info[k], k


def test_a_scenario_the_batch_would_let_through_unchecked_goes_lane_by_lane():
    """Nominal parameters for which a split's ends would break the tool (the force limit
    at or above ``breakage_force_N``): the batch is not taken and the lane's own check
    names the problem, as a single env's reset does."""
    venv = gym.make_vec(TURNING, num_envs=2, breakage_force_N=1100.0)
    with pytest.raises(ValueError, match="breakage_force_N"):
        venv.reset(seed=0, options={"scenario": "ood"})
        for _ in range(50):  # ood draws limits up to 1300 N
            venv.reset(options={"scenario": "ood"})
    venv.reset(seed=0)  # train's 1000 N limit is below it: batched
    checked = {f.name: ok for f, ok in venv.unwrapped._core._batch_ok.items()}
    assert checked == {"train": True, "ood": False}


def test_lane_objects_build_once_and_setting_wins():
    calls = []

    def build(x):
        calls.append(x)
        return [x]

    objs = LaneObjects(3)
    objs.defer_many([1], [(build, 5)])
    assert objs[0] is None and calls == []
    assert objs[1] == [5] and objs[1] is objs[1] and calls == [5]
    objs.defer_many([2], [(build, 6)])
    objs[2] = "set"
    assert objs[2] == "set" and calls == [5] and len(objs) == 3
