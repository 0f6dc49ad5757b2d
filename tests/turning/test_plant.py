"""The turning plant against the paper's equations and independent computations."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from agents.bench.turning import critical_gain_turning
from machining_envs.core.workpieces import DepthProfile
from machining_envs.turning.plant import TurningParams, TurningPlant


def test_zoh_reproduces_eq14_at_405_rpm():
    num, den = TurningParams().discrete_open_loop(405.0)
    # Numerator 0.287 z^-1 + 0.515 z^-2 + 0.071 z^-3 (eq. 14). The paper prints three
    # decimals; we ask for agreement within one unit of the third (ours: 0.28646, 0.51468,
    # 0.07094 - the first reads 0.287 only when rounded up, as the paper seems to have).
    np.testing.assert_allclose(num, [0.0, 0.287, 0.515, 0.071], atol=1e-3)
    # Denominator (1 - 0.060 z^-1 + 0.237 z^-2)(1 - 0.259 z^-1) (eq. 14), factor by factor.
    paper = np.convolve([1.0, -0.060, 0.237], [1.0, -0.259])
    np.testing.assert_allclose(den, paper, atol=1e-3)
    roots = np.roots(den)
    real = roots[np.isclose(roots.imag, 0)].real
    np.testing.assert_allclose(real, [0.259], atol=1e-3)
    pair = roots[~np.isclose(roots.imag, 0)]
    np.testing.assert_allclose(np.poly(pair).real, [1.0, -0.060, 0.237], atol=1e-3)


def test_critical_gain_within_5_percent_of_paper():
    k = critical_gain_turning(405.0, kgh=1.9)
    assert abs(k - 0.807) / 0.807 < 0.05, k
    # At that gain a closed-loop root sits on the unit circle; 1 % below it, all inside.
    num, den = TurningParams().discrete_open_loop(405.0)
    n = np.convolve([1.9, -1.0], num)
    d = np.convolve([1.0, -1.0], den)
    assert max(abs(np.roots(d + k * n))) == pytest.approx(1.0, abs=1e-6)
    assert max(abs(np.roots(d + 0.99 * k * n))) < 1.0


@pytest.mark.parametrize("rpm", [245.0, 405.0, 700.0, 1234.5])
def test_feed_is_the_exact_moving_integral(rpm):
    """f(t) = int_{t-T}^t Vf: compare with a tight ODE solution of the servo (eq. 1-4)."""
    p = TurningParams()
    prof = DepthProfile.steps()
    plant = TurningPlant(p, rpm, prof)
    rng = np.random.default_rng(3)
    us = rng.uniform(0, 3000, size=25)
    feeds = [plant.step(u).feed_mm_per_rev for u in us]
    wn, z = p.servo_natural_freq_rad_s, p.servo_damping
    g = p.servo_gain * p.gear_ratio * wn**2

    def rhs(t, x):
        u = us[min(int(t / 0.1), len(us) - 1)]
        return [x[1], -(wn**2) * x[0] - 2 * z * wn * x[1] + g * u, x[0]]

    tt = np.linspace(0, 2.5, 250001)
    sol = solve_ivp(rhs, (0, 2.5), [0, 0, 0], t_eval=tt, rtol=1e-11, atol=1e-12, max_step=1e-3)
    t_k = 0.1 * np.arange(1, 26)
    ref = np.interp(t_k, tt, sol.y[2]) - np.interp(t_k - 60 / rpm, tt, sol.y[2], left=0.0)
    np.testing.assert_allclose(feeds, ref, atol=1e-8)


def test_steady_state_follows_eq_1_to_10():
    p = TurningParams(noise_std_N=0.0)
    plant = TurningPlant(p, 405.0, DepthProfile.steps((2.0,), 1000.0))
    u = 1500.0
    for _ in range(100):
        s = plant.step(u)
    feed = p.servo_gain * p.gear_ratio * u * 60 / 405.0  # f = Ks Km U T
    force = p.force_coefficient * feed**p.feed_exponent * 2.0
    assert s.feed_mm_per_rev == pytest.approx(feed, rel=1e-9)
    assert s.force_N == pytest.approx(force, rel=1e-9)
    assert s.measured_counts == pytest.approx(p.sensor_gain * force, rel=1e-6)
    # Eq. (11)'s Kp is the steady ratio Fc / U.
    kp = p.process_gain(405.0, 2.0, feed)
    assert s.measured_counts / u == pytest.approx(kp, rel=1e-6)


def test_substep_size_is_converged():
    """2 ms sub-steps: force and filtered measurement within 0.5 % of a 0.2 ms simulation."""
    prof = DepthProfile.steps((1.0, 2.0, 3.0), 3.0)
    rng = np.random.default_rng(0)
    us = rng.uniform(0, 4000, size=40)
    out = {}
    for m in (50, 500):
        plant = TurningPlant(TurningParams(substeps=m), 405.0, prof)
        out[m] = np.array([[s.force_N, s.measured_counts] for s in (plant.step(u) for u in us)])
    scale = np.abs(out[500]).max(axis=0)
    assert np.max(np.abs(out[50] - out[500]) / scale) < 5e-3


@pytest.mark.parametrize(
    "field, value",
    [
        ("sample_time_s", 0.0),
        ("servo_damping", -0.1),
        ("feed_exponent", float("nan")),
        ("sensor_filter_order", 3),
        ("substeps", 0),
    ],
)
def test_bad_params_name_the_parameter(field, value):
    with pytest.raises(ValueError, match=field):
        TurningParams(**{field: value})


def test_plant_rejects_bad_spindle_speed():
    with pytest.raises(ValueError, match="spindle_rpm"):
        TurningPlant(TurningParams(), -405.0, DepthProfile.steps())


def test_position_excursion_bound_holds():
    """The one-segment shortcut relies on |Vf| <= the BIBO bound; bang-bang commands test it."""
    p = TurningParams()
    plant = TurningPlant(p, 405.0, DepthProfile.steps((1.0,), 1e5))
    vmax = 0.0
    for k in range(300):
        plant.step(p.command_max if (k // 3) % 2 == 0 else 0.0)
        vmax = max(vmax, abs(plant.state[0]))
    assert vmax > p.max_feed_velocity_mm_s  # the servo does overshoot
    assert vmax * p.sample_time_s <= plant._margin


def test_force_across_a_step_edge_matches_direct_evaluation():
    """Sub-steps straddling an edge use the profile itself: compare with a fine plant."""
    prof = DepthProfile.steps((1.0, 3.0), 0.5)
    coarse = TurningPlant(TurningParams(), 405.0, prof)
    forces = [coarse.step(3000.0).force_N for _ in range(12)]
    ref = TurningPlant(TurningParams(substeps=1000), 405.0, prof)
    forces_ref = [ref.step(3000.0).force_N for _ in range(12)]
    np.testing.assert_allclose(forces, forces_ref, rtol=1e-9)


def _step_matrix_reference(p, rpm):
    """The step matrix built directly with numpy (the derivation of ``_Matrices``): the
    rows on the current pair, less, in each feed row, the position at its delayed instant
    placed in the group of its sample."""
    import math

    from machining_envs.core.lti import zoh
    from machining_envs.turning.plant import _LinearKey, _servo_system, _speed_free

    key = _LinearKey.of(p)
    m, ts = p.substeps, p.sample_time_s
    h = ts / m
    phis, gams = _speed_free(key)[:2]
    period = 60.0 / rpm
    lags = int(math.ceil(period / ts + 1e-12)) + 1
    big = np.zeros((2 * m + 3, 4 * (lags + 1)))
    big[:m, 0:3] = phis[1:, 2]
    big[:m, 3] = gams[1:, 2]
    big[m : 2 * m, :4] = big[:m, :4]
    big[2 * m :, 0:3] = phis[m]
    big[2 * m :, 3] = gams[m]
    rho = (-period) % h
    if rho > h - 1e-12 * h:
        rho = 0.0
    phi_r, gam_r = zoh(*_servo_system(key), rho) if rho > 0 else (np.eye(3), np.zeros((3, 1)))
    for j in range(m):
        back = (j + 1) * h - period
        lag = math.ceil(-back / ts - 1e-9) if back < 0 else 0
        i = round((back + lag * ts - rho) / h)
        big[m + j, 4 * lag : 4 * lag + 3] -= phi_r[2] @ phis[i]
        big[m + j, 4 * lag + 3] -= gams[i] @ phi_r[2] + gam_r[2, 0]
    return big


@pytest.mark.parametrize("rpm", [100.0, 173.3, 600.0, 1234.5, 2500.0, 4000.0])
def test_packed_step_matrix_is_the_step_matrix(rpm):
    """The lanes hold the step matrix as its non-zero groups of four columns (the current
    pair, and a feed row's delayed pair where that is another): unpacked, it is the matrix
    built directly, each entry to rounding (sums of three products, in another order)."""
    from machining_envs.turning.plant import _LinearKey, _matrices

    p = TurningParams.noh_kim_kim_1992()
    mats = _matrices(_LinearKey.of(p), rpm)
    m = p.substeps
    ref = _step_matrix_reference(p, rpm)
    big = mats.big
    assert big.shape == ref.shape
    np.testing.assert_array_equal(big != 0, ref != 0)  # the same groups hold the numbers
    scale = np.abs(ref).max(axis=1, keepdims=True)
    assert np.all(np.abs(big - ref) <= 4 * np.finfo(float).eps * scale)
    assert not mats.packed[:m, 4:].any() and not mats.packed[2 * m :, 4:].any()  # feeds only
    assert (mats.delay_group > 0).any()  # the delayed groups are tested


def test_the_shared_tables_of_the_linear_blocks_are_read_only():
    """The tables every lane and env of one set of linear parameters share (cached once)
    refuse writes, so that no caller can change another env's plant through them; the
    lanes' own rows are copies and stay writable."""
    from machining_envs.turning.plant import (
        TurningLanes,
        _LinearKey,
        _matrices,
        _servo_system,
        _speed_free,
        _speed_free_rows,
        _speed_free_tables,
    )

    key = _LinearKey.of(TurningParams())
    shared = [*_servo_system(key), *_speed_free(key), *_speed_free_rows(key)]
    shared += [t for t in _speed_free_tables(key) if isinstance(t, np.ndarray)]
    mats = _matrices(key, 405.0)
    shared += [mats.delay_group, mats.filt_step, mats.packed]
    assert len(shared) == 18
    for table in shared:
        assert not table.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            table[(0,) * table.ndim] = 1.0
    lanes = TurningLanes(TurningParams(), n=2)
    assert lanes.base.flags.writeable and lanes.filt.flags.writeable


def test_exponential_row_of_a_delayed_instant_is_the_exact_discretisation():
    """The I-row of ``[Phi(rho), Gamma(rho)]`` that places a delayed instant between grid
    points (compiled Taylor series) equals scipy's ``expm``-based ``zoh`` to 1e-15 of the
    exponential's size (``zoh`` is exact to that, not to the last bit of its smallest
    entries), and declines a step whose augmented matrix is too large for the series."""
    from machining_envs.core.lti import zoh
    from machining_envs.turning.plant import _exp_row, _LinearKey, _servo_system

    key = _LinearKey.of(TurningParams())
    a, b = _servo_system(key)
    h = key.sample_time_s / key.substeps
    out = np.zeros(4)
    for rho in np.random.default_rng(0).uniform(0.0, h, 300):
        phi, gam = zoh(a, b, rho)
        assert _exp_row(a, b, rho, 2, out)
        np.testing.assert_allclose(out, [*phi[2], gam[2, 0]], rtol=0, atol=1e-15)
    assert not _exp_row(a, b, 10 * h, 2, out)  # norm about 5.6: zoh's job


def test_step_matrix_by_zoh_where_the_series_declines_it_agrees():
    """Where the compiled series declines ``Phi(rho)`` (never at the plant's speeds), the
    lane's step matrix comes from scipy's ``zoh`` instead: at speeds where both can run,
    the two give the same delay groups and rows within 4 eps of each row's size."""
    from machining_envs.turning.plant import (
        _fill_matrices_zoh,
        _lane_matrices,
        _LinearKey,
        _speed_free_tables,
    )

    key = _LinearKey.of(TurningParams())
    m = key.substeps
    for rpm in (50.0, 245.0, 333.3, 405.0, 700.0, 1234.5, 3000.0):
        series, zohs = np.empty((m, 4)), np.empty((m, 4))  # a lane's feed rows
        lag_s, lag_z = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
        lags = _lane_matrices(*_speed_free_tables(key), rpm, series, lag_s)
        assert lags > 0
        assert _fill_matrices_zoh(key, rpm, zohs, lag_z) == lags
        np.testing.assert_array_equal(lag_s, lag_z)
        scale = np.abs(series).max(axis=1, keepdims=True)
        assert np.all(np.abs(series - zohs) <= 4 * np.finfo(float).eps * scale)


@pytest.mark.parametrize("width", [5, 6, 9, 13, 53, 54, 101])
def test_the_filters_two_rows_are_matvecs(width):
    """The second-order filter's step (``_filter_pair``, both rows in one loop) gives
    ``core.compiled.kernels.matvec``'s numbers to the last bit, with inf and NaN too; widths matvec
    sums otherwise are left to it."""
    from machining_envs.core.compiled.kernels import matvec
    from machining_envs.turning.plant import _filter_pair

    rng = np.random.default_rng(width)
    for trial in range(40):
        f = rng.normal(size=2 * width) * 10.0 ** rng.integers(-3, 4, size=2 * width)
        x = rng.normal(size=width) * 10.0 ** rng.integers(-3, 4, size=width)
        if trial == 1:
            x[rng.integers(width)] = np.inf
        if trial == 2:
            f[rng.integers(2 * width)] = np.nan
        out = np.full(2, 7.0)
        expected = np.full((1, 2), 7.0)
        matvec(f.reshape(1, -1), 2, width, x.reshape(1, -1), expected)
        taken = _filter_pair(f, x, width, out)
        assert taken == (width & 3 < 2)
        if taken:
            assert out.tobytes() == expected[0].tobytes(), (width, trial)
        else:
            assert out.tolist() == [7.0, 7.0]


@pytest.mark.parametrize(
    "profile",
    [
        DepthProfile.steps((1.0, 2.0, 3.0), 3.0),
        DepthProfile.taper(),
        DepthProfile.random(np.random.default_rng(4), taper_probability=0.5),
    ],
    ids=["steps", "taper", "random"],
)
def test_depths_across_edges_are_the_profiles(profile):
    """A sample whose sub-steps cross the profile's edges takes each depth by walking from
    the lane's segment; every depth is the profile's own (``DepthProfile.__call__``) to the
    last bit, from any starting segment, outside the cut (zero) and at a NaN position."""
    from machining_envs.turning.plant import _profile_depths

    seg = profile.segment_array()
    edges, d0, slope = seg[0], seg[1, :-1].copy(), seg[3, :-1].copy()
    n = edges.size - 1
    rng = np.random.default_rng(0)
    length = profile.length_mm
    rows = [
        np.linspace(-0.5, length + 0.5, 50),  # every edge, from before the cut to past it
        np.linspace(length + 0.5, -0.5, 50),  # backwards
        rng.uniform(-1.0, length + 1.0, 50),  # anywhere, in no order
        np.resize(np.concatenate([edges, edges[::-1]]), 50),  # on the edges themselves
        np.where(np.arange(50) % 7 == 3, np.nan, np.linspace(0.0, length, 50)),
    ]
    kf = 1.37
    for x in rows:
        want = np.asarray(profile(x))
        for start in range(n):
            force = np.ones(50)
            last = _profile_depths(x, edges, d0, slope, n, start, force, 50, kf)
            np.testing.assert_array_equal(force, 1.0 * want * kf)
            assert last == want[-1]


def test_each_lanes_rows_are_its_step_matrix_after_starts_and_speed_changes():
    """What a lane holds of its step matrix (the shared rows, its feed rows and their delay
    groups) after a start and after a change of speed (a power-limited spindle's) gives
    the rows ``A @ z`` of the step matrix at its speed (``_matrices(...).big``), to
    rounding, for any memory ``z``."""
    from machining_envs.turning.plant import TurningLanes, _LinearKey, _matrices, _sampled_rows

    p = TurningParams.noh_kim_kim_1992().replace(spindle_power_W=5000.0)
    m = p.substeps
    speeds = (100.0, 173.3, 600.0, 1234.5, 2500.0, 3000.0)
    lanes = TurningLanes(p, n=len(speeds))
    profile = DepthProfile((0.0, 50.0), (2.0,), (2.0,))
    rng = np.random.default_rng(3)
    key = _LinearKey.of(p)
    for k, rpm in enumerate(speeds):
        lanes.start(k, p, rpm, profile)
    for changed in (False, True):
        if changed:  # every lane to another speed, as a power-limited spindle's drive does
            for k in range(len(speeds)):
                lanes.set_speed(k, speeds[(k + 2) % len(speeds)])
        for k in range(len(speeds)):
            mats = _matrices(key, float(lanes.spindle_rpm[k]))
            np.testing.assert_array_equal(lanes.lag[k], mats.delay_group)
            big = mats.big
            z = rng.standard_normal(big.shape[1])
            zk = np.zeros(lanes.z.shape[1])
            zk[: z.size] = z
            y = np.zeros(2 * m + 3)
            _sampled_rows(lanes.base, lanes.feed[k], lanes.lag[k], zk, m, y)
            ref = big @ z
            assert np.all(np.abs(y - ref) <= 1e-13 * np.abs(big).max() * np.abs(z).sum())
    assert any(np.unique(lanes.lag[k]).size > 1 for k in range(len(speeds)))  # two groups
