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

import math
import zlib
from collections.abc import Iterable

import numba
import numpy as np
from numpy.random.bit_generator import ISeedSequence

from machining_envs.core.checks import is_integer
from machining_envs.core.compiled.normals import next_word

__all__ = [
    "SPLITS",
    "HELD_OUT",
    "SPLIT_SEED_BASE",
    "MAX_SPLIT_EPISODES",
    "split_rng",
    "split_state",
    "lane_split_state",
    "split_stream",
    "SplitStream",
    "stream_bounded",
    "stream_double",
    "stream_fill",
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
    key = _split_key(split)  # before the draw: a bad name leaves rng as it was
    return _split_generator(draw_below_2_63(rng), key)


def _split_key(split: str) -> int:
    """The key ``split`` mixes into its generators' seeds (``ValueError`` for no split)."""
    key = _SPLIT_KEYS.get(split) if isinstance(split, str) else None
    if key is None:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    return key


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


def split_stream(rng: np.random.Generator, split: str) -> SplitStream:
    """The numbers of :func:`split_rng`'s generator, drawn by compiled code: what the
    scenario factories draw a ``split`` scenario with (every lane of a vector env draws
    one at each reset, and making a numpy ``Generator`` was a good part of that)."""
    return SplitStream(split_state(rng, split))


def split_state(rng: np.random.Generator, split: str) -> np.ndarray:
    """The state of :func:`split_stream`'s stream (see :class:`SplitStream`), for compiled
    code that draws from it with :func:`stream_double`, :func:`stream_fill` and
    :func:`stream_bounded`."""
    key = _split_key(split)
    x = draw_below_2_63(rng)
    state = np.empty(6, dtype=np.uint64)
    _seed_stream(x & 0xFFFFFFFF, x >> 32, key, state)
    return state


@numba.njit(cache=True)
def lane_split_state(table, k, key, state):
    """:func:`split_state` in compiled code, for lane ``k`` of a generator table
    (:class:`~machining_envs.core.compiled.normals.LaneGenerators`) and a split's ``key``
    (``_split_key``): ``state`` seeded from the lane generator's next draw below 2**63
    (its next 64-bit word shifted right by one, :func:`draw_below_2_63`'s number)."""
    x = next_word(table, k) >> _U1
    _seed_stream(np.int64(x & _LOW32), np.int64(x >> _U32), key, state)


class SplitStream:
    """A PCG64 stream that draws the numbers numpy's ``Generator(PCG64(...))`` draws from
    the same state, for the few methods scenario factories call, with numpy's arithmetic:
    :meth:`random` (``next_double``), :meth:`uniform` (``low + (high - low) u``) and
    :meth:`integers` (Lemire's bounded draw on 32-bit outputs, the second half of each
    64-bit output kept for the next, as numpy's PCG64 does). Made by :func:`split_stream`;
    ``tests/core/test_splits.py`` checks it against numpy's generator from many states.

    ``state``: the 128-bit state and increment (high words first), whether a 32-bit half is
    kept, and that half, as six uint64 values.
    """

    __slots__ = ("_state",)

    def __init__(self, state: np.ndarray) -> None:
        self._state = state

    def random(self, size=None):
        """Uniform numbers in [0, 1): a float, or an array of shape ``size``."""
        if size is None:
            return stream_double(self._state)
        out = np.empty(size)
        stream_fill(self._state, out.reshape(-1))
        return out

    def uniform(self, low: float = 0.0, high: float = 1.0, size=None):
        """Uniform numbers in [low, high): a float, or an array of shape ``size``."""
        low, high = float(low), float(high)
        span = high - low
        if not math.isfinite(span):
            raise OverflowError("high - low range exceeds valid bounds")
        if size is None:
            return low + span * stream_double(self._state)
        out = np.empty(size)
        stream_fill(self._state, out.reshape(-1))
        return low + span * out

    def integers(self, low: int, high: int) -> np.int64:
        """One integer in [low, high) (``int64``)."""
        low, high = int(low), int(high)
        if not -(2**63) <= low < high <= 2**63 or high - low > 2**32:
            raise ValueError(
                f"integers: need low < high within 2**32 of each other, got {low}, {high}"
            )
        return np.int64(low + stream_bounded(self._state, high - low - 1))


_U0, _U1, _U11, _U32, _U58, _U63, _U64 = (np.uint64(v) for v in (0, 1, 11, 32, 58, 63, 64))
_LOW32 = np.uint64(0xFFFFFFFF)
#: PCG64's multiplier (PCG_DEFAULT_MULTIPLIER_128), high and low words.
_MUL_HI = np.uint64(2549297995355413924)
_MUL_LO = np.uint64(4865540595714422341)


@numba.njit(cache=True, inline="always")
def _mul_high(a, b):
    """The high 64 bits of the 128-bit product of two uint64 values."""
    a0, a1, b0, b1 = a & _LOW32, a >> _U32, b & _LOW32, b >> _U32
    p01, p10 = a0 * b1, a1 * b0
    mid = ((a0 * b0) >> _U32) + (p01 & _LOW32) + (p10 & _LOW32)
    return a1 * b1 + (p01 >> _U32) + (p10 >> _U32) + (mid >> _U32)


@numba.njit(cache=True, inline="always")
def _advance(s):
    """The LCG step ``state = state * multiplier + increment`` (mod 2**128)."""
    lo = s[1] * _MUL_LO
    hi = s[0] * _MUL_LO + s[1] * _MUL_HI + _mul_high(s[1], _MUL_LO)
    s[1] = lo + s[3]
    s[0] = hi + s[2] + (_U1 if s[1] < lo else _U0)


@numba.njit(cache=True, inline="always")
def _next64(s):
    """The next 64-bit output: the state advanced, then its XSL-RR output."""
    _advance(s)
    v = s[0] ^ s[1]
    r = s[0] >> _U58
    return (v >> r) | (v << ((_U64 - r) & _U63))


@numba.njit(cache=True)
def _seed_stream(lo, hi, key, s):
    """``s`` seeded as ``PCG64(SeedSequence([lo + 2**32 hi, key]))``: the seed sequence's
    four 64-bit words (:func:`_seed_state`) as the initial state and the increment's
    sequence, as PCG64's seeding uses them."""
    w = np.empty(8, dtype=np.uint32)
    _seed_state(lo, hi, key, w)
    words = np.empty(4, dtype=np.uint64)
    for i in range(4):
        words[i] = np.uint64(w[2 * i]) | (np.uint64(w[2 * i + 1]) << _U32)
    s[0] = _U0
    s[1] = _U0
    s[2] = (words[2] << _U1) | (words[3] >> _U63)
    s[3] = (words[3] << _U1) | _U1
    _advance(s)
    lo_sum = s[1] + words[1]
    s[0] = s[0] + words[0] + (_U1 if lo_sum < s[1] else _U0)
    s[1] = lo_sum
    _advance(s)
    s[4] = _U0
    s[5] = _U0


@numba.njit(cache=True)
def stream_double(s):
    """The next uniform number in [0, 1) of the stream ``s`` (``Generator.random()``)."""
    return np.float64(_next64(s) >> _U11) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True)
