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

import dataclasses
import math
import operator
from typing import Self

import numpy as np

__all__ = [
    "fields_of",
    "REAL_TYPES",
    "PY_NUMBER_TYPES",
    "INTEGER_TYPES",
    "is_real",
    "is_integer",
    "is_seed",
    "check_range",
    "check_integer",
    "check_below",
    "check_overload_ratio",
    "check_instance",
    "ranged",
    "ranged_int",
    "one_of",
    "check_ranged_fields",
    "resolve_settings",
    "CheckedParams",
    "checked_params",
]

#: Python's and numpy's real scalar types: what a parameter check accepts by default.
REAL_TYPES: tuple[type, ...] = (int, float, np.integer, np.floating)
#: Python's own number types only (a numpy scalar other than ``np.float64`` is refused).
PY_NUMBER_TYPES: tuple[type, ...] = (int, float)
#: Python's and numpy's integer types: what an integer check accepts by default.
INTEGER_TYPES: tuple[type, ...] = (int, np.integer)


def is_real(value, types: tuple[type, ...] = REAL_TYPES) -> bool:
    """Whether ``value`` is a real number of ``types`` (``REAL_TYPES``, or
    ``PY_NUMBER_TYPES`` where numpy scalars are refused) and not a bool (finite or not:
    the caller says which range it takes)."""
    return isinstance(value, types) and not isinstance(value, bool)


def is_integer(value) -> bool:
    """Whether ``value`` is an integer of ``INTEGER_TYPES`` and not a bool."""
    return isinstance(value, INTEGER_TYPES) and not isinstance(value, bool)


def is_seed(value) -> bool:
    """Whether ``value`` can seed numpy's generators: an integer in ``[0, 2**32)``."""
    return is_integer(value) and 0 <= value < 2**32


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


def check_overload_ratio(value) -> None:
    """``ValueError`` unless ``value`` (a scenario's ``overload_ratio``, a multiple of its
    limit) is a Python number in ``(1, 10]``.

    >>> check_overload_ratio(1.0)
    Traceback (most recent call last):
    ...
    ValueError: overload_ratio must be in (1, 10], got 1.0
    """
    check_range(
        "overload_ratio", value, 1.0, 10.0, lo_open=True, types=PY_NUMBER_TYPES, bound_format="g"
    )


def check_instance(name: str, value, cls: type, *, optional: bool = False) -> None:
    """``ValueError`` unless ``value`` is a ``cls`` (or None, where ``optional``):
    ``"{name} must be a {cls} [or None], got {its type}"``.

    >>> check_instance("profile", 1.0, dict)
    Traceback (most recent call last):
    ...
    ValueError: profile must be a dict, got float
    """
    if isinstance(value, cls) or (optional and value is None):
        return
    article = "an" if cls.__name__[0] in "AEIOU" else "a"
    either = " or None" if optional else ""
    raise ValueError(f"{name} must be {article} {cls.__name__}{either}, got {type(value).__name__}")


def check_field(name: str, value, rule: tuple) -> None:
    """Check a parameter-set field by its ``rule``: ``(lo, hi, lo_open)`` for a number
    (:func:`check_range`), ``("int", lo, hi)`` for an integer (:func:`check_integer`),
    ``("choice", allowed, how the message names them)`` for a choice."""
    if rule[0] == "int":
        check_integer(name, value, rule[1], rule[2])
    elif rule[0] == "choice":
        if value not in rule[1]:
            raise ValueError(f"{name} must be {rule[2]}, got {value!r}")
    else:
        check_range(name, value, rule[0], rule[1], lo_open=rule[2])


def check_fields(params, rules: dict) -> None:
    """Check each field of the parameter set ``params`` that ``rules`` names, in the order
    of ``rules``, by its rule (:func:`check_field`): what a parameter dataclass's
    ``__post_init__`` checks field by field."""
    for name, rule in rules.items():
        check_field(name, getattr(params, name), rule)


def ranged(lo: float, hi: float, default=dataclasses.MISSING, *, lo_open: bool = False):
    """A dataclass field (``default``, or none) whose value must be a number in
    ``[lo, hi]`` (``(lo, hi]`` where ``lo_open``): the range stands with the field, and
    :func:`check_ranged_fields` checks every field declared so (a scenario's
    ``__post_init__``).

    >>> @dataclasses.dataclass(frozen=True)
    ... class Cut:
    ...     noise_scale: float = ranged(0.0, 10.0, default=1.0)
    ...     def __post_init__(self):
    ...         check_ranged_fields(self)
    >>> Cut(11.0)
    Traceback (most recent call last):
    ...
    ValueError: noise_scale must be in [0.0, 10.0], got 11.0
    """
    return dataclasses.field(default=default, metadata={"rule": (lo, hi, lo_open)})


def ranged_int(lo: int, hi: int, default=dataclasses.MISSING):
    """A dataclass field (``default``, or none) whose value must be an integer in
    ``[lo, hi]`` (rule of :func:`check_integer`), declared as :func:`ranged` declares a
    number's range."""
    return dataclasses.field(default=default, metadata={"rule": ("int", lo, hi)})


def one_of(allowed: tuple, wording: str, default=dataclasses.MISSING):
    """A dataclass field (``default``, or none) whose value must be one of ``allowed``
    (the message says it must be ``wording``), declared as :func:`ranged` declares a
    number's range."""
    return dataclasses.field(default=default, metadata={"rule": ("choice", allowed, wording)})


