"""The servo designs of ``machining_envs.contouring.servo`` (PI, H-infinity 2-DOF) and the
block loop ContouringFeed-v0 runs them in."""

import math

import gymnasium as gym
import numpy as np
import pytest

import machining_envs.contouring.servo as servo
from agents import HInf2DOF
from machining_envs.contouring.plant import ContouringParams
from machining_envs.contouring.servo import ServoLoop, closed_loop, hinf_2dof_design, pi_design
from tests.helpers import CONTOURING, servo_step_response

P = ContouringParams()
M0 = 500.0


def _step(params, design, t_end=0.1):
    """Unit step response of the discrete closed loop (position after each period)."""
    n = int(round(t_end / params.sample_time_s))
    y = servo_step_response(params, design, n)[0]
    return (np.arange(n) + 1) * params.sample_time_s, y


def _settling(t, y, band=0.02):
    bad = np.flatnonzero(np.abs(y - 1.0) > band)
    return t[bad[-1] + 1]


@pytest.mark.parametrize("axis", ["x", "y"])
def test_hinf_gamma_is_finite_and_reported(axis):
    d = hinf_2dof_design(P, axis)
    assert math.isfinite(d.gamma) and 1.0 < d.gamma < 20.0
    assert d.details["epsilon"] == pytest.approx(1.0 / d.gamma)
    print(f"H-inf 2-DOF gamma, axis {axis}: {d.gamma:.4f}")
    agent = HInf2DOF.from_env(gym.make(CONTOURING))
    assert agent.gammas[0 if axis == "x" else 1] == d.gamma


@pytest.mark.parametrize("axis", ["x", "y"])
@pytest.mark.parametrize("scale", [1.0, 0.7, 1.4])
def test_hinf_closed_loop_stable_at_the_servo_rate(axis, scale):
    """Spectral radius < 1 with the ZOH plant at 5 kHz: nominal, and with the inertia of the
    held-out scenarios' extremes (the design never sees them)."""
    d = hinf_2dof_design(P, axis)
    truth = P.replace(**{f"inertia_{axis}_kgm2": P.inertia_kgm2(axis) * scale})
    a = closed_loop(truth, d, axis)[0]
    assert np.max(np.abs(np.linalg.eigvals(a))) < 1.0


@pytest.mark.parametrize("axis", ["x", "y"])
def test_hinf_step_response_follows_m0(axis):
    """No overshoot beyond 2 %, exact steady state (the prefilter), settling (2 %) within
    25 % of M0's 7.8 ms, and the frequency response within 1 % of M0's over the contouring
    band (up to 50 rad/s: 50 mm/s on a 1 mm radius)."""
    d = hinf_2dof_design(P, axis)
    t, y = _step(P, d)
    assert y.max() - 1.0 <= 0.02
    assert y[-1] == pytest.approx(1.0, abs=1e-9)
    ts_m0 = math.log(50.0) / M0  # 1 - exp(-500 t) = 0.98: 7.8 ms
    assert abs(_settling(t, y) - ts_m0) <= 0.25 * ts_m0
    a, b, cy, _, _ = closed_loop(P, d)
    ts = P.sample_time_s
    for w in (1.0, 5.0, 20.0, 50.0):
        z = np.exp(1j * w * ts)
        t_jw = (cy @ np.linalg.solve(z * np.eye(a.shape[0]) - a, b[:, :1]))[0, 0]
        assert abs(t_jw) == pytest.approx(abs(M0 / (1j * w + M0)), rel=0.01)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_pi_design_is_critically_damped_without_overshoot(axis):
    d = pi_design(P, axis)
    a_pole = P.velocity_pole(axis)
    kp, ki = d.details["kp_per_s"], d.details["ki_per_s2"]
    # Characteristic polynomial s^3 + a s^2 + a Kp s + a Ki: a triple pole at -a/3.
    roots = np.roots([1.0, a_pole, a_pole * kp, a_pole * ki])
    np.testing.assert_allclose(roots.real, -a_pole / 3.0, rtol=1e-3)
    assert np.max(np.abs(roots.imag)) < 1e-3 * a_pole
    t, y = _step(P, d, t_end=0.5)
    assert y.max() - 1.0 <= 1e-3  # no overshoot (to the discretisation's 0.1 %)
    assert y[-1] == pytest.approx(1.0, abs=1e-6)
    # H-infinity is the faster loop (Fig. 4).
    th, yh = _step(P, hinf_2dof_design(P, axis))
    assert _settling(th, yh) < 0.2 * _settling(t, y)


