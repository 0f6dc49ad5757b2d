"""The evaluation harness (``agents.eval``): tables and files, the same workpieces for every agent."""

import csv

import pytest

from agents import FixedGainPI, VariableGainPI
from agents.eval import Evaluation, evaluate
from tests.helpers import TURNING


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
