"""The scenario splits every env shares: ``train``, ``validation``, ``test`` and ``ood``.

- ``train``: the training distribution (training and the tuning of classical agents);
- ``validation``: the same distribution, for model selection and checks during tuning;
- ``test``: the same distribution again, touched only by the benchmark's final table;
- ``ood``: wider ranges than ``train`` (each env's scenarios module states them), reported
  apart from ``test``.

``train``, ``validation`` and ``test`` draw from one distribution, but each through its own
stream (:func:`split_rng`): a seed gives different episodes in different splits, so no test
workpiece is ever a training one, whatever seeds a training run happens to use. The
benchmark's episodes are fixed: episode ``i`` of a split is the reset with seed
``split_seeds(split, n)[i]``.

Training and tuning call :func:`check_not_held_out` on every scenario they evaluate on, so
that neither can touch ``test`` or ``ood``.

>>> from machining_envs.core.splits import split_seeds
>>> list(split_seeds("test", 3))
[10000, 10001, 10002]
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable

import numba
import numpy as np
from numpy.random.bit_generator import ISeedSequence

__all__ = [
    "SPLITS",
    "HELD_OUT",
    "SPLIT_SEED_BASE",
    "MAX_SPLIT_EPISODES",
    "split_rng",
    "uniform_draws",
    "split_seeds",
    "check_not_held_out",
]

#: The split names, in the order tables show them. ``wear``: the training ranges with a tool
#: that dulls within the cut; ``shopfloor``: the training ranges on a real CNC (quantised,
#: rate- and acceleration-limited, delayed feed override; a power-limited spindle). Each
#: exists in the envs that model it: ``wear`` in Turning-v0, EndMilling-v0 and
#: MicroDrilling-v0, ``shopfloor`` in Turning-v0, EndMilling-v0 and ContouringFeed-v0.
SPLITS = ("train", "validation", "test", "ood", "wear", "shopfloor")
#: Splits only the final table may evaluate on.
HELD_OUT = ("test", "ood", "wear", "shopfloor")
#: First reset seed of each split's fixed episodes (``split_seeds``).
SPLIT_SEED_BASE = {
    "train": 0,
    "validation": 5000,
    "test": 10000,
    "ood": 20000,
    "wear": 30000,
    "shopfloor": 40000,
}
#: Fixed episodes each split holds.
MAX_SPLIT_EPISODES = 5000


#: The key each split mixes into its generators' seeds (a CRC-32 of its name).
_SPLIT_KEYS = {name: zlib.crc32(name.encode()) for name in SPLITS}


def split_rng(rng: np.random.Generator, split: str) -> np.random.Generator:
    """A generator for drawing one ``split`` scenario: one draw of ``rng`` mixed with the
    split's name, so that the same seed gives unrelated episodes in different splits.

    It is the generator ``np.random.default_rng([rng.integers(2**63), crc32(split)])``,
    made several times faster (every lane of a vector env pays it at each reset): the
    draw is :func:`draw_below_2_63`, the seed sequence's hash runs compiled
    (:func:`_seed_state`), and numpy's PCG64 is seeded from the words it gives.
    ``tests/core/test_splits.py`` checks the two agree.
    """
    key = _SPLIT_KEYS.get(split) if isinstance(split, str) else None
    if key is None:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    return _split_generator(draw_below_2_63(rng), key)


def draw_below_2_63(rng: np.random.Generator) -> int:
    """``int(rng.integers(2**63))``, the same number from the same generator state, in a
    fifth of the time: numpy draws it by Lemire's method, which for the range ``2**63``
    never rejects and returns the generator's next 64-bit word shifted right by one (the
    word times ``2**63``, high 64 bits). A PCG64's raw output is that word, so it is read
    straight from the bit generator (gymnasium's generators are PCG64s); any other bit
    generator goes through ``integers``. ``tests/core/test_splits.py`` checks the two
    agree from many states."""
    bits = rng.bit_generator
    if type(bits) is np.random.PCG64:
        return bits.random_raw() >> 1
    return int(rng.integers(2**63))


def _split_generator(x: int, key: int) -> np.random.Generator:
    """``np.random.default_rng([x, key])`` for ``0 <= x < 2**63`` and a 32-bit ``key``."""
    words = np.empty(8, dtype=np.uint32)
    _seed_state(x & 0xFFFFFFFF, x >> 32, key, words)
    return np.random.Generator(np.random.PCG64(_SeedWords(words.view(np.uint64))))


def uniform_draws(rng: np.random.Generator, lows: list, spans: list) -> list[float]:
    """One uniform number in ``[low, low + span)`` for each pair, as Python floats: the
    numbers ``rng.uniform(low, low + span)`` gives one call at a time, in order (numpy
    computes each as ``low + (high - low) u`` from the generator's next double), drawn with
    one call (a scenario's reset draws several; each call costs some microseconds)."""
    u = rng.random(len(lows)).tolist()
    return [lo + span * r for lo, span, r in zip(lows, spans, u, strict=True)]


class _SeedWords(ISeedSequence):
    """The four 64-bit words a PCG64 takes from its seed sequence, computed beforehand."""

    __slots__ = ("words",)

    def __init__(self, words: np.ndarray) -> None:
        self.words = words

    def generate_state(self, n_words, dtype=np.uint32):
        if n_words != 4 or np.dtype(dtype) != np.uint64:
            raise ValueError("these words seed a PCG64 only (4 words of uint64)")
        return self.words


@numba.njit(cache=True)
def _hash32(value, mult_state, mult):
    """One step of the seed sequence's hash: ``value`` mixed with the running multiplier
    ``mult_state`` (returned advanced by ``mult``). All arithmetic modulo 2**32."""
    value = (value ^ mult_state) & 0xFFFFFFFF
    mult_state = (mult_state * mult) & 0xFFFFFFFF
    value = (value * mult_state) & 0xFFFFFFFF
    return value ^ (value >> 16), mult_state


@numba.njit(cache=True)
def _mix32(x, y):
    r = (0xCA01F9DD * x - 0x4973F715 * y) & 0xFFFFFFFF
    return r ^ (r >> 16)


@numba.njit(cache=True)
def _seed_state(lo, hi, key, out):
    """The eight 32-bit words numpy's ``SeedSequence([x, key]).generate_state(4, uint64)``
    holds, for ``x = lo + 2**32 hi < 2**63`` and ``key < 2**32``: the entropy words
    (``x`` in 32-bit words, low first, then ``key``) hashed into a pool of four, the pool
    mixed with itself, then hashed out into ``out`` (O'Neill's seed_seq design, as numpy's
    SeedSequence implements it)."""
    entropy = np.zeros(3, dtype=np.int64)
    entropy[0] = lo
    n = 1
    if hi != 0:
        entropy[1] = hi
        n = 2
    entropy[n] = key
    n += 1
    pool = np.zeros(4, dtype=np.int64)
    h = 0x43B0D7E5
    for i in range(4):
        pool[i], h = _hash32(entropy[i] if i < n else 0, h, 0x931E8875)
    for src in range(4):
        for dst in range(4):
            if src != dst:
                v, h = _hash32(pool[src], h, 0x931E8875)
                pool[dst] = _mix32(pool[dst], v)
    h = 0x8B51F9DD
    for i in range(8):
        v, h = _hash32(pool[i % 4], h, 0x58F38DED)
        out[i] = v


def split_seeds(split: str, n: int) -> range:
    """The reset seeds of the first ``n`` fixed episodes of ``split``."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if (
        isinstance(n, bool)
        or not isinstance(n, (int, np.integer))
        or not 1 <= n <= MAX_SPLIT_EPISODES
    ):
        raise ValueError(
            f"n (episodes of split {split!r}) must be an integer in [1, {MAX_SPLIT_EPISODES}], got {n!r}"
        )
    base = SPLIT_SEED_BASE[split]
    return range(base, base + int(n))


def check_not_held_out(scenarios: Iterable, what: str) -> None:
    """Raise ``ValueError`` if any of ``scenarios`` names a held-out split (``test``,
    ``ood``): ``what`` (training, tuning) may use ``train`` and ``validation`` only."""
    bad = [s for s in scenarios if isinstance(s, str) and s in HELD_OUT]
    if bad:
        raise ValueError(
            f"{what} must not evaluate on the held-out splits {list(HELD_OUT)} (got {bad}); "
            "use 'train' or 'validation': the test split is for the final table only"
        )
