"""Drilling agents: protocol, the sliding-mode derivation, breakage on held-out holes, pecking."""

import math

import control as ct
import gymnasium as gym
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from agents import PD, NoControl, PeckDrilling, SlidingMode
from agents.drilling import sliding_mode_input
from agents.eval import rollout
from agents.eval.harness import rollout_batch
from machining_envs import DrillingParams, DrillingScenario
from machining_envs.drilling.metrics import drilling_metrics
from tests.helpers import (
    DRILLING,
    TURNING,
    assert_batched_predict_equals_single,
    assert_sb3_evaluate_policy_runs,
)

P = DrillingParams()
SHORT = DrillingScenario("short", 0.6, aspect_ratio=2.0)
VOLTAGE_AGENTS = [NoControl.from_env, PD.from_env, SlidingMode.from_env]


def _factories():
    return [(f, "voltage") for f in VOLTAGE_AGENTS] + [
        (NoControl.from_env, "feed"),
        (PeckDrilling.from_env, "feed"),
    ]


@pytest.mark.parametrize("factory,control", _factories())
def test_sb3_evaluate_policy_runs_agents_unchanged(factory, control):
    assert_sb3_evaluate_policy_runs(factory, DRILLING, {"scenario": SHORT, "control": control})


@pytest.mark.parametrize("factory,control", _factories())
def test_batched_predict_equals_single(factory, control):
    agent = factory(gym.make(DRILLING, control=control))
    assert_batched_predict_equals_single(
        agent, lambda: gym.make(DRILLING, control=control, scenario="paper_0.7"), n_steps=400
    )


def test_agents_refuse_the_wrong_env_or_mode_and_bad_gains():
    volt = gym.make(DRILLING)
    feed = gym.make(DRILLING, control="feed")
    with pytest.raises(ValueError, match="control='voltage'"):
        SlidingMode.from_env(feed)
    with pytest.raises(ValueError, match="control='voltage'"):
        PD.from_env(feed)
    with pytest.raises(ValueError, match="control='feed'"):
        PeckDrilling.from_env(volt)
    with pytest.raises(TypeError, match="MicroDrillingEnv"):
        PD.from_env(gym.make(TURNING))
    with pytest.raises(ValueError, match="lam"):
        SlidingMode.from_env(volt, lam=-1.0)
    with pytest.raises(ValueError, match="loop_gain"):
        PD.from_env(volt, loop_gain=0.0)
    with pytest.raises(ValueError, match="min_voltage"):
        PD.from_env(volt, min_voltage=11.0)
    with pytest.raises(ValueError, match="peck_diameters"):
        PeckDrilling.from_env(feed, peck_diameters=float("nan"))
    with pytest.raises(ValueError, match="voltage"):
        NoControl.from_env(volt, voltage=20.0)


def test_pd_law_by_hand():
    env = gym.make(DRILLING)
    pd = PD.from_env(env, loop_gain=3.0, derivative_time_s=0.0)
    obs = np.zeros(12, dtype=np.float32)
    obs[1] = 0.4  # reference 0.4 N·mm
    obs[0] = 0.5  # measured 0.5 N·mm
    a, _ = pd.predict(obs)
    kp = 3.0 * 0.608 * 5.0 / obs[1]
    u = 5.0 + kp * (float(obs[0]) - float(obs[1]))
    assert a[0] == pytest.approx(u / 5.0 - 1.0, rel=1e-6)
    obs[0] = 0.3  # below the reference: the voltage stays at the floor (speed up only)
    a, _ = pd.predict(obs)
    assert a[0] == pytest.approx(0.0, abs=1e-7)


