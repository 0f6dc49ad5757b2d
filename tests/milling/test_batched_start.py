"""Many lanes started at once (``MillingCore.start_lanes``): the same episodes as lane by
lane, for every scenario name and both torque laws, with each lane's scenario and truth
built when read."""

import gymnasium as gym
import pytest

from machining_envs.core.actuation import SHOPFLOOR_ACTUATION
from machining_envs.milling.plant import MillingParams
from machining_envs.milling.scenarios import MILLING_SCENARIOS
from tests.helpers import MILLING, assert_cores_alike, started_together_and_one_by_one

N = 12
PARAMS = {"power_law": MillingParams(), "average_force": MillingParams.ahn_choi_al6061()}
#: Env options a batch must respect: a nominal tool that wears (the splits' truths are
#: sharp all the same) and the CNC's actuation set for every lane.
OPTIONS = {
    "worn_nominal": {"params": MillingParams(wear_per_100mm=1.0)},
    "actuation": {"actuation": SHOPFLOOR_ACTUATION},
}


def _cores(spec, **kwargs):
    return started_together_and_one_by_one(MILLING, spec, N, **kwargs)


@pytest.mark.parametrize("law", sorted(PARAMS))
@pytest.mark.parametrize("spec", sorted(MILLING_SCENARIOS))
def test_lanes_started_together_start_as_one_by_one(spec, law):
    """Every array of the env and the plant, every lane's scenario, truth and name, and the
    generators' states: the same, bit for bit; and the lanes step alike after."""
    one, many, lanes = _cores(spec, params=PARAMS[law])
    batched = {"train", "validation", "test", "ood", "shopfloor"}  # wear: bound in Python
    assert many._batch_ok.get(MILLING_SCENARIOS[spec], False) == (spec in batched)
    _assert_same(one, many)


@pytest.mark.parametrize("option", sorted(OPTIONS))
def test_env_options_start_together_as_one_by_one(option):
    """The env's own options (``OPTIONS``) reach the lanes started together as they reach
    those started one by one."""
    one, many, _ = _cores("train", **OPTIONS[option])
    assert many._batch_ok[MILLING_SCENARIOS["train"]]
    _assert_same(one, many)


def _assert_same(one, many):
    """Two cores alike (``assert_cores_alike``), now and after a step of both."""
    assert_cores_alike(one, many)
    for core in (one, many):
        core.in_action[:] = 0.3
        core.step()
    assert_cores_alike(one, many)


def test_a_spindle_range_the_nominal_speed_pushes_out_goes_lane_by_lane():
    """A nominal speed whose split range reaches past ``SPINDLE_RPM_RANGE``: the lane's
    own check refuses it."""
    venv = gym.make_vec(MILLING, num_envs=2, spindle_rpm=5500.0)  # train: up to 6875 rpm
    with pytest.raises(ValueError, match="spindle_rpm range"):
        for seed in range(50):
            venv.reset(seed=seed)
    assert not venv.unwrapped._core._batch_ok[MILLING_SCENARIOS["train"]]


def test_a_drawn_speed_outside_the_range_stops_the_batch(monkeypatch):
    """The batch checks every drawn speed against ``SPINDLE_RPM_RANGE`` itself (a range's end
    may round past it): a lane outside raises ``ValueError`` naming the speed's range. Here
    the batch's range is narrowed below the train split's speeds (320-500 rpm)."""
    import machining_envs.milling.lanes as milling_env

    venv = gym.make_vec(MILLING, num_envs=4)
    monkeypatch.setattr(milling_env, "SPINDLE_RPM_RANGE", (20.0, 330.0))
    with pytest.raises(ValueError, match=r"lane \d: spindle_scale .* spindle_rpm range"):
        venv.reset(seed=0)
