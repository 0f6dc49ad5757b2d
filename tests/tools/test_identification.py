"""Identification: known parameters back from synthetic noisy measurements; bad data refused.

Noise levels are those of a careful shop-floor test: cut forces and torques repeat to about
1 % (each cut's mean over many revolutions), a velocity signal carries 2 % of its range
of white noise, and mean forces from a piezo dynamometer (threshold < 0.01 N) are
resolved to 0.05 N.
"""

import gymnasium as gym
import numpy as np
import pytest

from machining_envs import MillingParams
from machining_envs.core.workpieces import DepthProfile
from machining_envs.identification import (
    SEED_002_C,
    SEED_002_CUTS,
    IdentificationError,
    fit_calibration_matrix,
    fit_cutting_coefficients,
    fit_milling_torque,
    fit_power_law,
    fit_servo,
    fit_servo_sine,
    fit_servo_step,
    fit_turning_force,
)
from machining_envs.milling.plant import MillingPlant, mean_forces
from machining_envs.turning.plant import TurningParams

# The paper's cut design (seed 000 §3.1): d = 1, 2, 3 mm x ft = 0.025-0.1 mm, 3 replicates.
_D, _F = (g.ravel() for g in np.meshgrid([1.0, 2.0, 3.0], [0.025, 0.05, 0.075, 0.1]))
DEPTH, FEED = np.tile(_D, 3), np.tile(_F, 3)


@pytest.mark.parametrize("seed", range(10))
def test_milling_power_law_recovered_within_3_percent(seed):
    rng = np.random.default_rng(seed)
    p = MillingParams()
    torque = p.steady_torque_Nmm(DEPTH, FEED) * np.exp(0.01 * rng.standard_normal(DEPTH.size))
    fit = fit_milling_torque(DEPTH, FEED, torque)
    assert fit.exponents["depth"] == pytest.approx(0.4236, rel=0.03)
    assert fit.exponents["feed"] == pytest.approx(0.3999, rel=0.03)
    assert fit.coefficient == pytest.approx(118.0, rel=0.05)
    assert fit.r_squared > 0.99 and fit.rms_relative_error < 0.02
    assert fit.n_points == 36
    # The reported standard errors describe the actual error.
    assert abs(fit.exponents["feed"] - 0.3999) < 4 * fit.std_errors["feed"]
    # And the parameter set runs in the env.
    env = gym.make("machining_envs/EndMilling-v0", params=fit.params, scenario="paper_step")
    env.reset(seed=0)
    env.step(np.array([-0.9], dtype=np.float32))


@pytest.mark.parametrize("seed", range(10))
def test_turning_power_law_recovered_within_3_percent(seed):
    rng = np.random.default_rng(seed)
    feed = np.tile([0.1, 0.15, 0.2, 0.25, 0.3], 4)
    depth = np.repeat([1.0, 1.5, 2.0, 3.0], 5)
    force = 1822.0 * feed**0.7525 * depth * np.exp(0.01 * rng.standard_normal(feed.size))
    fit = fit_turning_force(feed, depth, force)
    assert fit.exponents["feed"] == pytest.approx(0.7525, rel=0.03)
    assert fit.exponents["depth"] == 1.0
    assert fit.coefficient == pytest.approx(1822.0, rel=0.05)
    assert isinstance(fit.params, TurningParams)
    assert fit.params.feed_exponent == fit.exponents["feed"]
    np.testing.assert_allclose(fit.predict(feed=feed, depth=depth), force, rtol=0.05)


