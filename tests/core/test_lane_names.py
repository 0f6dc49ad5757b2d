"""``core.lanes.LaneNames``: the names array a step hands out never changes after, and a
reset that keeps a lane's name copies nothing."""

import numpy as np

from machining_envs.core.lanes import LaneNames


def test_a_handed_out_array_keeps_its_names():
    names = LaneNames(4)
    names.set_many(np.arange(4), "train")
    first = names.array()
    assert not first.flags.writeable
    names[2] = "ood"
    names.set_many(np.array([0, 1]), "test")
    assert list(first) == ["train"] * 4
    assert list(names.array()) == ["test", "test", "ood", "train"]


def test_keeping_a_name_copies_nothing():
    names = LaneNames(3)
    names.set_many(np.arange(3), "train")
    handed = names.array()
    names.set_many(np.array([0, 2]), "train")
    names[1] = "train"
    assert names.array() is handed
    names.set_many(np.array([0, 2]), "wear")  # one lane renamed: a copy, the rest kept
    assert names.array() is not handed and list(names.array()) == ["wear", "train", "wear"]
