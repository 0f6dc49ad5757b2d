"""``replace`` of the parameter sets checks only what changed, and checks it as a new set
would: the same copy as ``dataclasses.replace``, the same errors."""

import dataclasses
import math

import numpy as np
import pytest

from machining_envs.drilling.plant import DrillingParams
from machining_envs.milling.plant import MillingParams
from machining_envs.turning.plant import TurningParams

PARAMS = [TurningParams(), MillingParams(), DrillingParams()]


def _numeric_fields(p):
    return [
        f.name
        for f in dataclasses.fields(p)
        if isinstance(getattr(p, f.name), float) and math.isfinite(getattr(p, f.name))
    ]


@pytest.mark.parametrize("p", PARAMS, ids=lambda p: type(p).__name__)
def test_every_field_is_checked_by_replace_and_by_the_constructor(p):
    for f in dataclasses.fields(p):
        for bad in (float("nan"), -1e30):
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