def test_power_law_rejects_data_it_cannot_fit():
    with pytest.raises(IdentificationError, match="at least 4 cuts"):
        fit_milling_torque([1, 2, 3], [0.05, 0.05, 0.1], [1.0, 2.0, 3.0])
    with pytest.raises(IdentificationError, match="feed.*entry 2"):
        fit_milling_torque(DEPTH[:5], [0.05, 0.05, -0.1, 0.1, 0.1], np.ones(5))
    with pytest.raises(IdentificationError, match="response.*entry 0"):
        fit_milling_torque(DEPTH[:5], FEED[:5], [0.0, 1, 1, 1, 1])
    with pytest.raises(IdentificationError, match="finite"):
        fit_milling_torque(DEPTH[:5], FEED[:5], [np.nan, 1, 1, 1, 1])
    with pytest.raises(IdentificationError, match="feed takes the same value"):
        fit_milling_torque(DEPTH, np.full(DEPTH.size, 0.05), np.ones(DEPTH.size))
    with pytest.raises(IdentificationError, match="rank-deficient"):
        fit_power_law(np.ones(6), {"a": [1, 2, 3, 1, 2, 3], "b": [2, 4, 6, 2, 4, 6]})
    with pytest.raises(IdentificationError, match="one per cut"):
        fit_milling_torque(DEPTH, FEED[:-1], np.ones(DEPTH.size))
    for e in (np.nan, True, "1"):  # a NaN exponent gave a fit of NaNs
        with pytest.raises(IdentificationError, match=r"fixed_exponents\['b'\] must be a finite"):
            fit_power_law([1, 2, 3, 4, 5], {"a": [1, 2, 3, 5, 4], "b": [1, 1, 2, 3, 2]}, {"b": e})
    with pytest.raises(IdentificationError, match="outside what the plant accepts"):
        # An exponent above 2: not a cutting law the plant accepts.
        fit_milling_torque(DEPTH, FEED, FEED**3.0 * 1e4)
    assert issubclass(IdentificationError, ValueError)


def _cal_data():
    cal = SEED_002_CUTS["calibration"]
    r = SEED_002_CUTS["tool_radius_mm"]
    x = np.column_stack([np.ones(len(cal)), cal[:, 0] / r, cal[:, 1] / r, cal[:, 2]])
    return cal, r, x @ SEED_002_C


def test_calibration_matrix_of_seed_002_is_returned_exactly_from_exact_data():
    cal, r, forces = _cal_data()
    fit = fit_calibration_matrix(cal[:, 0], cal[:, 1], cal[:, 2], forces, r)
    np.testing.assert_allclose(fit.matrix, SEED_002_C, rtol=1e-10, atol=1e-9)
    assert fit.n_cuts == 6 and fit.rms_residual_N < 1e-9


@pytest.mark.parametrize("seed", range(10))
def test_calibration_matrix_within_1_percent_from_noisy_forces(seed):
    cal, r, forces = _cal_data()
    rng = np.random.default_rng(seed)
    noisy = forces + 0.05 * rng.standard_normal(forces.shape)
    fit = fit_calibration_matrix(cal[:, 0], cal[:, 1], cal[:, 2], noisy, r)
    np.testing.assert_allclose(fit.matrix, SEED_002_C, rtol=0.01)
    assert np.all(fit.r_squared > 0.9999)
    # Predict the confirmation cuts (tests 7-9) as eq. (8) does with the true matrix.
    conf = SEED_002_CUTS["confirmation"]
    truth = np.column_stack([np.ones(3), conf[:, 0] / r, conf[:, 1] / r, conf[:, 2]]) @ SEED_002_C
    # Within 1 %, or 0.5 N for the near-zero Fx of test 9 (0.1 % of the cuts' 500 N scale).
    np.testing.assert_allclose(
        fit.predict(conf[:, 0], conf[:, 1], conf[:, 2]), truth, rtol=0.01, atol=0.5
    )


def test_calibration_matrix_rejects_data_it_cannot_fit():
    cal, r, forces = _cal_data()
    with pytest.raises(IdentificationError, match="at least 4 cuts"):
        fit_calibration_matrix(cal[:3, 0], cal[:3, 1], cal[:3, 2], forces[:3], r)
    with pytest.raises(IdentificationError, match="axial_depth_mm takes the same value"):
        fit_calibration_matrix(cal[:, 0], np.full(6, 10.0), cal[:, 2], forces, r)
    with pytest.raises(IdentificationError, match="rank-deficient"):
        # dr and da move together: their rows of [C] cannot be told apart.
        fit_calibration_matrix(cal[:, 0], cal[:, 0], cal[:, 2], forces, r)
    with pytest.raises(IdentificationError, match=r"shape \(6, 3\)"):
        fit_calibration_matrix(cal[:, 0], cal[:, 1], cal[:, 2], forces[:, :2], r)
    with pytest.raises(IdentificationError, match="tool_radius_mm"):
        fit_calibration_matrix(cal[:, 0], cal[:, 1], cal[:, 2], forces, 0.0)


