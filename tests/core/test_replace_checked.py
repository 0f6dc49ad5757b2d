"""``replace`` of the parameter sets checks only what changed, and checks it as a new set
would: the same copy as ``dataclasses.replace``, the same errors."""

import dataclasses
import math

import numpy as np
import pytest

from machining_envs.contouring.plant import ContouringParams
from machining_envs.drilling.plant import DrillingParams
from machining_envs.milling.plant import MillingParams
from machining_envs.turning.plant import TurningParams

PARAMS = [TurningParams(), MillingParams(), DrillingParams(), ContouringParams()]


def _numeric_fields(p):
    return [
        f.name
        for f in dataclasses.fields(p)
        if isinstance(getattr(p, f.name), float) and math.isfinite(getattr(p, f.name))
    ]


@pytest.mark.parametrize("p", PARAMS, ids=lambda p: type(p).__name__)
def test_every_field_is_checked_by_replace_and_by_the_constructor(p):
    for f in dataclasses.fields(p):
        for bad in (float("nan"), float("-inf"), -1e30):  # +inf: a spindle without a limit
            with pytest.raises(ValueError, match=f.name):
                dataclasses.replace(p, **{f.name: bad})
            with pytest.raises(ValueError, match=f.name):
                p.replace(**{f.name: bad})


@pytest.mark.parametrize("p", PARAMS, ids=lambda p: type(p).__name__)
def test_replace_is_dataclasses_replace(p):
    rng = np.random.default_rng(3)
    names = _numeric_fields(p)
    for _ in range(200):
        picked = rng.choice(names, size=int(rng.integers(1, 6)), replace=False)
        changes = {n: getattr(p, n) * float(rng.uniform(0.9, 1.1)) for n in picked}
        try:
            ref = dataclasses.replace(p, **changes)
        except ValueError as err:
            with pytest.raises(ValueError, match=str(err).split(" ")[0]):
                p.replace(**changes)
            continue
        new = p.replace(**changes)
        assert type(new) is type(p) and new == ref and hash(new) == hash(ref)
        assert all(getattr(new, n) == v for n, v in changes.items())
    with pytest.raises(TypeError):
        p.replace(no_such_field=1.0)


def test_a_change_checked_against_another_field_checks_the_whole_set():
    p = DrillingParams()
    with pytest.raises(ValueError, match="nominal_voltage"):
        p.replace(voltage_max=0.5 * p.nominal_voltage)
    with pytest.raises(ValueError, match="feed_velocity_mm_s"):
        p.replace(feed_speed_max_mm_s=0.5 * p.feed_velocity_mm_s)


def test_replace_checked_applies_each_rule_exactly():
    """The rules' bounds, as check_range applies them: an open bottom excludes its bound, a
    closed one and the top include theirs; ints and non-finite values are refused or taken
    by the same rules."""
    from machining_envs.core.checks import replace_checked

    @dataclasses.dataclass(frozen=True)
    class P:
        a: float = 1.0
        b: float = 1.0

    rules = {"a": (0.0, 2.0, True), "b": (0.0, 2.0, False)}
    assert replace_checked(P(), {"a": 2.0, "b": 0.0}, rules, P) == P(2.0, 0.0)
    assert replace_checked(P(), {"a": 1e-300, "b": 2}, rules, P) == P(1e-300, 2)
    for name, bad in (("a", 0.0), ("a", 2.0000001), ("b", -1e-300), ("b", math.inf)):
        with pytest.raises(ValueError, match=f"{name} must be in"):
            replace_checked(P(), {name: bad}, rules, P)


def test_check_fields_checks_each_named_field_in_the_order_of_its_rules():
    from types import SimpleNamespace

    from machining_envs.core.checks import check_fields

    rules = {"gain": (0.0, 10.0, True), "steps": ("int", 1, 5), "mode": ("choice", ("a",), "'a'")}
    check_fields(SimpleNamespace(gain=1.0, steps=2, mode="a", other=-1.0), rules)
    with pytest.raises(ValueError, match="gain"):  # the first bad field in the rules' order
        check_fields(SimpleNamespace(gain=0.0, steps=9, mode="a"), rules)
    with pytest.raises(ValueError, match="steps"):
        check_fields(SimpleNamespace(gain=1.0, steps=9, mode="a"), rules)
    with pytest.raises(ValueError, match="mode must be 'a'"):
        check_fields(SimpleNamespace(gain=1.0, steps=2, mode="b"), rules)


def test_checked_params_collects_the_rules_declared_with_the_fields():
    from machining_envs.core.checks import (
        CheckedParams,
        checked_params,
        one_of,
        ranged,
        ranged_int,
    )

    @checked_params(across=("b",))
    @dataclasses.dataclass(frozen=True)
    class P(CheckedParams):
        a: float = ranged(0.0, 10.0, default=1.0, lo_open=True)
        free: float = -5.0
        n: int = ranged_int(1, 9, default=2)
        mode: str = one_of(("x", "y"), "'x' or 'y'", default="x")
        b: float = ranged(0.0, 10.0, default=2.0)

        def __post_init__(self) -> None:
            super().__post_init__()
            if self.b < self.a:
                raise ValueError("b must not be below a")

    assert list(P._field_rules) == ["a", "n", "mode", "b"]  # the fields' order
    assert list(P._replace_rules) == ["a", "n", "mode"]
    for bad, match in (
        ({"a": 0.0}, "a must be in \\(0.0"),
        ({"n": 0}, "n must be an integer"),
        ({"mode": "z"}, "mode must be 'x' or 'y'"),
    ):
        with pytest.raises(ValueError, match=match):
            P(**bad)
        with pytest.raises(ValueError, match=match):
            P().replace(**bad)
    assert P(free=1e300).free == 1e300  # no rule: not checked
    with pytest.raises(ValueError, match="below a"):
        P().replace(b=0.5)  # across: the whole __post_init__


def test_a_subclass_of_a_params_class_replaces_through_its_own_post_init():
    """A user's subclass with its own checks: ``replace`` must not skip them (the fast path
    is for the class that stated the rules)."""

    @dataclasses.dataclass(frozen=True)
    class Strict(TurningParams):
        def __post_init__(self) -> None:
            super().__post_init__()
            if self.servo_gain > 1.0:
                raise ValueError("servo_gain of this machine must be at most 1")

    p = Strict()
    with pytest.raises(ValueError, match="at most 1"):
        p.replace(servo_gain=2.0)
    with pytest.raises(ValueError, match="servo_gain must be in"):
        p.replace(servo_gain=-1.0)
    assert type(p.replace(servo_gain=0.5)) is Strict
