"""``machining-bench tune --machine`` and ``train --machine``."""

import json
from pathlib import Path

import agents.rl
from agents.bench.cli import main
from machining_envs.core.actuation import SHOPFLOOR_ACTUATION

EXAMPLE = str(Path(__file__).resolve().parents[2] / "docs" / "my_cnc.yml")


def test_tune_for_the_machine_records_it(tmp_path):
    out = tmp_path / "tuned.json"
    args = ["tune", "--env", "machining_envs/Turning-v0", "--trials", "1", "--episodes", "1"]
    assert main([*args, "--machine", EXAMPLE, "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["machine"]["name"] == "my_lathe"
    assert data["machine"]["actuation"]["delay_steps"] == SHOPFLOOR_ACTUATION.delay_steps
    assert data["command"].endswith(f"--machine {EXAMPLE}")
    entries = data["envs"]["machining_envs/Turning-v0"]
    assert "AdaptiveFeedControl" in entries and "ConstantFeed" in entries


def test_bad_machine_file_is_refused(tmp_path):
    bad = tmp_path / "bad.yml"
    bad.write_text("spindle: 3\n")
    assert main(["tune", "--env", "machining_envs/Turning-v0", "--machine", str(bad)]) == 2
    args = ["train", "--env", "machining_envs/Turning-v0", "--out", str(tmp_path / "r")]
    assert main([*args, "--machine", str(bad)]) == 2


def test_train_passes_the_machine_to_the_envs(tmp_path, monkeypatch):
    seen = {}

    def fake_train(env_id, algo, out, **kw):
        seen.update(kw)

    monkeypatch.setattr(agents.rl, "train", fake_train)
    args = ["train", "--env", "machining_envs/Turning-v0", "--out", str(tmp_path / "r")]
    assert main([*args, "--machine", EXAMPLE]) == 0
    kw = seen["overrides"]["env_kwargs"]
    assert kw["actuation"]["max_rate_per_s"] == SHOPFLOOR_ACTUATION.max_rate_per_s
    assert kw["spindle_power_W"] == 2200.0


def test_tune_at_the_strictest_allowance_records_it(tmp_path):
    """``--allowance 0.005``: the objective counts an episode at the verdict's strictest
    allowance; the file states it (budget and command) and keeps each env's machine
    options."""
    out = tmp_path / "tuned.json"
    args = [
        "tune",
        "--env",
        "machining_envs/ContouringFeed-v0",
        "--trials",
        "1",
        "--episodes",
        "1",
        "--allowance",
        "0.005",
    ]
    assert main([*args, "--machine", EXAMPLE, "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["budget"]["allowance"] == 0.005
    assert data["command"].endswith("--allowance 0.005")
    env_id = "machining_envs/ContouringFeed-v0"
    assert data["commands"][env_id] == data["command"]
    assert data["env_kwargs"][env_id]["actuation"]["max_rate_per_s"] == 2.5  # feed_override
    assert set(data["envs"][env_id]) == {"ConstantOverride", "LookAheadFeed", "ContourAFC"}


def test_tuning_budget_allowance_is_checked():
    import pytest

    from agents.bench.tune import TuningBudget

    assert "allowance" not in TuningBudget().as_dict()  # the protocol's 2 %: files unchanged
    with pytest.raises(ValueError, match="allowance"):
        TuningBudget(allowance=0.03)
    with pytest.raises(SystemExit) as e:  # argparse names the choices
        main(["tune", "--allowance", "0.03"])
    assert e.value.code == 2