def test_block_loop_matches_period_by_period_simulation():
    """ContouringFeed-v0's block update equals the plant stepped period by period under
    the agent's controller (same designs, same commands), with and without clipping."""
    from machining_envs.contouring.plant import ContouringPlant

    designs = tuple(hinf_2dof_design(P, ax) for ax in "xy")
    truth = P.replace(inertia_y_kgm2=P.inertia_y_kgm2 * 1.2)
    loop = ServoLoop(truth, designs, 50)
    rng = np.random.default_rng(0)
    for amplitude in (0.05, 5.0):  # 5 mm jumps ask for more than the 333 mm/s limit
        state = loop.initial_state()
        plant = ContouringPlant(truth)
        xi = [np.zeros(d.n_states) for d in designs]
        ref = np.cumsum(rng.normal(0, amplitude, (50, 2)), axis=0)
        load = np.repeat(rng.uniform(-1, 1, (1, 2)), 50, axis=0)
        pos, vel, cmd, torque, clipped = loop.run(state, ref, load)
        assert clipped == (amplitude > 1.0)
        for j in range(50):
            u = []
            for k, d in enumerate(designs):
                inp = np.array([ref[j, k], plant.z[2 * k]])
                u.append(float(d.c[0] @ xi[k] + d.d[0] @ inp))
                xi[k] = d.a @ xi[k] + d.b @ inp
            s = plant.step(u[0], u[1], load[j, 0], load[j, 1])
            np.testing.assert_allclose([s.x_mm, s.y_mm], pos[j], rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(
                [s.torque_x_Nm, s.torque_y_Nm], torque[j], rtol=1e-7, atol=1e-7
            )
            umax = P.command_max_mm_s
            np.testing.assert_allclose(np.clip(u, -umax, umax), cmd[j], rtol=1e-9, atol=1e-9)


def test_servo_design_by_name():
    assert servo.servo_design("pi", P, "y").kind == "pi"
    assert servo.servo_design("hinf", P, "y").kind == "hinf"
    with pytest.raises(ValueError, match="servo"):
        servo.servo_design("lqr", P, "x")


def test_lane_rows_hold_the_arrays_the_kernel_reads():
    """A lane's row of ``ServoLanes.buf`` carved by ``lane_loops`` (what the kernel reads)
    gives the arrays ``ServoLanes`` names and writes."""
    from machining_envs.contouring.servo import _LANE_ARRAYS, ServoLanes, lane_loops

    lanes = ServoLanes(tuple(pi_design(P, ax) for ax in "xy"), 50, 3)
    lanes.buf[:] = np.arange(lanes.buf.size).reshape(lanes.buf.shape)
    carved = lane_loops(lanes.buf[1])
    assert len(carved) == len(_LANE_ARRAYS)
    for (name, shape), view in zip(_LANE_ARRAYS, carved, strict=True):
        assert view.size == math.prod(shape)
        named = np.asarray(getattr(lanes, name)[1]).reshape(view.shape)
        np.testing.assert_array_equal(view, named, err_msg=name)


@pytest.mark.parametrize("design", [pi_design, hinf_2dof_design])
def test_lanes_started_together_hold_each_plants_closed_loop(design):
    """``ServoLanes.start_lanes`` (every lane's axes discretised at once, their loops closed
    in one compiled call) writes, for each lane on its own plant, ``closed_loop``'s
    matrices (numpy's products) to the last bit, the torque factor and the command limit,
    and copies them into each lane's place of its group's table (``groups``, as
    ``run_lanes`` reads it); the lanes it is not given keep theirs (zeros in the tables)."""
    from machining_envs.contouring.servo import ServoLanes

    designs = tuple(design(P, ax) for ax in "xy")
    lanes = ServoLanes(designs, 50, 10)
    lanes.buf[:] = 7.0
    truths = [
        P.replace(inertia_x_kgm2=P.inertia_x_kgm2 * sx, inertia_y_kgm2=P.inertia_y_kgm2 * sy)
        for sx, sy in ((0.8, 1.25), (1.0, 1.0), (1.13, 0.91))
    ]
    truths[2] = truths[2].replace(
        velocity_loop_gain=P.velocity_loop_gain * 1.7, motor_max_rpm=900.0
    )
    started = np.array([3, 0, 9])  # lane 9: the second group's second place
    lanes.start_lanes(started, truths)
    ns = lanes.n_states_axis
    for lane, truth in zip(started.tolist(), truths, strict=True):
        for k, (axis, d) in enumerate(zip("xy", designs, strict=True)):
            a, b, _, cu, du = closed_loop(truth, d, axis)
            np.testing.assert_array_equal(lanes.ac[lane, k][:ns, :ns], a.T)
            np.testing.assert_array_equal(lanes.bc[lane, k][:, :ns], b.T)
            np.testing.assert_array_equal(lanes.cu[lane, k][:ns], cu[0])
            assert lanes.du[lane, k] == du[0, 0]
            np.testing.assert_array_equal(lanes.gu[lane, k], truth.discrete_axis(axis)[1][:, 0])
            tq = truth.inertia_kgm2(axis) / (truth.mm_per_rad * truth.sample_time_s)
            assert lanes.tq[lane, k] == tq
        assert lanes.umax[lane] == truth.command_max_mm_s
    assert (lanes.buf[[1, 2, 8]] == 7.0).all()
    assert lanes.groups.shape == (2, servo.GROUP_SIZE)
    for lane in range(10):
        g, p = divmod(lane, servo.LANES)
        for k in range(2):
            t = lanes.groups[g, k * servo._L_AXIS :]
            placed = {
                "ac": t[: servo._L_B].reshape(8, 8, 8)[:, :, p],
                "bc": t[servo._L_B : servo._L_C].reshape(2, 8, 8)[:, :, p],
                "cu": t[servo._L_C : servo._L_DU].reshape(8, 8)[:, p],
                "du": t[servo._L_DU + p],
                "gu": t[servo._L_GU : servo._L_TQ].reshape(2, 8)[:, p],
                "tq": t[servo._L_TQ + p],
                "umax": t[servo._L_UMAX + p],
            }
            for name, got in placed.items():
                own = getattr(lanes, name)[lane]
                want = own if name == "umax" else own[k]
                if lane not in started:
                    want = np.zeros_like(want)
                np.testing.assert_array_equal(np.squeeze(got), want, err_msg=f"{name} {lane}")


@pytest.mark.parametrize("design", [pi_design, hinf_2dof_design])
def test_lanes_started_on_scaled_inertias_hold_the_scaled_plants_loops(design):
    """``ServoLanes.start_scaled`` (what a batch of a split's lanes starts with: the
    nominal plant, each lane's inertia scales) writes what ``start_lanes`` writes for the
    plants ``true_params_of`` makes of them, to the last bit, scales of 1 included."""
    from machining_envs.contouring.scenarios import true_params_of
    from machining_envs.contouring.servo import ServoLanes

    designs = tuple(design(P, ax) for ax in "xy")
    scales = np.array([[1.0, 1.0], [0.71, 1.38], [1.2, 0.9], [1.0, 1.3]])
    lanes = np.array([5, 0, 9, 2])
    want, got = ServoLanes(designs, 50, 12), ServoLanes(designs, 50, 12)
    want.start_lanes(lanes, [true_params_of(tuple(sc), P) for sc in scales.tolist()])
    got.start_scaled(lanes, P, scales)
    assert got.buf.tobytes() == want.buf.tobytes()
    assert got.groups.tobytes() == want.groups.tobytes()
    assert np.any(got.buf[lanes] != 0.0, axis=1).all()


def test_a_nan_state_runs_through_unclipped():
    """A diverged loop (NaN state) gives NaN outputs and is not reported as clipped."""
    loop = ServoLoop(P, tuple(pi_design(P, ax) for ax in "xy"), 50)
    state = loop.initial_state()
    state[0] = np.nan
    pos, vel, cmd, torque, clipped = loop.run(state, np.zeros((50, 2)), np.zeros((50, 2)))
    assert not clipped
    assert np.isnan(pos[:, 0]).all() and np.isnan(cmd[:, 0]).all()
    assert np.isfinite(pos[:, 1]).all()  # the other axis is its own loop