def test_pd_loop_margins_and_bandwidth():
    """L = 3: the PD's crossover near the sliding mode's lambda, with wide margins.

    The loop linearised at the nominal cut (valve, loaded spindle, 50 Hz sensor, half a
    sample of hold delay) is computed with python-control, independently of the agents.
    """
    lam = SlidingMode.from_env(gym.make(DRILLING)).lam
    s = ct.tf("s")
    for d in (0.5, 0.6, 0.7, 0.8):
        t0 = P.nominal_torque_Nmm(d)
        w0 = P.free_speed_rad_s(P.nominal_voltage)
        w = w0
        for _ in range(50):  # loaded equilibrium: k2 x_v = k3 w^n + k4 / (I w)
            w = P.free_speed_rad_s(P.nominal_voltage, t0 * w0 / w)
        k4 = t0 * w0
        wn, z, n = P.valve_natural_freq_rad_s, P.valve_damping, P.spindle_friction_exponent
        pole = n * P.spindle_friction * w ** (n - 1) - k4 / (P.spindle_inertia_Nmm_s2 * w**2)
        num, den = ct.pade(P.sample_time_s / 2, 3)
        plant = (
            P.k1
            / (s**2 + 2 * z * wn * s + wn**2)
            * P.spindle_drive_gain
            / (s + pole)
            * (k4 / w**2)
            / (s / (2 * math.pi * P.sensor_cutoff_hz) + 1)
            * ct.tf(num, den)
        )
        pd = PD.from_env(gym.make(DRILLING))
        kp = pd.loop_gain * n * pd.u0 / t0
        td, nf = pd.derivative_time_s, pd.derivative_filter
        ctrl = kp * (1 + td * s / (td / nf * s + 1))
        gm, pm, _, wc = ct.margin(ctrl * plant)
        assert pm > 60.0 and gm > 4.0, (d, gm, pm)
        assert 0.75 * lam < wc < 1.25 * lam, (d, wc)


def _model_rhs(u, k4, p):
    wn, z = p.valve_natural_freq_rad_s, p.valve_damping

    def f(t, x):
        return [
            x[1],
            p.k1 * u - 2 * z * wn * x[1] - wn**2 * x[0],
            p.spindle_drive_gain * x[0]
            - p.spindle_friction * x[2] ** p.spindle_friction_exponent
            - k4 / (p.spindle_inertia_Nmm_s2 * x[2]),
        ]

    return f


@pytest.mark.parametrize(
    "x1,x2,hz,torque",
    [
        (0.52, 0.4, 560.0, 0.46),  # torque above the reference, spool opening
        (0.50, -0.2, 545.0, 0.415),  # close to the surface: inside the boundary layer
        (0.61, 0.0, 700.0, 0.52),  # well into the cut
    ],
)
def test_sliding_mode_input_makes_s_dot_equal_minus_k_sat(x1, x2, hz, torque):
    """The feedback-linearising input, checked against the model by numbers alone.

    With ``u`` held, the model (eq. 17-20 with the drilling load) is integrated to 1e-13 on
    both sides of t = 0; the output ``y = k4 / x3`` is fitted by a polynomial and
    differentiated. Then ``S = e'' + 2 lambda e' + lambda^2 e`` must equal the agent's
    surface, and ``dS/dt = -y''' - 2 lambda y'' - lambda^2 y'`` must equal ``-K sat(S/phi)``.
    """
    p = P
    lam, tr = 12.0, 0.41
    phi = 0.03 * tr * lam**2
    k_near, k_far = 35.0 * phi, 0.25 * 35.0 * phi
    x3 = 2 * math.pi * hz
    k4 = torque * x3
    u, s, _ = sliding_mode_input(
        np.array([x1]),
        np.array([x2]),
        np.array([x3]),
        np.array([k4]),
        np.array([tr]),
        lam,
        np.array([phi]),
        np.array([k_near]),
        np.array([k_far]),
        p,
    )
    u, s = float(u[0]), float(s[0])
    f = _model_rhs(u, k4, p)
    half = 4e-3
    fwd = solve_ivp(
        f, (0, half), [x1, x2, x3], rtol=1e-13, atol=1e-13, dense_output=True, method="DOP853"
    )
    bwd = solve_ivp(
        f, (0, -half), [x1, x2, x3], rtol=1e-13, atol=1e-13, dense_output=True, method="DOP853"
    )
    t = half * np.cos(np.pi * (np.arange(41) + 0.5) / 41)  # Chebyshev nodes
    x3t = np.where(t >= 0, fwd.sol(np.abs(t))[2], bwd.sol(-np.abs(t))[2])
    y = k4 / x3t
    poly = np.polynomial.Chebyshev.fit(t, y, 12, domain=[-half, half])
    y0, y1, y2, y3 = (poly.deriv(k)(0.0) for k in range(4))
    e, ed, edd = tr - y0, -y1, -y2
    s_num = edd + 2 * lam * ed + lam**2 * e
    sdot_num = -y3 - 2 * lam * y2 - lam**2 * y1
    gain = k_near if abs(s) <= phi else k_far
    scale = lam**2 * tr
    assert s_num == pytest.approx(s, abs=1e-6 * scale)
    assert sdot_num == pytest.approx(-gain * np.clip(s / phi, -1, 1), abs=1e-5 * scale * lam)


