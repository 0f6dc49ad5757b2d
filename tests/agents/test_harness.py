"""Metrics against hand-made trajectories; the harness's tables and files; the CLI."""

import csv
import subprocess
import sys

import numpy as np
import pytest

from agents import FixedGainPI, VariableGainPI
from agents.bench.cli import main
from agents.eval import Evaluation, evaluate
from machining_envs.core.metrics import regulation_metrics
from tests.conftest import TURNING


def _traj(force, segment=None, dt=0.1, finished_at=None):
    n = len(force)
    t = dt * np.arange(n)
    fin = np.zeros(n, dtype=bool)
    mt = np.full(n, np.nan)
    if finished_at is not None:
        fin[-1] = True
        mt[-1] = finished_at
    return {
        "t_s": t,
        "force_N": np.asarray(force, dtype=float),
        "force_ref_N": np.full(n, 1000.0),
        "depth_mm": np.ones(n),
        "segment": np.zeros(n) if segment is None else np.asarray(segment),
        "finished": fin,
        "machining_time_s": mt,
        "breakage": np.zeros(n, dtype=bool),
        "diverged": np.zeros(n, dtype=bool),
    }


def test_metrics_of_a_constant_error():
    m = regulation_metrics(_traj([0.0] + [900.0] * 100, finished_at=9.95))
    assert m["iae"] == pytest.approx(0.1 * 100 * 0.1)
    assert m["itae"] == pytest.approx(0.1 * 0.1 * sum(0.1 * k for k in range(1, 101)))
    assert m["steady_state_error"] == pytest.approx(0.1)
    assert m["oscillation"] == pytest.approx(0.0, abs=1e-12)
    assert m["n_unsettled"] == 1.0 and m["time_over_limit"] == 0.0
    assert m["machining_time_s"] == 9.95 and m["finished"] == 1.0


def test_metrics_of_a_step_response():
    # Settles into the band at sample 11, overshoots 20 % once, then stays at 1 kN.
    f = [0.0] + [500.0] * 10 + [1000.0, 1200.0] + [1000.0] * 60
    m = regulation_metrics(_traj(f))
    assert m["max_overshoot"] == pytest.approx(0.2)
    assert m["settling_time_s"] == pytest.approx(1.2)
    assert m["time_over_limit"] == pytest.approx(1 / 72)


def test_oscillation_is_measured_and_drift_is_not():
    k = np.arange(200)
    osc = 1000.0 + 300.0 * (-1.0) ** k  # 0.2 s period: the 1 s mean removes it exactly
    drift = np.linspace(500.0, 1500.0, 200)
    assert regulation_metrics(_traj(osc))["oscillation"] == pytest.approx(0.3, rel=1e-9)
    assert regulation_metrics(_traj(drift))["oscillation"] < 0.01


def test_evaluate_table_and_csv(tmp_path):
    ev = Evaluation.concat(
        evaluate(f, TURNING, ["paper_700"], n_episodes=2, seed=0)
        for f in (FixedGainPI.from_env, VariableGainPI.from_env)
    )
    assert len(ev.rows) == 4
    assert {r["agent"] for r in ev.rows} == {"fixed PI Kh=0.02", "adaptive PI K=0.5"}
    md = ev.to_markdown(["iae", "breakage"])
    assert md.count("\n") == 3 and "0/2" in md
    path = tmp_path / "m.csv"
    ev.to_csv(path)
    rows = list(csv.DictReader(open(path)))
    assert len(rows) == 4 and float(rows[0]["iae"]) == pytest.approx(ev.rows[0]["iae"])
    with pytest.raises(ValueError, match="n_episodes"):
        evaluate(FixedGainPI.from_env, TURNING, ["paper_700"], n_episodes=0)


def test_same_seeds_give_every_agent_the_same_workpieces():
    a = evaluate(
        FixedGainPI.from_env, TURNING, ["test"], n_episodes=3, seed=5, keep_trajectories=True
    )
    b = evaluate(
        VariableGainPI.from_env, TURNING, ["test"], n_episodes=3, seed=5, keep_trajectories=True
    )
    for ta, tb in zip(a.trajectories, b.trajectories, strict=True):
        assert ta["workpiece_length_mm"][0] == tb["workpiece_length_mm"][0]
        assert ta["spindle_rpm"][0] == tb["spindle_rpm"][0]


def test_cli_reproduce_turning(tmp_path, capsys):
    assert main(["reproduce", "turning", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "8/8 runs" in out and "paper 0.807" in out
    assert (tmp_path / "reproduce_turning.png").stat().st_size > 10_000


def test_cli_benchmark_quick_writes_report(tmp_path):
    out = subprocess.run(
        [sys.executable, "-m", "agents.bench.cli", "benchmark", "--quick", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "| agent | scenario |" in out.stdout
    assert "margin over" in out.stdout  # the pretrained policies against the best classical
    for name in (
        "benchmark.csv",
        "report.md",
        "Turning-v0_trajectories.png",
        "Turning-v0_metrics.png",
        "reproduce_turning.png",
    ):
        assert (tmp_path / name).stat().st_size > 0, name


def test_cli_rejects_bad_arguments():
    with pytest.raises(SystemExit):
        main(["reproduce", "grinding"])
    with pytest.raises(SystemExit):
        main(["reproduce", "turning", "--sensor-gain", "-3"])


def test_primary_score_table_gives_learned_agents_a_paired_margin():
    from agents.eval import primary_score_table

    def row(agent, seed, t, over=0.0):
        return {
            "agent": agent,
            "scenario": "test",
            "seed": seed,
            "machining_time_s": t,
            "finished": 1.0,
            "breakage": 0.0,
            "time_over_limit": over,
            "itae": 1.0,
        }

    ev = Evaluation()
    ev.rows = (
        [row("A", s, t) for s, t in ((1, 10.0), (2, 20.0), (3, 30.0))]
        + [row("B", s, t) for s, t in ((1, 12.0), (2, 22.0), (3, 32.0))]
        + [row("P", 1, 11.0), row("P", 2, 19.0), row("P", 3, 30.0, over=0.05)]
    )
    table = primary_score_table(ev, "test", 100.0, learned=["P"])
    assert "margin over A ± s.e." in table
    # P against A, seed by seed: -1, +1, and its third episode does not count (100 - 30 = -70).
    line = next(x for x in table.splitlines() if x.startswith("| P |"))
    d = np.array([-1.0, 1.0, -70.0])
    assert f"{d.mean():+.4g} ± {np.std(d, ddof=1) / np.sqrt(3):.2g}" in line
    assert table.splitlines()[4].endswith("| |")  # classical agents: no margin
    assert "margin" not in primary_score_table(ev, "test", 100.0)