def stream_fill(s, out):
    """``out`` (one dimension) filled with the stream's next uniform numbers in order."""
    for i in range(out.size):
        out[i] = stream_double(s)


@numba.njit(cache=True, inline="always")
def _next32(s):
    """The next 32-bit output: the kept high half of the last 64-bit one, else the low half
    of a new one (whose high half is kept)."""
    if s[4] != _U0:
        s[4] = _U0
        return s[5]
    v = _next64(s)
    s[4] = _U1
    s[5] = v >> _U32
    return v & _LOW32


@numba.njit(cache=True)
def stream_bounded(s, rng):
    """An integer in ``[0, rng]`` (``rng < 2**32``) by Lemire's method on 32-bit outputs:
    ``Generator.integers(low, low + rng + 1) - low``."""
    r = np.uint64(rng)
    if r == _U0:
        return 0
    if r == _LOW32:
        return np.int64(_next32(s))
    excl = r + _U1
    m = _next32(s) * excl
    left = m & _LOW32
    if left < excl:
        threshold = (_LOW32 - r) % excl
        while left < threshold:
            m = _next32(s) * excl
            left = m & _LOW32
    return np.int64(m >> _U32)


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
    if not is_integer(n) or not 1 <= n <= MAX_SPLIT_EPISODES:
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
