"""What the cores that start many lanes at once (``start_lanes``: Turning-v0, EndMilling-v0)
share: each lane's scenario and true parameters are built only when read, and a pickle or
copy of the core carries what is still to be built. Each process's own file
(``tests/<process>/test_batched_start.py``) compares the lanes with lanes started one by
one."""

import copy
import pickle

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
