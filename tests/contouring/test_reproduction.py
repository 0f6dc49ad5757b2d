"""The contouring paper's results (Choi et al., Fig. 4-8) reproduced by the agents on the env.

One run of ``reproduce_contouring`` (the PI and H-infinity agents on Contouring-v0 over the
paper's five tests) feeds every assertion here.
"""

import pytest

from agents.bench.cli import main
from agents.bench.contouring import CONTOUR_RATIO, reproduce_contouring
from agents.bench.declarations import process


@pytest.fixture(scope="module")
def repro(tmp_path_factory):
    out = tmp_path_factory.mktemp("repro")
    results = reproduce_contouring(out, verbose=False)
    return out, {r["experiment"].scenario: r for r in results}


@pytest.mark.parametrize("scenario", ["paper_corner", "paper_circle", "paper_involute"])
def test_hinf_contour_error_at_least_5x_smaller_than_pi(repro, scenario):
    r = repro[1][scenario]
    pi, hinf = r["pi"]["max_contour_error_mm"], r["hinf"]["max_contour_error_mm"]
    print(f"{scenario}: max contour error PI {1000 * pi:.2f} um, H-inf {1000 * hinf:.2f} um")
    assert pi >= CONTOUR_RATIO * hinf
    assert r["pi"]["finished"] == r["hinf"]["finished"] == 1.0


def test_circle_pi_shrinks_and_turns_into_an_ellipse(repro):
    r = repro[1]["paper_circle"]
    assert r["pi"]["radius_reduction_mm"] > 0.0
    assert r["pi"]["ellipse_mm"] >= 5 * r["hinf"]["ellipse_mm"]
    assert abs(r["hinf"]["radius_reduction_mm"]) < 0.2 * r["pi"]["radius_reduction_mm"]


def test_step_and_load_step(repro):
    step = repro[1]["paper_step"]
    assert step["hinf"]["settling_time_s"] < step["pi"]["settling_time_s"]
    assert step["hinf"]["overshoot"] <= 0.02 and step["pi"]["overshoot"] <= 0.001
    load = repro[1]["paper_step_load"]
    assert load["hinf"]["load_deviation_mm"] < load["pi"]["load_deviation_mm"]


def test_every_experiment_matches_and_the_figure_is_written(repro):
    out, by = repro
    assert all(r["match"] for r in by.values()), {k: r["match"] for k, r in by.items()}
    assert (out / "reproduce_contouring.png").stat().st_size > 10_000
    g = next(iter(by.values()))["gammas"]
    assert all(1.0 < v < 20.0 for v in g)


def test_cli_registry_names_the_reproduction(capsys):
    assert process("contouring").reproduce is reproduce_contouring
    assert main(["reproduce", "contouring", "--sensor-gain", "15"]) == 2  # a usage error
    assert "--sensor-gain applies to 'reproduce turning' only" in capsys.readouterr().err


def test_pi_circle_matches_the_papers_ellipse_formula(repro):
    """Paper §3.2: steady outputs x = Rx cos(wt - psi_x), y = Ry sin(wt - psi_y) trace an
    ellipse with half-axes a, b = (sqrt(Rx^2 + Ry^2 + 2 Rx Ry cos d) +- sqrt(Rx^2 + Ry^2 -
    2 Rx Ry cos d)) / 2, d = psi_x - psi_y. Gains and phases here come from the PI loops'
    discrete frequency responses at w = F / R; the env's circle must show R - (a + b)/2
    and (a - b)/2 (within 2 %: the discrete set point and the finite run)."""
    import numpy as np

    from machining_envs.contouring.plant import ContouringParams
    from machining_envs.contouring.servo import closed_loop, pi_design

    p = ContouringParams()
    w = 50.0 / 10.0
    gains = []
    for axis in "xy":
        a, b, cy, _, _ = closed_loop(p, pi_design(p, axis))
        z = np.exp(1j * w * p.sample_time_s)
        gains.append((cy @ np.linalg.solve(z * np.eye(a.shape[0]) - a, b[:, :1]))[0, 0])
    rx, ry = abs(gains[0]) * 10.0, abs(gains[1]) * 10.0
    d = np.angle(gains[0]) - np.angle(gains[1])
    s1 = np.sqrt(rx**2 + ry**2 + 2 * rx * ry * np.cos(d))
    s2 = np.sqrt(rx**2 + ry**2 - 2 * rx * ry * np.cos(d))
    big, small = 0.5 * (s1 + s2), 0.5 * (s1 - s2)
    r = repro[1]["paper_circle"]["pi"]
    assert r["radius_reduction_mm"] == pytest.approx(10.0 - 0.5 * (big + small), rel=0.02)
    assert r["ellipse_mm"] == pytest.approx(0.5 * (big - small), rel=0.02)
