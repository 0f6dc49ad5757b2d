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


@pytest.mark.parametrize("fast", [True, False])
def test_discretisation_is_the_zoh_of_core_to_the_last_bit(fast, monkeypatch):
    """An axis's ZOH (scipy's compiled Pade step without ``expm``'s overhead, a reset
    pays it) is ``core.lti.zoh``'s to the last bit: over the inertias the scenarios draw
    and far beyond (where ``expm`` scales and runs itself), and without the fast path."""
    from machining_envs.contouring import plant as plant_module
    from machining_envs.core.lti import zoh

    if not fast:  # else the path the module chose at import (expm where no Pade step)
        monkeypatch.setattr(plant_module, "_PADE", None)
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
            a, g = p.velocity_pole(axis), -p.mm_per_rad / p.inertia_kgm2(axis)
            phi, gam = plant_module._axis_zoh.__wrapped__(a, g, p.sample_time_s)
            ref_phi, ref_gam = zoh(*p.continuous_axis(axis), p.sample_time_s)
            assert phi.tobytes() == ref_phi.tobytes() and gam.tobytes() == ref_gam.tobytes()
            assert not phi.flags.writeable and not gam.flags.writeable
            blocks.append((a, g, p.sample_time_s, ref_phi, ref_gam))
    # Many axes at once (a vector env's lanes at a reset), those expm scales among them.
    a, g, dt = (np.array([b[i] for b in blocks]) for i in range(3))
    e = plant_module.axes_zoh(a, g, dt)
    for i, (*_, ref_phi, ref_gam) in enumerate(blocks):
        assert e[i, :2, :2].tobytes() == ref_phi.tobytes()
        assert e[i, :2, 2:].tobytes() == ref_gam.tobytes()
