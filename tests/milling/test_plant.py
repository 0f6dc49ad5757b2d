"""The milling plant against Park & Yoon's equations, seed 002's model and independent solutions."""

import math

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from machining_envs.core.workpieces import DepthProfile
from machining_envs.milling.plant import (
    KGF,
    MillingLanes,
    MillingParams,
    MillingPlant,
    immersion_angles,
    mean_forces,
    mean_torque_average_force,
)

PROFILE = DepthProfile((0.0, 0.6, 1.4, 30.0), (1.0, 1.0, 3.0), (1.0, 2.5, 3.0))


def _ode_reference(p: MillingParams, rpm: float, profile, commands):
    """Servo (eq. 7), position, torque law (eq. 8 or seed 002) and lag (eq. 10) as one ODE,
    integrated sample by sample (the command is held over each)."""
    wn, z = p.servo_natural_freq_rad_s, p.servo_damping
    tau = p.process_lag_s(rpm)
    ts = p.sample_time_s
    edges, d0, d1 = profile.edges_mm, profile.start_depths_mm, profile.end_depths_mm
    c = float(p.torque_gain(1.0))
    e_f, e_d = p.torque_feed_exponent, (p.depth_exponent if p.force_model == "power_law" else 1.0)

    def depth(x):
        for a, b, da, db in zip(edges[:-1], edges[1:], d0, d1, strict=True):
            if a <= x < b:
                return da + (db - da) * (x - a) / (b - a)
        return 0.0

    out = []
    s = [0.0, 0.0, 0.0, 0.0]
    for k, u in enumerate(commands):

        def rhs(t, s, u=u):
            vf, dvf, x, torque = s
            ft = max(vf, 0.0) * 60.0 / (rpm * p.n_teeth)
            static = c * depth(x) ** e_d * ft**e_f
            return [
                dvf,
                -(wn**2) * vf - 2 * z * wn * dvf + wn**2 * p.servo_gain * u,
                vf,
                (static - torque) / tau,
            ]

        sol = solve_ivp(rhs, (k * ts, (k + 1) * ts), s, rtol=1e-10, atol=1e-10, max_step=2e-3)
        s = list(sol.y[:, -1])
        out.append(s)
    return np.array(out).T


def _plant_run(p, rpm, profile, commands):
    plant = MillingPlant(p, rpm, profile)
    out = [plant.step(u) for u in commands]
    return out


@pytest.mark.parametrize("force_model", ["power_law", "average_force"])
def test_plant_matches_the_ode_of_eq_5_to_10(force_model):
    p = MillingParams(force_model=force_model)
    rng = np.random.default_rng(1)
    commands = rng.uniform(5.0, 60.0, size=40)
    ref = _ode_reference(p, 400.0, PROFILE, commands)
    steps = _plant_run(p, 400.0, PROFILE, commands)
    vf = np.array([s.feed_velocity_mm_s for s in steps])
    x = np.array([s.position_mm for s in steps])
    torque = np.array([s.torque_Nmm for s in steps])
    # The servo and position are discretised exactly: agreement to the ODE's tolerance.
    np.testing.assert_allclose(vf, ref[0], atol=1e-7)
    np.testing.assert_allclose(x, ref[2], atol=1e-7)
    assert x[-1] > PROFILE.edges_mm[2]  # the cut crosses the taper and the step
    # The lag's input is the torque law at the 10 ms sub-steps, linear in between, and the
    # profile's depth step falls inside a sub-step: agreement to 0.2 % of the torque's
    # scale (we see 0.06-0.09 %).
    scale = np.max(np.abs(ref[3]))
    assert np.max(np.abs(torque - ref[3])) < 2e-3 * scale


def test_torque_error_shrinks_with_substeps():
    p = MillingParams()
    commands = np.full(30, 20.0)
    ref = _ode_reference(p, 400.0, PROFILE, commands)[3]
    errs = []
    for m in (4, 16, 64):
        steps = _plant_run(p.replace(substeps=m), 400.0, PROFILE, commands)
        errs.append(np.max(np.abs(np.array([s.torque_Nmm for s in steps]) - ref)))
    assert errs[0] > errs[1] > errs[2]


