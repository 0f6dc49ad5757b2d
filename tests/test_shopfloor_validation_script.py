"""The shop-floor validation script runs end to end on a tiny budget (numbers not judged)."""

import json

from tests.benchmark_scripts import run_benchmark


def test_shopfloor_validation_script_compares_with_the_constant_feed(tmp_path):
    out = tmp_path / "x.json"
    printed = run_benchmark(
        "shopfloor_validation.py --env machining_envs/Turning-v0 --trials 1 --episodes 1 "
        f"--validation 2 --only afc --out {out}"
    )
    assert "AFC (force/torque channel) vs constant feed" in printed
    data = json.loads(out.read_text())
    assert set(data) == {"constant feed", "AFC (force/torque channel)"}
    d = data["AFC (force/torque channel)"]["vs_constant_feed"]
    assert d["n"] == 2 and d["low"] <= d["diff"] <= d["high"]
    assert "afc_min_feed_factor" in data["AFC (force/torque channel)"]["afc_log_means"]
