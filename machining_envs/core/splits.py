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

import numpy as np

__all__ = [
    "SPLITS",
    "HELD_OUT",
    "SPLIT_SEED_BASE",
    "MAX_SPLIT_EPISODES",
    "split_rng",
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


def split_rng(rng: np.random.Generator, split: str) -> np.random.Generator:
    """A generator for drawing one ``split`` scenario: one draw of ``rng`` mixed with the
    split's name, so that the same seed gives unrelated episodes in different splits."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    key = zlib.crc32(split.encode())
    return np.random.default_rng([int(rng.integers(2**63)), key])


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
