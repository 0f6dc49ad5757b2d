"""The micro-drilling plant against the paper's equations and independent computations."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from machining_envs.drilling.plant import (
    DrillingParams,
    DrillingPlant,
    _filter_weights,
)

P = DrillingParams()
TWO_PI = 2.0 * math.pi
QUIET = dict(chip_fluctuation=0.0, cutting_fluctuation=0.0)


def _run(plant, voltages, feed=0.32):
    out = []
    for u in voltages:
        out.append(plant.step(u, feed))
    return out


def test_free_spindle_settles_at_545_hz_at_nominal_voltage():
    """Table 1: initial spindle frequency 545 Hz; from rest-ish (300 Hz) it gets there."""
    assert P.free_speed_hz(P.nominal_voltage) == pytest.approx(545.0, abs=0.01)
    assert P.spindle_time_constant_s(545.0) == pytest.approx(0.25, rel=1e-4)
    plant = DrillingPlant(P, 0.8, 8.0, start_position_mm=-1.0)
    plant.reset(speed_hz=300.0)
    steps = _run(plant, [P.nominal_voltage] * 500, feed=0.0)  # 5 s, never touching
    assert steps[-1].speed_hz == pytest.approx(545.0, abs=0.05)
    assert all(not s.cutting and s.torque_Nmm == 0.0 for s in steps)
    # Full voltage: the top speed the controllers can use (about 3.1x the nominal).
    top = P.free_speed_hz(P.nominal_voltage) * 2 ** (1 / 0.608)
    assert P.free_speed_hz(P.voltage_max) == pytest.approx(top, rel=1e-12)


def test_valve_is_the_exact_second_order_step_response():
    """Eq. (17): x_v of a 1 V step against the closed-form underdamped response."""
    p = P.replace(spindle_inertia_Nmm_s2=1.0)
    plant = DrillingPlant(p, 0.8, 8.0, start_position_mm=-1.0)
    plant.reset(voltage=0.0, speed_hz=0.0)
    wn, z, k = p.valve_natural_freq_rad_s, p.valve_damping, p.valve_static_gain_per_V
    wd = wn * math.sqrt(1 - z * z)
    for n in range(1, 40):
        plant.step(1.0, 0.0)
        t = n * p.sample_time_s
        exact = k * (
            1
            - math.exp(-z * wn * t)
            * (math.cos(wd * t) + z / math.sqrt(1 - z * z) * math.sin(wd * t))
        )
        assert plant.x1 == pytest.approx(exact, abs=1e-12)


def _sine_run(params, substeps, n=300):
    """Sine voltage (like the paper's Fig. 7 test), drilling a 0.8 mm hole."""
    plant = DrillingPlant(params.replace(substeps=substeps), 0.8, 8.0)
    out = []
    for k in range(n):
        u = 5.0 + 2.0 * math.sin(TWO_PI * 2.0 * k * params.sample_time_s)
        s = plant.step(u, 0.32)
        out.append((s.speed_hz, s.torque_Nmm, s.thrust_N, s.measured_torque_Nmm))
    return np.array(out)


def test_rk4_step_size_against_finer_substeps():
    """The default RK4 step (h = 5 ms) against h / 32.

    A sine voltage at 2 Hz (like the paper's Fig. 7 test) swings the spindle by about
    +-140 Hz while the drill enters and cuts, so both the nonlinear air friction and the
    drilling load are exercised. Speed, torque and thrust at the samples agree within 1e-6
    of their range, and the error shrinks like h^4 when the step is halved. The measured
    torque also carries the sensor filter's piecewise-linear input between sub-steps: within
    1e-3, forty times below the sensor's noise.
    """
    p = P.replace(**QUIET)
    ref = _sine_run(p, 64)
    coarse = _sine_run(p, p.substeps)
    half = _sine_run(p, 2 * p.substeps)
    assert np.ptp(ref[:, 0]) > 250.0
    err = np.max(np.abs(coarse - ref) / np.abs(ref).max(axis=0), axis=0)
    assert np.all(err[:3] < 1e-6), err
    assert err[3] < 1e-3, err
    err_half = np.max(np.abs(half - ref)[:, 0])
    err_full = np.max(np.abs(coarse - ref)[:, 0])
    assert err_full / err_half > 8.0  # fourth order: 16 in the limit


def test_spindle_against_an_independent_ode_solution():
    """Valve and spindle (no cut) against scipy's adaptive solver on eq. (17)-(19)."""
    p = P
    wn, z = p.valve_natural_freq_rad_s, p.valve_damping
    k1, k2, k3, n = p.k1, p.spindle_drive_gain, p.spindle_friction, p.spindle_friction_exponent
    volts = [5.0 + 2.0 * math.sin(TWO_PI * 2.0 * k * p.sample_time_s) for k in range(200)]
    plant = DrillingPlant(p, 0.8, 8.0, start_position_mm=-1.0)
    x = np.array([plant.x1, plant.x2, plant.omega])
    for u in volts:
        s = plant.step(u, 0.0)

        def f(t, y, u=u):
            return [y[1], k1 * u - 2 * z * wn * y[1] - wn**2 * y[0], k2 * y[0] - k3 * y[2] ** n]

        sol = solve_ivp(f, (0.0, p.sample_time_s), x, rtol=1e-12, atol=1e-12, method="DOP853")
        x = sol.y[:, -1]
        assert s.speed_hz == pytest.approx(x[2] / TWO_PI, rel=1e-7)
        assert plant.x1 == pytest.approx(x[0], rel=1e-10, abs=1e-12)


def test_loaded_spindle_settles_where_drive_meets_friction_and_drilling_torque():
    """Steady cut: k2 x_v = k3 w^n + k4 / (I w), solved independently by brentq."""
    p = P.replace(chip_friction=0.0, **QUIET)
    d, v = 0.8, 0.32
    plant = DrillingPlant(p, d, 8.0)
    s = _run(plant, [p.nominal_voltage] * 400)[-1]  # 4 s: engaged after 0.75 s
    k4 = TWO_PI * p.coefficients(d).torque_per_feed * v
    drive = p.spindle_drive_gain * p.valve_static_gain_per_V * p.nominal_voltage
    w = brentq(
        lambda w: drive - p.spindle_friction * w**0.608 - k4 / (p.spindle_inertia_Nmm_s2 * w),
        100.0,
        1e4,
        xtol=1e-12,
    )
    assert s.speed_hz == pytest.approx(w / TWO_PI, rel=1e-6)
    assert s.torque_Nmm == pytest.approx(k4 / w, rel=1e-6)  # eq. (20): T = k4 / omega
    # The load slows the spindle below the free 545 Hz (their Fig. 8(c)).
    assert 500.0 < s.speed_hz < 545.0
    # Measured torque without noise: the sensor's filter has unit DC gain.
    assert s.measured_torque_Nmm == pytest.approx(s.torque_Nmm, rel=1e-6)


def test_torque_is_k4_over_speed_and_linear_in_feed():
    """Eq. (20) and Fig. 9-10: at a fixed feed torque falls as 1/speed; linear in feed."""
    p = P.replace(chip_friction=0.0, **QUIET)
    products = []
    for volts in (4.0, 5.0, 7.0):
        plant = DrillingPlant(p, 0.7, 8.0)
        plant.reset(voltage=volts)
        s = _run(plant, [volts] * 300)[-1]
        products.append(s.torque_Nmm * TWO_PI * s.speed_hz)
    np.testing.assert_allclose(products, products[0], rtol=1e-9)
    t1 = p.chip_free_torque_Nmm(0.7, 750.0, 0.16)
    t2 = p.chip_free_torque_Nmm(0.7, 750.0, 0.32)
    assert t2 == pytest.approx(2.0 * t1, rel=1e-12)


def test_cutting_model_facts():
    c = P.coefficients(0.8)
    # §3.2: the chisel edge makes 30-40 % of the thrust.
    assert 0.30 <= c.chisel_thrust_share <= 0.40
    # Most of the torque comes from the lips (large radius), most chisel force is thrust.
    assert c.lip_torque_per_feed > 10 * c.chisel_torque_per_feed
    # Geometry scales with D: torque per feed ~ D^2, thrust per feed ~ D (Fig. 11's trend),
    # up to the chisel's feed angle and indentation radius, which do not scale.
    c5 = P.coefficients(0.5)
    assert c5.torque_per_feed / c.torque_per_feed == pytest.approx((0.5 / 0.8) ** 2, rel=1e-2)
    assert c5.thrust_per_feed / c.thrust_per_feed == pytest.approx(0.5 / 0.8, rel=1e-2)
    # Indentation (eq. 14) is negligible at micro-drilling feeds.
    f = 0.32 / 545.0
    assert c.indentation_per_feed2 * f**2 < 1e-3 * c.thrust_per_feed * f
    # Engagement: nothing before the point touches, all once the lips are in.
    plant = DrillingPlant(P, 0.8, 8.0)
    assert plant.engagement(0.0) == (0.0, 0.0)
    full = 0.4 / math.tan(math.radians(59.0))
    assert c.full_engagement_mm == pytest.approx(full)
    assert plant.engagement(full) == (1.0, 1.0)
    shares = [plant.engagement(z)[0] for z in np.linspace(0.001, full, 50)]
    assert np.all(np.diff(shares) >= 0) and 0 < shares[0] < 0.1


def test_nominal_torque_and_breakage_per_diameter():
    tb = [P.breakage_torque_Nmm(d) for d in (0.5, 0.6, 0.7, 0.8)]
    np.testing.assert_allclose(tb, [0.625, 1.08, 1.715, 2.56])
    t0 = [P.nominal_torque_Nmm(d) for d in (0.5, 0.6, 0.7, 0.8)]
    ratio = np.array(tb) / np.array(t0)
    assert np.all(np.diff(ratio) > 0)  # small drills are closer to breaking
    assert 3.5 < ratio[0] < ratio[-1] < 7.0
    assert t0[-1] == pytest.approx(0.4126, abs=1e-3)


def test_chip_friction_grows_with_depth_and_a_retract_clears_it():
    """Fig. 12: torque rises with depth; leaving the hole (a peck) resets the chips."""
    p = P.replace(**QUIET)
    d, v = 0.6, 0.32
    plant = DrillingPlant(p, d, 20.0)
    kt = TWO_PI * p.coefficients(d).torque_per_feed * v
    steps = _run(plant, [5.0] * 1500)  # 4.8 mm = 8 D
    s = steps[-1]
    g_mid = p.chip_friction_ratio(s.packed_mm - 0.5 * v * p.sample_time_s, d)
    assert s.torque_Nmm * TWO_PI * s.speed_hz == pytest.approx(kt * (1 + g_mid), rel=1e-9)
    early = steps[200].torque_Nmm
    assert s.torque_Nmm > 1.5 * early
    # Retract out of the hole at 3 mm/s, come back and cut again.
    while plant.position_mm > -0.05:
        plant.step(5.0, -3.0)
    assert plant.packed_mm == 0.0
    while plant.position_mm < plant.depth_mm - 0.01:
        plant.step(5.0, 3.0)
    for _ in range(50):
        s = plant.step(5.0, v)
    g = p.chip_friction_ratio(s.packed_mm - 0.5 * v * p.sample_time_s, d)
    assert g < 0.02  # 0.15 mm of chips since the peck, against 3.2 mm before
    assert s.torque_Nmm * TWO_PI * s.speed_hz == pytest.approx(kt * (1 + g), rel=1e-9)


def test_sensor_filter_is_exact_for_a_ramp():
    """The 50 Hz first-order filter over one sample, against the ODE solved by scipy."""
    a, w = _filter_weights(50.0, 0.01, 2)
    assert a + sum(w) == pytest.approx(1.0, abs=1e-15)  # unit DC gain
    assert a == pytest.approx(math.exp(-TWO_PI * 50.0 * 0.01))
    x = [0.3, 1.1, 0.7]  # input at 0, 5 and 10 ms, linear in between
    tau = 1.0 / (TWO_PI * 50.0)

    def f(t, y):
        xt = np.interp(t, [0.0, 0.005, 0.01], x)
        return [(xt - y[0]) / tau]

    sol = solve_ivp(f, (0.0, 0.01), [0.2], rtol=1e-12, atol=1e-14, max_step=1e-4)
    assert a * 0.2 + sum(wj * xj for wj, xj in zip(w, x, strict=True)) == pytest.approx(
        sol.y[0, -1], abs=1e-9
    )


def test_parameter_validation_names_the_field():
    with pytest.raises(ValueError, match="valve_damping"):
        DrillingParams(valve_damping=0.0)
    with pytest.raises(ValueError, match="spindle_friction_exponent"):
        DrillingParams(spindle_friction_exponent=2.0)
    with pytest.raises(ValueError, match="substeps"):
        DrillingParams(substeps=0)
    with pytest.raises(ValueError, match="substeps"):
        DrillingParams(substeps=2.5)
    with pytest.raises(ValueError, match="shear_stress_MPa"):
        DrillingParams(shear_stress_MPa=float("nan"))
    with pytest.raises(TypeError):
        P.replace(shear_stres_MPa=1.0)
    with pytest.raises(ValueError, match="diameter_mm"):
        DrillingPlant(P, 2.0, 8.0)
    with pytest.raises(ValueError, match="target_depth_mm"):
        DrillingPlant(P, 0.8, -1.0)
    with pytest.raises(ValueError, match="diameter_mm"):
        P.coefficients(0.0)
