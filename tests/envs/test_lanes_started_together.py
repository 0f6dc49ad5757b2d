"""What the cores that start many lanes at once (``start_lanes``: Turning-v0, EndMilling-v0)
share: each lane's scenario and true parameters are built only when read, a pickle or
copy of the core carries what is still to be built, and a split the batch cannot take
unchecked is started lane by lane. Each process's own file
(``tests/<process>/test_batched_start.py``) compares the lanes with lanes started one by
one."""

import copy
import pickle

import gymnasium as gym
import pytest

from tests.helpers import MILLING, TURNING, started_together_and_one_by_one


@pytest.mark.parametrize("env_id", [TURNING, MILLING])
def test_a_batch_builds_the_lanes_objects_only_when_read(env_id):
    one, many, lanes = started_together_and_one_by_one(env_id, "train")
    assert (many.scenarios._batch[lanes] >= 0).all() and (many.truths._batch[lanes] >= 0).all()
    assert many.scenarios[4] == one.scenarios[4]
    assert many.scenarios._batch[4] == -1 and many.scenarios._batch[7] >= 0
    for clone in (pickle.loads(pickle.dumps(many)), copy.deepcopy(many)):
        assert clone.scenarios[7] == one.scenarios[7]
        assert clone.truths[11] == one.truths[11]


@pytest.mark.parametrize(
    ("env_id", "limit_name", "breakage"),
    [
        # ood draws limits up to 1300 N; train's 1000 N is below 1100 N
        (TURNING, "breakage_force_N", 1100.0),
        # ood draws limits up to 1.4 x 3600 N·mm; train's reach 1.25 x 3600 = 4500 N·mm
        (MILLING, "breakage_torque_Nmm", 4600.0),
    ],
)
def test_a_scenario_the_batch_would_let_through_unchecked_goes_lane_by_lane(
    env_id, limit_name, breakage
):
    """Nominal parameters for which a split's ends would break the tool (the limit at or
    above the breakage load): the batch is not taken and the lane's own check names the
    problem, as a single env's reset does; the split whose limits stay below it is
    batched."""
    venv = gym.make_vec(env_id, num_envs=2, **{limit_name: breakage})
    with pytest.raises(ValueError, match=limit_name):
        venv.reset(seed=0, options={"scenario": "ood"})
        for _ in range(50):
            venv.reset(options={"scenario": "ood"})
    venv.reset(seed=0)
    checked = {f.name: ok for f, ok in venv.unwrapped._core._batch_ok.items()}
    assert checked == {"train": True, "ood": False}