def test_steady_state_follows_eq_6_and_8():
    """Held command: Vf = Kn U (eq. 5), f = 60 Vf / N (eq. 6), T = Ks d^l ft^m D (eq. 8)."""
    p = MillingParams()
    prof = DepthProfile.steps((2.0,), 100.0)
    plant = MillingPlant(p, 400.0, prof)
    for _ in range(60):
        s = plant.step(20.0)
    vf = 0.02 * 20.0
    assert s.feed_velocity_mm_s == pytest.approx(vf, rel=1e-9)
    assert s.feed_mm_per_rev == pytest.approx(60 * vf / 400.0, rel=1e-9)
    ft = 60 * vf / 400.0 / 4
    expected_kgfmm = 118.0 * 2.0**0.4236 * ft**0.3999 * 16.0
    assert s.torque_Nmm == pytest.approx(KGF * expected_kgfmm, rel=1e-9)
    assert s.measured_counts == pytest.approx(p.sensor_gain * s.torque_Nmm, rel=1e-12)
    assert s.mean_feed_mm_per_rev == pytest.approx(s.feed_mm_per_rev, rel=1e-9)


def test_process_gain_is_the_steady_ratio_tc_over_u():
    p = MillingParams()
    for d in (1.0, 2.0, 3.0):
        u = float(p.command_for_torque(p.torque_limit_Nmm, d))
        plant = MillingPlant(p, 400.0, DepthProfile.steps((d,), 100.0))
        for _ in range(80):
            s = plant.step(u)
        assert s.torque_Nmm == pytest.approx(p.torque_limit_Nmm, rel=1e-9)
        assert s.measured_counts / u == pytest.approx(float(p.process_gain(d)), rel=1e-9)
    # Deeper cut, smaller command, larger gain: the source of Fig. 5's trend.
    gains = [float(p.process_gain(d)) for d in (1.0, 2.0, 3.0)]
    assert gains[0] < gains[1] < gains[2]


def test_finish_time_and_segments():
    p = MillingParams()
    prof = DepthProfile.steps((1.0, 2.0), 1.0)
    plant = MillingPlant(p, 400.0, prof)
    segs, finish = [], None
    while finish is None:
        s = plant.step(60.0)
        segs.append(s.segment)
        finish = s.finish_time_s
    assert segs[0] == 0 and 1 in segs
    # 2 mm at a feed velocity near 1.2 mm/s after the servo's rise: about 1.9 s.
    assert 1.6 < finish < 2.2
    assert plant.t_s - p.sample_time_s < finish <= plant.t_s


def test_average_force_torque_is_the_tangential_force_times_radius():
    """Mean of R * sum of tangential tooth forces over a revolution, integrated numerically."""
    kt, nf, r, a, ft = 700.0, 2, 6.0, 10.0, 0.05
    for dr in (0.5, 3.0, 6.0, 11.0):
        for mode in ("up", "down"):
            st, ex = immersion_angles(dr, r, mode)
            integral, _ = quad(lambda phi: kt * a * ft * math.sin(phi) * r, float(st), float(ex))
            numeric = nf * integral / (2 * math.pi)
            closed = mean_torque_average_force(dr, a, ft, kt=kt, n_flutes=nf)
            assert closed == pytest.approx(numeric, rel=1e-9)
    p = MillingParams.ahn_choi_al6061()
    assert float(p.steady_torque_Nmm(2.0, 0.05)) == pytest.approx(p.torque_limit_Nmm, rel=1e-3)


@pytest.mark.parametrize("mode", ["up", "down"])
def test_mean_forces_match_numerical_integration(mode):
    """Seed 002 eq. (1) (Altintas' form) against the mean of the instantaneous tooth forces
    (tangential and radial on each tooth resolved in x, y; axial along -z)."""
    kt, kr, ka, nf, r, a, ft, dr = 700.0, 210.0, 140.0, 2, 6.0, 10.0, 0.05, 4.0
    st, ex = (float(v) for v in immersion_angles(dr, r, mode))

    def component(i):
        def integrand(phi):
            h = ft * math.sin(phi)
            f_t, f_r, f_a = kt * a * h, kr * a * h, ka * a * h
            fx = -f_t * math.cos(phi) - f_r * math.sin(phi)
            fy = f_t * math.sin(phi) - f_r * math.cos(phi)
            return (fx, fy, -f_a)[i]  # axial force on the workpiece along -z (seed 002)

        return nf * quad(integrand, st, ex)[0] / (2 * math.pi)

    numeric = [component(i) for i in range(3)]
    closed = mean_forces(dr, a, ft, kt=kt, kr=kr, ka=ka, n_flutes=nf, tool_radius_mm=r, mode=mode)
    np.testing.assert_allclose(closed, numeric, rtol=1e-9, atol=1e-9)


