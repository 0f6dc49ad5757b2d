"""Checks of parameter values: a finite number in a range, an integer in a range, and one
value below another (a check across fields).

Every check raises ``ValueError`` with one message format, which names the parameter, the
value and the allowed range: ``"{name} must be in [lo, hi], got {value!r}"`` (``(lo, hi]``
for a range open at the bottom) and ``"{name} must be an integer in [lo, hi], got
{value!r}"``. Numpy and math only, so that the plants can use it (they run without
gymnasium).

The callers differ in what they take for a number, and each keeps its own rule (``types``,
``allow_bool``): the checks were written once per process before they were shared, and a
value that one process accepts must not start failing there.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "REAL_TYPES",
    "PY_NUMBER_TYPES",
    "INTEGER_TYPES",
    "check_range",
    "check_integer",
    "check_below",
]

#: Python's and numpy's real scalar types: what a parameter check accepts by default.
REAL_TYPES: tuple[type, ...] = (int, float, np.integer, np.floating)
#: Python's own number types only (a numpy scalar other than ``np.float64`` is refused).
PY_NUMBER_TYPES: tuple[type, ...] = (int, float)
#: Python's and numpy's integer types: what an integer check accepts by default.
INTEGER_TYPES: tuple[type, ...] = (int, np.integer)


def check_range(
    name: str,
    value,
    lo: float,
    hi: float,
    *,
    lo_open: bool = False,
    types: tuple[type, ...] = REAL_TYPES,
    allow_bool: bool = False,
    bound_format: str = "",
) -> float:
    """``value`` as a float if it is a finite number in ``[lo, hi]``, else ``ValueError``.

    Parameters
    ----------
    name : str
        The parameter's name, for the message.
    value
        The value to check.
    lo, hi : float
        The allowed range; ``hi`` is always included.
    lo_open : bool
        Exclude ``lo`` too: the range is ``(lo, hi]``.
    types : tuple of type
        What counts as a number (``REAL_TYPES`` or ``PY_NUMBER_TYPES``).
    allow_bool : bool
        Take ``True`` and ``False`` as the numbers 1 and 0 (``bool`` is an ``int``);
        refused by default.
    bound_format : str
        Format spec of the bounds in the message (``""``: as ``str`` prints them, ``"g"``).

    Returns
    -------
    float
        ``float(value)``.

    Raises
    ------
    ValueError
        ``"{name} must be in [lo, hi], got {value!r}"``, with ``(`` for an open bottom.

    >>> check_range("gain", 2, 0.0, 10.0, lo_open=True)
    2.0
    >>> check_range("gain", 0.0, 0.0, 10.0, lo_open=True)
    Traceback (most recent call last):
    ...
    ValueError: gain must be in (0.0, 10.0], got 0.0
    """
    ok = (
        isinstance(value, types)
        and (allow_bool or not isinstance(value, bool))
        and math.isfinite(value)
    )
    if not (ok and (value > lo if lo_open else value >= lo) and value <= hi):
        left = "(" if lo_open else "["
        raise ValueError(
            f"{name} must be in {left}{lo:{bound_format}}, {hi:{bound_format}}], got {value!r}"
        )
    return float(value)


def check_integer(
    name: str,
    value,
    lo: int,
    hi: int,
    *,
    types: tuple[type, ...] = INTEGER_TYPES,
    allow_bool: bool = False,
) -> int:
    """``value`` if it is an integer in ``[lo, hi]``, else ``ValueError``.

    ``types`` and ``allow_bool`` as in :func:`check_range`; the message is
    ``"{name} must be an integer in [lo, hi], got {value!r}"``.

    >>> check_integer("substeps", 1.0, 1, 100)
    Traceback (most recent call last):
    ...
    ValueError: substeps must be an integer in [1, 100], got 1.0
    """
    if (
        not isinstance(value, types)
        or (not allow_bool and isinstance(value, bool))
        or not lo <= value <= hi
    ):
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return value


def check_below(
    name: str, value: float, bound_name: str, bound: float, why: str, *, strict: bool = True
) -> None:
    """``ValueError`` unless ``value < bound`` (``<=`` with ``strict=False``): a check across
    two fields, whose message names both, their values and why they must be ordered.

    >>> check_below("force_limit_N", 4000.0, "breakage_force_N", 3000.0, "the tool breaks first")
    Traceback (most recent call last):
    ...
    ValueError: force_limit_N (4000) must be below breakage_force_N (3000): the tool breaks first
    """
    if value < bound or (not strict and value == bound):
        return
    word = "below" if strict else "at most"
    raise ValueError(f"{name} ({value:.6g}) must be {word} {bound_name} ({bound:.6g}): {why}")