def check_ranged_fields(obj) -> None:
    """Check every field of the dataclass instance ``obj`` declared with :func:`ranged`,
    in the order of the fields, by its range (:func:`check_field`)."""
    for f in dataclasses.fields(obj):
        rule = f.metadata.get("rule")
        if rule is not None:
            check_field(f.name, getattr(obj, f.name), rule)


def replace_checked(params, changes: dict, rules: dict, cls: type):
    """A copy of the frozen dataclass ``params`` (of exactly ``cls``) with ``changes``, of
    which only the changed fields are checked, by ``rules`` (field -> rule of
    :func:`check_field`; the others were checked when ``params`` was made). Envs draw a
    cut's true parameters at every reset, and checking every field again was a good part
    of a reset's cost. A field given the value it has (same type, equal) is no change. Any
    other change ``rules`` does not cover (an unknown name, a subclass, a field checked
    against another) goes through ``dataclasses.replace`` and the whole ``__post_init__``."""
    if type(params) is not cls:
        return dataclasses.replace(params, **changes)
    old = params.__dict__
    changes = {
        k: v
        for k, v in changes.items()
        if not (k in old and type(v) is type(old[k]) and v == old[k])
    }
    if not changes.keys() <= rules.keys():
        return dataclasses.replace(params, **changes)
    for name, value in changes.items():
        rule = rules[name]
        if type(value) is float and type(rule[0]) is not str:  # a number's rule: the common
            lo, hi, lo_open = rule  # case checked here, with check_range's comparisons
            if (value > lo if lo_open else value >= lo) and value <= hi and value - value == 0:
                continue
        check_field(name, value, rule)
    new = object.__new__(cls)
    new.__dict__.update(params.__dict__)
    new.__dict__.update(changes)
    return new


class CheckedParams:
    """Base of the plants' frozen parameter dataclasses: each field declared with a range
    (:func:`ranged`, :func:`ranged_int`, :func:`one_of`) is checked when an instance is
    made (``__post_init__``), and :meth:`replace` checks only the fields it changes
    (:func:`replace_checked`).

    A subclass is decorated with :func:`checked_params` (above ``@dataclass``), which
    collects its fields' rules; one with checks across fields extends ``__post_init__``
    (calling this one first). A subclass of a parameter class that is not decorated
    itself is checked by its base's rules, and its :meth:`replace` goes through
    ``dataclasses.replace`` and its whole ``__post_init__``."""

    _field_rules: dict = {}
    _replace_rules: dict = {}
    _checked_class: type | None = None

    def __post_init__(self) -> None:
        check_fields(self, self._field_rules)

    def replace(self, **changes) -> Self:
        """A copy with fields changed; unknown names raise ``TypeError``. Only the changed
        fields are checked (:func:`replace_checked`): envs draw a cut's true parameters at
        every reset."""
        return replace_checked(self, changes, self._replace_rules, self._checked_class)


def checked_params(*, across: tuple[str, ...] = ()):
    """Class decorator of a :class:`CheckedParams` dataclass (above ``@dataclass``): the
    rules of its fields, in their order, are the ones it checks. :meth:`~CheckedParams.replace`
    checks a changed field alone, but for those named in ``across`` (checked against
    another field by ``__post_init__``), whose change checks the whole set again."""

    def collect(cls: type) -> type:
        fields = dataclasses.fields(cls)
        cls._field_rules = {f.name: f.metadata["rule"] for f in fields if "rule" in f.metadata}
        cls._replace_rules = {k: v for k, v in cls._field_rules.items() if k not in across}
        cls._checked_class = cls
        return cls

    return collect


def fields_of(cls: type, source):
    """The named tuple ``cls`` of ``source``'s attributes (fields or properties) named as
    its fields: the part of a parameter set a cache is keyed by (a key class's
    ``of = classmethod(fields_of)``).

    >>> from typing import NamedTuple
    >>> class Key(NamedTuple):
    ...     real: float
    ...     imag: float
    >>> fields_of(Key, 2 + 3j)
    Key(real=2.0, imag=3.0)
    """
    return cls._make(operator.attrgetter(*cls._fields)(source))


def drawn_instance(cls: type, fields: dict):
    """An instance of the frozen dataclass ``cls`` with ``fields`` (every field, by name),
    made without running ``__post_init__``.

    For the scenario factories, which draw every field of a scenario at each reset from
    ranges they checked once, when they were made (by building the scenarios at the ranges'
    ends through the public constructor): checking every drawn value again was a good part
    of a vector env's reset. Anything else builds its instances the public way."""
    new = object.__new__(cls)
    new.__dict__.update(fields)
    return new


def resolve_settings(name: str, value, cls: type):
    """A settings dataclass ``cls`` from ``value``: an instance, or a dict of its fields
    (``TypeError`` naming unknown keys, as ``"{name}: unknown settings [...]; allowed
    [...]"``); ``ValueError`` for anything else. ``None`` is the caller's to handle."""
    if isinstance(value, dict):
        known = [f.name for f in dataclasses.fields(cls)]
        bad = sorted(set(value) - set(known))
        if bad:
            raise TypeError(f"{name}: unknown settings {bad}; allowed {known}")
        value = cls(**value)
    if not isinstance(value, cls):
        article = "an" if cls.__name__[:1] in "AEIOU" else "a"
        raise ValueError(
            f"{name} must be {article} {cls.__name__}, a dict or None, got {type(value).__name__}"
        )
    return value
