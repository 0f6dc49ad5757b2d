"""Contouring metrics against closed forms; the constant-override baseline keeps the tolerance."""

import math

import gymnasium as gym
import numpy as np
import pytest

from agents.contouring import BASELINE_OVERRIDE, CALIBRATION_SEEDS, ConstantOverride, _max_error
from machining_envs.contouring.metrics import circle_radius_errors, contouring_metrics
from machining_envs.contouring.paths import Arc, Path
from machining_envs.core.lti import zoh


def _first_order_circle(feed, radius, tau, ts=2e-4):
    """Both axes first order, x/r = 1/(tau s + 1), following one turn of the circle at
    ``feed``: the trajectory as the env records it (exact ZOH, table starting at rest on
    the path; the start-up transient is over long before the quarter turn the metric skips)."""
    path = Path([Arc((0.0, 0.0), radius, 0.0, 2 * math.pi)])
    n = int(path.length / feed / ts)
    s = np.minimum(np.arange(n + 1) * feed * ts, path.length)
    rx, ry = path.points(s)
    phi, gam = zoh(np.array([[-1.0 / tau]]), np.array([[1.0 / tau]]), ts)
    x = np.empty(n + 1)
    y = np.empty(n + 1)
    x[0], y[0] = rx[0], ry[0]
    for k in range(n):
        x[k + 1] = phi[0, 0] * x[k] + gam[0, 0] * rx[k]
        y[k + 1] = phi[0, 0] * y[k] + gam[0, 0] * ry[k]
    return {
        "t_s": np.arange(n + 1) * ts,
        "x_mm": x,
        "y_mm": y,
        "path_s_mm": s,
        "path_length_mm": np.full(n + 1, path.length),
        "circle_cx_mm": np.zeros(n + 1),
        "circle_cy_mm": np.zeros(n + 1),
        "circle_radius_mm": np.full(n + 1, radius),
    }


@pytest.mark.parametrize(
    "feed,radius,tau",
    [(50.0, 10.0, 1 / 30), (20.0, 5.0, 1 / 40), (50.0, 10.0, 0.02)],
)
def test_radius_reduction_of_a_first_order_axis_matches_f2t2_over_2r(feed, radius, tau):
    """Paper §3.2 (after Na, Choi & Jang): dR ~ F^2 T^2 / (2R) for first-order axes.

    The approximation drops terms of order (w T)^4; at w T <= 0.17 here it is within 3 % of
    the exact steady radius R / sqrt(1 + (w T)^2); the test allows the 10 % the issue asks.
    """
    traj = _first_order_circle(feed, radius, tau)
    dr, ellipse = circle_radius_errors(traj)
    formula = feed**2 * tau**2 / (2 * radius)
    assert dr == pytest.approx(formula, rel=0.10)
    w = feed / radius
    assert dr == pytest.approx(radius * (1 - 1 / math.sqrt(1 + (w * tau) ** 2)), rel=0.01)
    assert ellipse < 0.02 * dr  # equal axes: a circle, no ellipse


def test_unequal_axes_make_an_ellipse():
    a = _first_order_circle(50.0, 10.0, 1 / 30)
    b = _first_order_circle(50.0, 10.0, 1 / 20)
    traj = dict(a, y_mm=b["y_mm"])  # Y lags more than X
    dr, ellipse = circle_radius_errors(traj)
    # Paper's a, b: half-axes of the ellipse from the axes' gains and phases.
    w = 5.0
    rx, ry = 10 / math.hypot(1, w / 30), 10 / math.hypot(1, w / 20)
    px, py = math.atan(w / 30), math.atan(w / 20)
    c = math.cos(px - py)
    big = 0.5 * (
        math.sqrt(rx**2 + ry**2 + 2 * rx * ry * c) + math.sqrt(rx**2 + ry**2 - 2 * rx * ry * c)
    )
    small = 0.5 * (
        math.sqrt(rx**2 + ry**2 + 2 * rx * ry * c) - math.sqrt(rx**2 + ry**2 - 2 * rx * ry * c)
    )
    assert ellipse == pytest.approx(0.5 * (big - small), rel=0.02)
    assert dr == pytest.approx(10 - 0.5 * (big + small), rel=0.05)