def test_cutting_coefficients_recovered_and_usable_by_the_env():
    p = MillingParams.ahn_choi_al6061()
    dr = np.array([1.0, 2.0, 3.0, 4.0, 2.0, 2.0])
    da = np.array([10.0, 10.0, 10.0, 10.0, 5.0, 15.0])
    ft = np.array([0.05, 0.05, 0.05, 0.05, 0.025, 0.1])
    kw = {"n_flutes": 2, "tool_radius_mm": 6.0, "mode": "down"}
    forces = mean_forces(dr, da, ft, kt=700.0, kr=210.0, ka=140.0, **kw)
    rng = np.random.default_rng(0)
    fit = fit_cutting_coefficients(
        dr, da, ft, forces * (1 + 0.01 * rng.standard_normal(forces.shape))
    )
    assert fit.kt == pytest.approx(700.0, rel=0.02)
    assert fit.kr == pytest.approx(210.0, rel=0.05)
    assert fit.ka == pytest.approx(140.0, rel=0.03)
    assert fit.r_squared > 0.99
    assert fit.params.force_model == "average_force" and fit.params.n_teeth == p.n_teeth
    plant = MillingPlant(fit.params, 1000.0, DepthProfile.steps((2.0,), 50.0))
    for _ in range(30):
        s = plant.step(80.0)
    assert s.torque_Nmm > 0
    with pytest.raises(IdentificationError, match="radial_depth_mm"):
        fit_cutting_coefficients(dr * 4, da, ft, forces)


def test_calibration_matrix_to_params_round_trip():
    """Forces from the average-force model -> [C] -> Kt, Kr, Ka for the env, near the centre
    of the calibrated range (the model is nonlinear in dr, so [C] holds only locally)."""
    kw = {"n_flutes": 2, "tool_radius_mm": 6.0, "mode": "down"}
    dr = np.array([2.5, 3.5, 3.0, 3.0, 3.0, 3.0])
    da = np.array([10.0, 10.0, 12.0, 8.0, 10.0, 10.0])
    ft = np.array([0.05, 0.05, 0.05, 0.05, 0.04, 0.06])
    forces = mean_forces(dr, da, ft, kt=700.0, kr=210.0, ka=140.0, **kw)
    fit = fit_calibration_matrix(dr, da, ft, forces, 6.0)
    coef = fit.to_params([2.8, 3.0, 3.2], [9.0, 10.0, 11.0], [0.045, 0.05, 0.055])
    assert coef.kt == pytest.approx(700.0, rel=0.03)
    assert coef.ka == pytest.approx(140.0, rel=0.03)
    assert coef.r_squared > 0.99
    assert coef.params.force_model == "average_force" and coef.params.tool_diameter_mm == 12.0


def test_seed_002_matrix_to_params_reports_its_fit():
    """Seed 002's own [C] (fitted on its Table 1 as printed) also converts; the goodness of
    fit says how far one set of Kt, Kr, Ka is from it over the chosen cuts."""
    cal, r, forces = _cal_data()
    fit = fit_calibration_matrix(cal[:, 0], cal[:, 1], cal[:, 2], forces, r)
    coef = fit.to_params([5.0, 8.0, 11.0], [10.0, 10.0, 10.0], [0.05, 0.05, 0.05])
    assert coef.kt > 0 and coef.kr > 0 and coef.ka > 0
    assert np.isfinite(coef.r_squared) and coef.rms_relative_error > 0