def _smc_nominal_run(d):
    env = gym.make(DRILLING)
    sc = DrillingScenario("nominal", d, noise_scale=0.0, fluctuation_scale=0.0)
    agent = SlidingMode.from_env(env)
    obs, info = env.reset(seed=0, options={"scenario": sc})
    state, start, done = None, np.ones(1, dtype=bool), False
    rec = {k: [] for k in ("t", "S", "u", "torque", "engaged")}
    while not done:
        rec["t"].append(info["t_s"])
        rec["torque"].append(info["torque_Nmm"])
        rec["engaged"].append(info["engagement"] >= 1.0)
        action, state = agent.predict(obs, state=state, episode_start=start)
        start = np.zeros(1, dtype=bool)
        rec["S"].append(state[0, agent.STATE["S"]])
        rec["u"].append(state[0, agent.STATE["u"]])
        obs, _, term, trunc, info = env.step(action)
        done = term or trunc
    assert info["finished"] and not info["breakage"]
    return agent, info["torque_limit_Nmm"], {k: np.array(v) for k, v in rec.items()}


@pytest.mark.parametrize("d", [0.6, 0.8])
def test_sliding_surface_converges_into_the_boundary_layer_and_error_stays_bounded(d):
    r"""Nominal plant, no noise, no fluctuation: S reaches |S| <= phi and stays there.

    The derived bound on the true torque error, once inside the layer: the agent's S is
    computed with k4 frozen over a sample (``S_model``); with the true, growing ``k4`` the
    error obeys ``e'' + 2 lambda e' + lambda^2 e = S_true`` with
    ``S_true = S_model - 2 lambda Tdot - Tddot + 2 Tdot a / x3``, where ``Tdot = k4dot / x3``
    is the torque's rise at a frozen speed (the chips) and ``a / x3 = k4dot / k4`` the
    spindle's relative acceleration that follows it. The filter ``e -> S`` has DC gain and
    impulse-response L1 norm ``1 / lambda^2``, so after the entry transient

    .. math:: |e| \le \epsilon T_r + (2/\lambda + 2 r / \lambda^2) \dot T_{max}
                    + \ddot T_{max} / \lambda^2,

    and the measured torque the agent uses lags the true one by at most the k4 filter,
    the sensor filter and one held sample: ``+ (tau_k + tau_s + T_s) Tdot_max``. With
    ``g(L) = g0 (exp(L / (l D)) - 1)``, ``Tdot = T_r gdot / (1 + g)`` grows with depth, so
    its maximum is at the hole's bottom.
    """
    agent, tr, rec = _smc_nominal_run(d)
    phi = float(agent.boundary_layer(tr))
    assert np.all(rec["u"] < P.voltage_max)  # never saturated on this hole
    k_eng = int(np.argmax(rec["engaged"]))
    inside = np.flatnonzero((np.abs(rec["S"]) <= phi) & (np.arange(rec["S"].size) >= k_eng))
    k_in = int(inside[0])
    # Reaching: |S| / K_far after engagement, well under a second here.
    assert rec["t"][k_in] - rec["t"][k_eng] < 1.0
    assert np.all(np.abs(rec["S"][k_in:]) <= phi)

    v, ell = P.feed_velocity_mm_s, P.chip_length_diameters * d
    x = 10.0 * d / ell  # aspect ratio 10
    g = P.chip_friction * (math.exp(x) - 1)
    gdot = P.chip_friction * math.exp(x) * v / ell
    rate = gdot / (1 + g)  # relative rise of the torque, 1/s
    t_dot = (1 + agent.epsilon) * tr * rate
    t_ddot = t_dot * v / ell
    lam = agent.lam
    lag = agent.k4_filter_s + 1 / (2 * math.pi * P.sensor_cutoff_hz) + P.sample_time_s
    bound = agent.epsilon * tr + (2 / lam + 2 * rate / lam**2 + lag) * t_dot + t_ddot / lam**2
    after = rec["t"] >= rec["t"][k_in] + 1.0  # 12 time constants 1/lambda: transient gone
    err = np.abs(rec["torque"][after] - tr)
    assert err.max() <= bound, (err.max() / tr, bound / tr)
    assert bound / tr < 0.05  # and the bound itself is tight enough to mean something


