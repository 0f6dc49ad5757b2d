"""Controllers that declare their keyword settings once (``SETTINGS``): the constructors
keep their keywords, positional order and defaults, check every setting, and ``TUNABLE``
follows the table in the order tuning draws it."""

from __future__ import annotations

import inspect

import gymnasium as gym
import pytest

from agents.base import Setting
from agents.contouring import ContourAFC, LookAheadFeed
from agents.drilling import (
    PD,
    PeckDrilling,
    SlidingMode,
    TorquePeck,
    VoltagePeck,
    VoltageTorquePeck,
)
from agents.milling import FixedGainIntegral, IntegralACC, MillingConstantFeed
from agents.turning import ConstantFeed, DelayAwarePI, FixedGainPI, TurningIO, VariableGainPI
from tests.helpers import TURNING

#: The constructors' signatures as they were written out by hand before the tables.
SIGNATURES = {
    FixedGainPI: "(io, kh=0.02, kgh=1.9, setpoint=1.0)",
    ConstantFeed: "(io, feed_mm_per_rev=None, design_depth_mm=3.0, setpoint=1.0)",
    VariableGainPI: "(io, k=0.5, kgh=1.9, design_depth_mm=2.0, min_command_fraction=0.01, "
    "min_force_fraction=0.05, setpoint=1.0)",
    DelayAwarePI: "(io, delay_steps=2, phase_margin_deg=45.0, kgh=1.9, setpoint=1.0, "
    "design_depth_mm=2.0, min_command_fraction=0.01, min_force_fraction=0.05)",
    FixedGainIntegral: "(io, kc=0.2, setpoint=1.0)",
    IntegralACC: "(io, k=None, c1=0.001, c2=0.001, kc_design=0.2, design_depth_mm=1.0, "
    "min_torque_fraction=0.2, setpoint=1.0)",
    MillingConstantFeed: "(io, feed_mm_per_min=None, design_depth_mm=3.0, setpoint=1.0)",
    PD: "(io, loop_gain=3.0, derivative_time_s=0.02, derivative_filter=5.0, "
    "min_voltage=None, setpoint=1.0)",
    SlidingMode: "(io, lam=12.0, epsilon=0.03, near_rate=35.0, far_ratio=0.25, "
    "k4_filter_s=0.02, min_voltage=None, engage_fraction=0.3, setpoint=1.0)",
    PeckDrilling: "(io, peck_diameters=1.0, clearance_mm=0.1, approach_gap_mm=0.05, "
    "rapid_mm_s=None, feed_scale=1.0, voltage=None)",
    TorquePeck: "(io, torque_share=0.8, feed_scale=0.7, peck_diameters=100.0, "
    "min_peck_diameters=0.25, clearance_mm=0.1, approach_gap_mm=0.05, rapid_mm_s=None, "
    "voltage=None)",
    VoltagePeck: "(io, peck_diameters=1.0, clearance_mm=0.1, approach_gap_mm=0.05, "
    "rapid_mm_s=None, feed_scale=1.0, voltage=None)",
    VoltageTorquePeck: "(io, torque_share=0.8, feed_scale=0.7, peck_diameters=100.0, "
    "min_peck_diameters=0.25, clearance_mm=0.1, approach_gap_mm=0.05, rapid_mm_s=None, "
    "voltage=None)",
    LookAheadFeed: "(override_max: 'float', centripetal_mm_s2=1000.0, "
    "tangential_mm_s2=1000.0, override_cap=1.0)",
    ContourAFC: "(override_max: 'float', reference=0.7, gain=0.2, rise=0.01, fmin=0.2, "
    "fmax=1.2, fent=0.9, centripetal_mm_s2=1000.0, tangential_mm_s2=1000.0, "
    "override_cap=1.0)",
}


@pytest.mark.parametrize("cls", list(SIGNATURES), ids=lambda c: c.__name__)
def test_the_signature_lists_every_setting_with_its_default(cls):
    assert str(inspect.signature(cls)) == SIGNATURES[cls]
    assert set(cls.TUNABLE) <= set(cls.SETTINGS)


def test_tunable_keeps_the_order_tuning_draws_it_in():
    """Optuna draws the parameters in ``TUNABLE``'s order: a table may not reorder it."""
    assert list(DelayAwarePI.TUNABLE) == ["phase_margin_deg", "kgh", "setpoint"]
    assert list(TorquePeck.TUNABLE) == ["torque_share", "feed_scale"]
    assert list(VoltagePeck.TUNABLE) == ["voltage", "peck_diameters", "feed_scale"]
    assert list(VoltageTorquePeck.TUNABLE) == ["voltage", "torque_share", "feed_scale"]
    assert list(IntegralACC.TUNABLE) == ["kc_design", "c1", "setpoint"]
    assert list(ContourAFC.TUNABLE) == [
        *LookAheadFeed.TUNABLE,
        "reference",
        "gain",
        "rise",
    ]


def test_settings_bind_by_position_or_name_and_are_checked():
    io = TurningIO.from_env(gym.make(TURNING))
    by_position = VariableGainPI(io, 0.4, 2.0, 3.0)
    by_name = VariableGainPI(io, design_depth_mm=3.0, kgh=2.0, k=0.4)
    for name in VariableGainPI.SETTINGS:
        assert getattr(by_position, name) == getattr(by_name, name)
    assert by_name.min_command == 0.01 * io.command_max
    with pytest.raises(ValueError, match=r"kgh must be in \(0, 100\], got 0"):
        VariableGainPI(io, kgh=0)
    with pytest.raises(TypeError, match="VariableGainPI.*unexpected keyword argument 'kp'"):
        VariableGainPI(io, kp=0.4)
    with pytest.raises(TypeError, match="VariableGainPI.*multiple values for argument 'k'"):
        VariableGainPI(io, 0.4, k=0.4)


def test_a_setting_checks_its_range_and_lets_a_none_default_through():
    assert Setting(0.5, hi=1.0).check("f", 1) == 1.0
    assert Setting(None, hi=1.0).check("f", None) is None
    assert Setting(0.5, hi=None).check("f", "as given") == "as given"
    with pytest.raises(ValueError, match=r"f must be in \[0.1, 1\], got 0.05"):
        Setting(0.5, lo=0.1, hi=1.0, lo_open=False).check("f", 0.05)
    with pytest.raises(ValueError, match="f must be in"):
        Setting(0.5, hi=1.0).check("f", None)