def test_sm45c_average_force_set_matches_the_power_law_at_the_design_centre():
    p = MillingParams()
    pl = float(p.steady_torque_Nmm(2.0, 0.0625))
    af = float(p.replace(force_model="average_force").steady_torque_Nmm(2.0, 0.0625))
    assert af == pytest.approx(pl, rel=2e-3)


def test_bad_parameters_raise_naming_the_field():
    with pytest.raises(ValueError, match="feed_exponent"):
        MillingParams(feed_exponent=-0.4)
    with pytest.raises(ValueError, match="force_model"):
        MillingParams(force_model="linear")
    with pytest.raises(ValueError, match="n_teeth"):
        MillingParams(n_teeth=2.5)
    with pytest.raises(ValueError, match="milling_mode"):
        MillingParams(milling_mode="climb")
    with pytest.raises(ValueError, match="sensor_gain"):
        MillingParams(sensor_gain=math.nan)
    with pytest.raises(TypeError):
        MillingParams().replace(servo_gian=0.02)
    with pytest.raises(ValueError, match="spindle_rpm"):
        MillingPlant(MillingParams(), 1e6, PROFILE)
    with pytest.raises(ValueError, match="radial depth"):
        MillingPlant(MillingParams(tool_diameter_mm=4.0), 400.0, DepthProfile.steps((3.0, 5.0)))
    with pytest.raises(ValueError, match="radial_depth_mm"):
        immersion_angles(13.0, 6.0)


def test_a_lane_of_a_batch_is_the_one_lane_plant():
    """MillingPlant (one lane) and the lanes of one MillingLanes with different true
    parameters, spindle speeds and workpieces give the same signals to the last bit."""
    rng = np.random.default_rng(3)
    nominal = MillingParams()
    cuts = [
        (nominal, 400.0, PROFILE),
        (nominal.replace(force_model="average_force"), 520.0, DepthProfile.steps((2.0, 0.5), 3.0)),
        (nominal.replace(feed_exponent=0.5, torque_coefficient_kgfmm=90.0), 333.0, PROFILE),
        (nominal, 610.0, DepthProfile.taper(0.5, 3.0, 4.0)),
    ]
    lanes = MillingLanes(nominal, len(cuts))
    plants = []
    for k, (p, rpm, prof) in enumerate(cuts):
        lanes.start(k, p, rpm, prof)
        plants.append(MillingPlant(p, rpm, prof))
    for _ in range(150):
        u = rng.uniform(-5.0, 160.0, size=len(cuts))
        noise = rng.standard_normal(len(cuts))
        lanes.step(u, noise)
        for k, plant in enumerate(plants):
            s = plant.step(float(u[k]), float(noise[k]))
            row = (
                s.torque_Nmm,
                s.peak_torque_Nmm,
                s.measured_counts,
                s.feed_velocity_mm_s,
                s.feed_mm_per_rev,
                s.mean_feed_mm_per_rev,
                s.position_mm,
                s.depth_mm,
            )
            assert np.array(row).tobytes() == lanes.out[k].tobytes()
            assert s.segment == lanes.out_segment[k]
            fin = lanes.out_finish[k]
            assert (s.finish_time_s is None) == np.isnan(fin)
            assert s.finish_time_s is None or s.finish_time_s == fin
    assert np.any(lanes.finished) and not np.all(lanes.finished)


def test_lanes_refuse_another_servo():
    lanes = MillingLanes(MillingParams(), 2)
    with pytest.raises(ValueError, match="servo"):
        lanes.start(1, MillingParams(servo_gain=0.025), 400.0, PROFILE)


def test_replace_checks_the_changed_fields():
    p = MillingParams()
    with pytest.raises(ValueError, match="feed_exponent"):
        p.replace(feed_exponent=2.5)
    with pytest.raises(ValueError, match="force_model"):
        p.replace(force_model="linear")
    q = p.replace(feed_exponent=0.5, noise_std_Nmm=1.0)
    assert q == MillingParams(feed_exponent=0.5, noise_std_Nmm=1.0)
    assert hash(q) == hash(MillingParams(feed_exponent=0.5, noise_std_Nmm=1.0))
    assert p.feed_exponent == 0.3999  # the original is unchanged
