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
