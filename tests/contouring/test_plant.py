"""The contouring plant against the paper's G(s), an ODE solver and closed forms."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from machining_envs.contouring.plant import ContouringParams, ContouringPlant

P = ContouringParams()


def test_paper_table_1_and_derived_quantities():
    assert P.velocity_loop_gain == 1.3 and P.torque_constant_Nm_per_A == 1.2054
    assert P.inertia_x_kgm2 == pytest.approx(2.29 * 0.00376)
    assert P.inertia_y_kgm2 == pytest.approx(3.04 * 0.00376)
    # a = Ksp Kt / J: 182.0 /s (X), 137.1 /s (Y).
    assert P.velocity_pole("x") == pytest.approx(1.3 * 1.2054 / (2.29 * 0.00376))
    assert P.velocity_pole("x") == pytest.approx(182.0, abs=0.05)
    assert P.velocity_pole("y") == pytest.approx(137.1, abs=0.05)
    num, den = P.transfer_function("x")
    assert num == [pytest.approx(1.3 * 1.2054)]
    assert den == [pytest.approx(2.29 * 0.00376), pytest.approx(1.3 * 1.2054), 0.0]
    assert P.command_max_mm_s == pytest.approx(2000 / 60 * 10)
    assert P.sample_time_s <= 1e-3  # a servo rate of 1 kHz or faster


def test_zoh_step_matches_an_ode_solver_under_random_inputs():
    rng = np.random.default_rng(0)
    plant = ContouringPlant(P)
    plant.reset(3.0, -2.0)
    n = 150
    u = rng.uniform(-100, 100, (n, 2))
    tl = rng.uniform(-2, 2, (n, 2))
    ours = []
    for k in range(n):
        s = plant.step(u[k, 0], u[k, 1], tl[k, 0], tl[k, 1])
        ours.append((s.x_mm, s.vx_mm_s, s.y_mm, s.vy_mm_s))
    ours = np.array(ours)
    ts = P.sample_time_s
    for i, axis in enumerate("xy"):
        a, b = P.continuous_axis(axis)
        z = np.array([3.0 if axis == "x" else -2.0, 0.0])
        for k in range(n):
            w = np.array([u[k, i], tl[k, i]])
            sol = solve_ivp(
                lambda t, z, a=a, b=b, w=w: a @ z + b @ w,
                (0, ts),
                z,
                rtol=1e-12,
                atol=1e-12,
                method="DOP853",
            )
            z = sol.y[:, -1]
            np.testing.assert_allclose(ours[k, 2 * i : 2 * i + 2], z, rtol=1e-9, atol=1e-9)


def test_velocity_loop_is_first_order_and_load_torque_droops_it():
    plant = ContouringPlant(P)
    plant.reset()
    a = P.velocity_pole("x")
    u = 50.0
    for k in range(1, 201):
        s = plant.step(u, 0.0)
        assert s.vx_mm_s == pytest.approx(u * (1 - math.exp(-a * k * P.sample_time_s)), rel=1e-10)
    # Steady velocity under a load torque T: u - (lead / 2 pi) T / (Ksp Kt).
    plant.reset()
    for _ in range(2000):
        s = plant.step(u, 0.0, 1.0, 0.0)
    droop = P.mm_per_rad * 1.0 / P.loop_gain_Nms
    assert s.vx_mm_s == pytest.approx(u - droop, rel=1e-9)
    assert droop == pytest.approx(1.016, abs=1e-3)  # mm/s per N m with the 10 mm lead
    # ... and the motor then delivers exactly the load torque.
    assert s.torque_x_Nm == pytest.approx(1.0, abs=1e-6)


def test_reported_torque_is_the_mean_over_the_period():
    plant = ContouringPlant(P)
    plant.reset()
    u, ts, a = 80.0, P.sample_time_s, P.velocity_pole("y")
    s = plant.step(0.0, u)
    # From rest: mean velocity over the period u (1 - (1 - e^{-a Ts}) / (a Ts)); the motor
    # torque is Ksp Kt (w_ref - w), w = v 2 pi / lead.
    mean_v = u * (1 - (1 - math.exp(-a * ts)) / (a * ts))
    expected = P.loop_gain_Nms * (u - mean_v) / P.mm_per_rad
    assert s.torque_y_Nm == pytest.approx(expected, rel=1e-9)
    assert s.torque_x_Nm == 0.0


def test_commands_clip_at_the_motor_top_speed_and_batch_agrees():
    plant = ContouringPlant(P)
    plant.reset()
    for _ in range(5000):
        s = plant.step(1e6, -1e6)
    assert s.vx_mm_s == pytest.approx(P.command_max_mm_s)
    assert s.vy_mm_s == pytest.approx(-P.command_max_mm_s)
    rng = np.random.default_rng(1)
    z = rng.normal(size=(6, 4))
    w = rng.uniform(-500, 500, (6, 4))
    w[:, 1::2] = rng.uniform(-3, 3, (6, 2))
    batch = plant.step_batch(z, w)
    for i in range(6):
        plant.z = z[i].copy()  # the plant keeps its state as a float array
        s = plant.step(w[i, 0], w[i, 2], w[i, 1], w[i, 3])
        np.testing.assert_allclose(
            [s.x_mm, s.vx_mm_s, s.y_mm, s.vy_mm_s], batch[i], rtol=1e-12, atol=1e-12
        )


def test_bad_parameters_raise_naming_the_field():
    with pytest.raises(ValueError, match="inertia_x_kgm2"):
        ContouringParams(inertia_x_kgm2=-1.0)
    with pytest.raises(ValueError, match="sample_time_s"):
        ContouringParams(sample_time_s=0.1)
    with pytest.raises(ValueError, match="screw_lead_mm"):
        ContouringParams(screw_lead_mm=math.nan)
    with pytest.raises(TypeError):
        P.replace(inertia_z_kgm2=1.0)
    with pytest.raises(ValueError, match="axis"):
        P.velocity_pole("z")
    with pytest.raises(ValueError, match="params"):
        ContouringPlant("not params")


def _exact_axis_zoh(a: float, g: float, dt: float) -> np.ndarray:
    """``[Phi, Gamma]`` of one axis, ``(2, 4)``, from the closed form in 40-digit decimal
    arithmetic on the given floats: the exact discretisation, independent of the code and
    of scipy (``(1 - E) / q`` and ``(q - 1 + E) / q^2`` cancel nothing at this precision)."""
    import decimal

    ctx = decimal.Context(prec=40)
    a_, g_, h = (decimal.Decimal(x) for x in (a, g, dt))
    q = ctx.multiply(a_, h)
    e = ctx.exp(-q)
    phi1 = ctx.divide(1 - e, q)
    phi2 = ctx.divide(q - 1 + e, ctx.multiply(q, q))
    rows = [[1, h * phi1, h * q * phi2, g_ * h * h * phi2], [0, e, q * phi1, g_ * h * phi1]]
    return np.array([[float(ctx.plus(x)) for x in row] for row in rows])


def test_discretisation_is_exact_to_a_few_units_in_the_last_place():
    """An axis's ZOH (the closed form a reset pays, compiled) is the exact discretisation
    to a few units in the last place, over the inertias the scenarios draw and far beyond
    (gains over seven decades, sample times over four): each entry within ``(16 + q)``
    units of its size, ``q = a dt`` (the rounding of ``a dt`` itself moves ``exp(-q)`` by
    ``q`` units). Over the scenarios' inertias it is also scipy's ``expm`` (``core.lti.zoh``)
    to 1e-13, which is that far from the exact values itself (64 units measured, against
    40-digit arithmetic); beyond, where ``expm`` scales and squares, scipy's numbers are
    the less exact ones (3 600 units at ``q = 4``). Many axes at once give the numbers of
    each alone, to the last bit."""
    from machining_envs.contouring import plant as plant_module
    from machining_envs.core.lti import zoh

    eps = np.finfo(float).eps
    rng = np.random.default_rng(0)
    blocks = []
    for k in range(400):
        p = P.replace(
            inertia_x_kgm2=P.inertia_x_kgm2 * math.exp(rng.uniform(-0.7, 0.7)),
            inertia_y_kgm2=P.inertia_y_kgm2 * math.exp(rng.uniform(-0.7, 0.7)),
        )
        if k >= 300:
            p = p.replace(
                velocity_loop_gain=10.0 ** rng.uniform(-3.0, 4.0),
                sample_time_s=10.0 ** rng.uniform(-6.0, -2.0),
            )
        for axis in "xy":
            a, g, dt = p.velocity_pole(axis), -p.mm_per_rad / p.inertia_kgm2(axis), p.sample_time_s
            phi, gam = plant_module._axis_zoh.__wrapped__(a, g, dt)
            assert not phi.flags.writeable and not gam.flags.writeable
            got = np.hstack([phi, gam])
            exact = _exact_axis_zoh(a, g, dt)
            np.testing.assert_array_equal(got[exact == 0], 0.0)
            assert np.all(np.abs(got - exact) <= (16.0 + a * dt) * eps * np.abs(exact)), (a, dt)
            if k < 300:
                ref = np.hstack(zoh(*p.continuous_axis(axis), dt))
                np.testing.assert_allclose(got, ref, rtol=1e-13, atol=0.0)
            blocks.append((a, g, dt, got))
    # Many axes at once (a vector env's lanes at a reset): each alone's numbers.
    a, g, dt = (np.array([b[i] for b in blocks]) for i in range(3))
    e = plant_module.axes_zoh(a, g, dt)
    for i, (*_, got) in enumerate(blocks):
        assert e[i, :2].tobytes() == got.tobytes()
        np.testing.assert_array_equal(e[i, 2:], np.eye(4)[2:])
    # a = 0 (no velocity loop, a gain too small to count): the double integrator's ZOH
    e = plant_module.axes_zoh(np.array([0.0]), np.array([-3.0]), np.array([0.5]))[0]
    np.testing.assert_array_equal(e[:2], [[1.0, 0.5, 0.0, -3.0 * 0.125], [0.0, 1.0, 0.0, -1.5]])
    # the two ways phi2 is computed (series below q = 1, the closed form above) meet
    q = np.array([1.0 - 2 * eps, 1.0, 1.0 + 2 * eps])
    e = plant_module.axes_zoh(q, -q, np.ones(3))
    np.testing.assert_allclose(e[:, 0, 2], e[1, 0, 2], rtol=8 * eps, atol=0.0)
