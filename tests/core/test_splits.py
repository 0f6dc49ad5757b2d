"""The split streams: ``split_rng`` is numpy's ``default_rng([draw, crc32(split)])``."""

import zlib

import numpy as np
import pytest

from machining_envs.core.splits import SPLITS, split_rng


class _Draw:
    """Stands in for the env's generator: its one draw is ``x``."""

    def __init__(self, x: int) -> None:
        self.x = x

    def integers(self, high: int) -> int:
        assert high == 2**63
        return self.x


def _draws():
    edges = [0, 1, 2**32 - 1, 2**32, 2**32 + 1, 2**63 - 1]
    rng = np.random.default_rng(2024)
    small = rng.integers(2**32, size=300).tolist()  # one 32-bit entropy word
    large = rng.integers(2**32, 2**63, size=300).tolist()  # two
    return edges + small + large


@pytest.mark.parametrize("split", SPLITS)
def test_split_rng_is_numpys_default_rng_of_the_draw_and_the_split_key(split):
    key = zlib.crc32(split.encode())
    for x in _draws():
        fast = split_rng(_Draw(x), split)
        ref = np.random.default_rng([x, key])
        assert fast.bit_generator.state == ref.bit_generator.state, x
    # and the numbers drawn from it, through the env's real generator
    a = split_rng(np.random.default_rng(5), split).random(8)
    b = np.random.default_rng([int(np.random.default_rng(5).integers(2**63)), key]).random(8)
    assert np.array_equal(a, b)


def test_split_rng_names_the_allowed_splits():
    with pytest.raises(ValueError, match="split must be one of"):
        split_rng(np.random.default_rng(0), "holdout")
    with pytest.raises(ValueError, match="split must be one of"):
        split_rng(np.random.default_rng(0), 3)
