"""What a cache hands to every caller is read-only (``core.compiled.kernels.read_only``): a caller that
wrote to a cached discretisation or cutting model would change every env built on it."""

import numpy as np
import pytest

from machining_envs.core.compiled.kernels import read_only


def test_read_only_freezes_in_place_and_returns_what_it_was_given():
    a, b = np.zeros(3), np.ones((2, 2))
    assert read_only(a) is a and not a.flags.writeable
    out = read_only(b, np.arange(2.0))
    assert isinstance(out, tuple) and out[0] is b and not any(x.flags.writeable for x in out)


def _milling():
    from machining_envs.milling.plant import MillingParams, _servo_matrix, _ServoKey

    return [_servo_matrix(_ServoKey.of(MillingParams()))]


def _drilling():
    from machining_envs.drilling.plant import DrillingParams, _valve_matrices

    p = DrillingParams()
    c = p.coefficients(1.0)
    half, step = _valve_matrices(
        p.valve_natural_freq_rad_s, p.valve_damping, p.k1, p.sample_time_s, p.substeps
    )
    return [c.engage_depth_mm, c.engage_torque, c.engage_thrust, half, step]


def _contouring():
    from machining_envs.contouring.plant import ContouringParams, _axis_zoh
    from machining_envs.contouring.servo import servo_design

    p = ContouringParams()
    tables = list(_axis_zoh(1.0, 2.0, 1e-3))
    for kind in ("pi", "hinf"):
        d = servo_design(kind, p, "x")
        tables += [d.a, d.b, d.c, d.d, *d.continuous]
    return tables


def _turning_agents():
    from machining_envs.turning.plant import TurningParams, unit_plant_coefficients

    return [unit_plant_coefficients(TurningParams(), 405.0)]


@pytest.mark.parametrize("tables", [_milling, _drilling, _contouring, _turning_agents])
def test_cached_tables_refuse_writes(tables):
    got = tables()
    assert got
    for table in got:
        assert isinstance(table, np.ndarray)
        with pytest.raises(ValueError, match="read-only"):
            table[(0,) * table.ndim] = 1.0