def test_contouring_metrics_of_a_hand_made_run():
    n = 101
    t = 0.01 * np.arange(n)
    eps = np.full(n, 0.002)
    eps[0] = 0.0
    eps[50] = 0.01
    trk = np.full(n, 0.3)
    finished = np.zeros(n, dtype=bool)
    finished[-1] = True
    mt = np.full(n, math.nan)
    mt[-1] = 0.995
    traj = {
        "t_s": t,
        "contour_error_mm": eps,
        "tracking_error_mm": trk,
        "torque_sq_Nm2": np.full(n, 4.0),
        "command_x_mm_s": np.linspace(0, 30, n),
        "command_y_mm_s": -np.linspace(0, 40, n),
        "finished": finished,
        "machining_time_s": mt,
        "diverged": np.zeros(n, dtype=bool),
        "x_mm": np.zeros(n),
        "y_mm": np.zeros(n),
    }
    m = contouring_metrics(traj)
    assert m["max_contour_error_mm"] == 0.01
    assert m["rms_contour_error_mm"] == pytest.approx(math.sqrt((99 * 0.002**2 + 0.01**2) / 100))
    assert m["max_tracking_error_mm"] == 0.3 and m["rms_tracking_error_mm"] == pytest.approx(0.3)
    assert math.isnan(m["radius_reduction_mm"]) and math.isnan(m["ellipse_mm"])
    assert m["cycle_time_s"] == 0.995 and m["finished"] == 1.0 and m["diverged"] == 0.0
    assert m["effort_rms_Nm"] == pytest.approx(2.0)
    assert m["peak_command_mm_s"] == pytest.approx(40.0)
    assert math.isnan(m["time_over_tolerance"])
    traj["contour_tolerance_mm"] = np.full(n, 0.005)
    traj["peak_contour_error_mm"] = eps * 2
    traj["cost"] = (traj["peak_contour_error_mm"] > 0.005).astype(float)  # as the env gives it
    m = contouring_metrics(traj)
    assert m["max_contour_error_mm"] == 0.02
    assert m["time_over_tolerance"] == pytest.approx(1 / 100)


@pytest.mark.parametrize("servo,n_paths", [("hinf", 12), ("pi", 4)])
def test_constant_override_baseline_keeps_the_tolerance_on_training_paths(servo, n_paths):
    """The stored baseline override keeps the default tolerance on training paths it was
    calibrated on (a spread sample of them, always including the path that bounds it), and
    it is the largest such override to the calibration's resolution: 0.02 more breaks the
    tolerance on the bounding path."""
    env = gym.make("machining_envs/ContouringFeed-v0", servo=servo)
    base = env.unwrapped
    agent = ConstantOverride.from_env(env)
    assert agent.override == BASELINE_OVERRIDE[servo] > 0
    seeds = sorted(
        {*CALIBRATION_SEEDS[:: len(CALIBRATION_SEEDS) // n_paths], *BINDING_SEEDS[servo]}
    )
    worst = 0.0
    for seed in seeds:
        base.reset(seed=seed, options={"scenario": "train"})
        err = _max_error(env, base.scenario, agent.override)
        worst = max(worst, err)
        assert err <= base.tolerance_mm, (seed, err)
    faster = []
    for seed in BINDING_SEEDS[servo]:
        base.reset(seed=seed, options={"scenario": "train"})
        faster.append(_max_error(env, base.scenario, agent.override + 0.02))
    assert max(faster) > base.tolerance_mm
    print(
        f"{servo}: override {agent.override}, worst {1000 * worst:.2f} um of "
        f"{1000 * base.tolerance_mm:g} um"
    )


#: The calibration paths whose bisection set the stored override (from ``python -m
#: agents.contouring``'s log).
BINDING_SEEDS = {"pi": (6,), "hinf": (54,)}