def test_no_controller_breaks_a_drill_no_control_would_not_and_peck_never_breaks(capsys):
    """Out-of-distribution ``ood`` holes (deeper, worse chips) and the paper's four holes.

    No control breaks some of them (so the check can fail); PD and sliding mode break
    none that no control survives; peck drilling breaks none and always takes longer
    than sliding mode. Both drilling times are printed.
    """
    ood = range(16)  # run as the lanes of one vector env (the same episodes, faster)
    papers = [f"paper_{d:g}" for d in (0.5, 0.6, 0.7, 0.8)]
    cases = [("ood", s) for s in ood] + [(p, 0) for p in papers]
    broke = {}
    times = {}
    for name, factory, control in (
        ("none", NoControl.from_env, "voltage"),
        ("PD", PD.from_env, "voltage"),
        ("SMC", SlidingMode.from_env, "voltage"),
        ("peck", PeckDrilling.from_env, "feed"),
    ):
        env = gym.make(DRILLING, control=control)
        agent = factory(env)
        venv = gym.make_vec(
            DRILLING, num_envs=len(ood), control=control, autoreset_mode="SAME_STEP"
        )
        trajs = rollout_batch(agent, venv, "ood", list(ood))
        trajs += [rollout(agent, env, p, 0) for p in papers]
        rows = [drilling_metrics(t) for t in trajs]
        broke[name] = {i for i, r in enumerate(rows) if r["breakage"]}
        times[name] = [r["drilling_time_s"] for r in rows]
        if name != "none":
            assert all(r["finished"] or r["breakage"] for r in rows)
    assert len(broke["none"]) >= 2
    assert broke["PD"] <= broke["none"] and broke["SMC"] <= broke["none"]
    assert broke["peck"] == set()
    for i, (sc, seed) in enumerate(cases):
        if i not in broke["SMC"]:
            assert times["peck"][i] > times["SMC"][i], (sc, seed)
    with capsys.disabled():
        print(
            f"\n[drilling] broken by no control {sorted(broke['none'])}, PD {sorted(broke['PD'])}, "
            f"SMC {sorted(broke['SMC'])}, peck {sorted(broke['peck'])} of {len(cases)} holes; "
            f"mean drilling time peck {np.mean(times['peck']):.1f} s vs sliding mode "
            f"{np.mean(times['SMC']):.1f} s"
        )


def test_peck_drilling_cycle():
    """Feed q, retract out of the hole at rapid speed, rapid back, feed on."""
    env = gym.make(DRILLING, control="feed", scenario="paper_0.8")
    agent = PeckDrilling.from_env(env)
    tr = rollout(agent, env, seed=0)
    m = drilling_metrics(tr)
    assert m["finished"] == 1.0 and m["breakage"] == 0.0
    assert m["n_retracts"] == 9.0  # 8 mm in 0.8 mm pecks; the last one finishes the hole
    # Chips never pack deeper than q (plus the sample the agent needs to see the depth).
    assert np.max(tr["packed_chip_mm"]) <= 0.8 + 0.32 * 0.01 + 1e-6
    assert np.min(tr["position_mm"]) == pytest.approx(-0.1, abs=1e-4)
    # The time is the feeding plus 2 x depth / rapid per peck, to within a few samples.
    pecks = 0.8 * np.arange(1, 10)
    expected = 8.0 / 0.32 + float(np.sum(2 * pecks / 3.0)) + 9 * 0.05 / 0.32 + 9 * 2 * 0.1 / 3.0
    assert m["drilling_time_s"] == pytest.approx(expected, abs=0.2)