def _servo_record(gain, wn_hz, zeta, t, u_of_t):
    """Response from rest by the plant's own servo (eq. 7, exact ZOH) on a grid 10x finer
    than the record, the command held at its value mid-way through each fine step."""
    fine = (t[1] - t[0]) / 10
    p = MillingParams(
        servo_gain=gain,
        servo_natural_freq_hz=wn_hz,
        servo_damping=zeta,
        sample_time_s=fine,
        substeps=1,
        command_max=1e6,
    )
    plant = MillingPlant(p, 400.0, DepthProfile.steps((1.0,), 1e4))
    y = [0.0]
    for k in range(10 * (t.size - 1)):
        plant.step(float(u_of_t(t[0] + (k + 0.5) * fine)))
        if (k + 1) % 10 == 0:
            y.append(plant.state[0])
    return np.array(y)


@pytest.mark.parametrize("seed", range(5))
def test_servo_natural_frequency_within_5_percent_from_a_noisy_step(seed):
    rng = np.random.default_rng(seed)
    dt = 0.005
    t = np.arange(400) * dt
    y = _servo_record(0.02, 3.0, 0.7, t, lambda _: 50.0)
    fit = fit_servo_step(t, y + 0.02 * np.ptp(y) * rng.standard_normal(t.size), step=50.0)
    assert fit.natural_freq_hz == pytest.approx(3.0, rel=0.05)
    assert fit.damping == pytest.approx(0.7, rel=0.1)
    assert fit.gain == pytest.approx(0.02, rel=0.02)
    assert fit.r_squared > 0.98
    assert isinstance(fit.params, MillingParams) and fit.params.servo_gain == fit.gain


def test_servo_from_a_sine_and_into_turning_params():
    """The lathe of seed 001 (2.66 Hz, zeta 0.43), driven by a 1.5 Hz sine from rest."""
    rng = np.random.default_rng(1)
    dt = 0.005
    t = np.arange(800) * dt
    g = 0.66 * 0.0021414
    y = _servo_record(g, 2.66, 0.43, t, lambda s: 1000.0 + 500.0 * np.sin(2 * np.pi * 1.5 * s))
    fit = fit_servo_sine(
        t,
        y + 0.02 * np.ptp(y) * rng.standard_normal(t.size),
        500.0,
        1.5,
        offset=1000.0,
        base=TurningParams(),
    )
    assert fit.natural_freq_hz == pytest.approx(2.66, rel=0.05)
    assert fit.damping == pytest.approx(0.43, rel=0.1)
    assert fit.params.servo_gain == pytest.approx(0.66, rel=0.02)  # the gear ratio divided out


def test_servo_fit_rejects_data_it_cannot_fit():
    t = np.arange(100) * 0.01
    with pytest.raises(IdentificationError, match="at least 20 samples"):
        fit_servo_step(t[:10], np.ones(10))
    with pytest.raises(IdentificationError, match="equal steps"):
        fit_servo_step(np.r_[t[:50], t[50:] + 0.003], np.linspace(0, 1, 100))
    with pytest.raises(IdentificationError, match="does not vary"):
        fit_servo_step(t, np.zeros(100))
    with pytest.raises(IdentificationError, match="command is zero"):
        fit_servo(t, np.zeros(100), np.linspace(0, 1, 100))
    with pytest.raises(IdentificationError, match="finite"):
        fit_servo_step(t, np.r_[np.linspace(0, 1, 99), np.inf])
    with pytest.raises(IdentificationError, match="step"):
        fit_servo_step(t, np.linspace(0, 1, 100), step=0.0)
    with pytest.raises(IdentificationError, match="step must be a non-zero number, got True"):
        fit_servo_step(t, np.linspace(0, 1, 100), step=True)
    with pytest.raises(IdentificationError, match="response must hold 100 values .one per sample"):
        fit_servo(t, np.ones(100), np.ones(99))
    with pytest.raises(IdentificationError, match="offset must be a finite number"):
        fit_servo_sine(t, np.linspace(0, 1, 100), 1.0, 2.0, offset=np.nan)
    # A sine command whose response is a plain step (the drive clipped it): no servo fits.
    u = 1000.0 + 500.0 * np.sin(2 * np.pi * 1.5 * t)
    y = 0.02 * 150.0 * (1.0 - np.exp(-t / 0.3))
    with pytest.raises(IdentificationError, match="second-order"):
        fit_servo(t, u, y)
