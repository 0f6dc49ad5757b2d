"""Scenario fields declared with ``ranged``: each is checked by its own range, by name."""

import dataclasses

import pytest

from machining_envs.core.workpieces import DepthProfile
from machining_envs.drilling.scenarios import DrillingScenario
from machining_envs.milling.scenarios import MillingScenario
from machining_envs.turning.scenarios import TurningScenario

_PROFILE = DepthProfile.steps((1.0,), 10.0)
_VALID = {
    TurningScenario: {"name": "x", "profile": _PROFILE, "spindle_rpm": 400.0},
    MillingScenario: {"name": "x", "profile": _PROFILE},
    DrillingScenario: {"name": "x", "diameter_mm": 0.6},
}
_CASES = [
    (cls, f.name, f.metadata["rule"])
    for cls in _VALID
    for f in dataclasses.fields(cls)
    if "rule" in f.metadata
]


def test_the_scenarios_declare_their_ranges():
    names = {(cls.__name__, name) for cls, name, _ in _CASES}
    assert ("TurningScenario", "spindle_rpm") in names
    assert ("MillingScenario", "torque_limit_scale") in names
    assert ("DrillingScenario", "diameter_mm") in names
    assert len(_CASES) == 6 + 6 + 8


@pytest.mark.parametrize(("cls", "name", "rule"), _CASES, ids=lambda c: getattr(c, "__name__", c))
def test_a_ranged_field_is_checked_by_its_range(cls, name, rule):
    lo, hi, _ = rule
    fields = _VALID[cls]
    assert getattr(cls(**{**fields, name: lo}), name) == lo
    assert getattr(cls(**{**fields, name: hi}), name) == hi
    for bad in (hi * 1.5 + 1.0, lo - 1.0, float("nan")):
        with pytest.raises(ValueError, match=rf"^{name} must be in \["):
            cls(**{**fields, name: bad})
