"""The split streams: ``split_rng`` is numpy's ``default_rng([draw, crc32(split)])``."""

import zlib

import numpy as np
import pytest

from machining_envs.core.splits import SPLITS, _split_generator, draw_below_2_63, split_rng


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
        fast = _split_generator(x, key)
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


@pytest.mark.parametrize(
    "bits", [np.random.PCG64, np.random.MT19937, np.random.Philox, np.random.PCG64DXSM]
)
def test_the_draw_below_2_63_is_numpys_integers(bits):
    """``draw_below_2_63`` gives ``integers(2**63)``'s numbers and leaves the generator in
    its state, whatever was drawn before (doubles, normals, 32-bit integers whose other half
    numpy keeps for the next one), on gymnasium's PCG64 and on other bit generators."""
    for seed in range(300):
        a = np.random.Generator(bits(seed))
        b = np.random.Generator(bits(seed))
        for g in (a, b):  # the same earlier draws on both
            if seed % 4 == 1:
                g.integers(0, 5)
            elif seed % 4 == 2:
                g.random(3)
            elif seed % 4 == 3:
                g.standard_normal(7)
                g.integers(0, 3, size=3)
        for _ in range(3):
            assert draw_below_2_63(a) == int(b.integers(2**63)), seed
        assert np.array_equal(a.random(4), b.random(4)), seed  # and on from the same state


def test_split_stream_draws_the_numbers_of_split_rng():
    """The compiled stream a scenario factory draws from gives the numbers numpy's generator
    of :func:`split_rng` gives, call for call, from many lane states and in every split:
    single and shaped ``random``, ``uniform`` with and without a size, and ``integers``
    over small and large ranges, interleaved (so the 32-bit half ``integers`` keeps is
    tested too)."""
    from machining_envs.core.splits import split_stream

    for seed in range(400):
        for split in SPLITS:
            a, b = np.random.default_rng(seed), np.random.default_rng(seed)
            g, s = split_rng(a, split), split_stream(b, split)
            assert a.bit_generator.state == b.bit_generator.state  # one draw each
            got, want = [], []
            for draw in (
                lambda r: r.random(),
                lambda r: int(r.integers(2, 6)),
                lambda r: r.random((4, 3)).tolist(),
                lambda r: r.uniform(-3.0, 7.5),
                lambda r: r.uniform(0.5, 2.0, 3).tolist(),
                lambda r: int(r.integers(0, 2**32)),
                lambda r: int(r.integers(-5, 1_000_003)),
                lambda r: int(r.integers(7, 8)),
                lambda r: r.random(5).tolist(),
            ):
                want.append(draw(g))
                got.append(draw(s))
            assert got == want
    with pytest.raises(ValueError, match="split must be one of"):
        split_stream(np.random.default_rng(0), "nope")


def test_drawn_profile_is_depth_profile_random_between_uniforms():
    """The compiled draw the scenario factories use (uniforms, a random workpiece,
    uniforms, from a split's stream) gives what ``random``, ``DepthProfile.random`` and
    ``random`` give from :func:`split_rng`'s generator: the same numbers and the same
    profile, over many states and both factories' shapes."""
    from machining_envs.core.splits import split_state
    from machining_envs.core.workpieces import DepthProfile, cut_ranges, drawn_profile

    for seed in range(300):
        for before, after, segments, seg_mm in (
            (1, 5, (2, 5), (4.0, 12.0)),
            (0, 6, (2, 6), (5.0, 12.0)),
        ):
            a, b = np.random.default_rng(seed), np.random.default_rng(seed)
            g = split_rng(a, "train")
            want_b = g.random(before)
            want = DepthProfile.random(g, (0.5, 3.0), segments, seg_mm, 0.3, 2.5, name="p")
            want_a = g.random(after)
            ranges = cut_ranges((0.5, 3.0), segments, seg_mm, 0.3, 2.5)
            got_b, got, got_a = drawn_profile(split_state(b, "train"), before, ranges, after, "p")
            assert got == want
            np.testing.assert_array_equal(got.segment_array(), want.segment_array())
            assert got_b.tolist() == want_b.tolist() and got_a.tolist() == want_a.tolist()
