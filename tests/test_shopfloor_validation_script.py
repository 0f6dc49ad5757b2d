"""The shop-floor validation script runs end to end on a tiny budget (numbers not judged)."""

from tests.benchmark_scripts import run_benchmark_json


def test_shopfloor_validation_script_compares_with_the_constant_feed(tmp_path):
    printed, data = run_benchmark_json(
        "shopfloor_validation.py --env machining_envs/Turning-v0 --trials 1 --episodes 1 "
        "--validation 2 --only afc",
        tmp_path / "x.json",
    )
    assert "AFC (force/torque channel) vs constant feed" in printed
    assert set(data) == {"constant feed", "AFC (force/torque channel)"}
    d = data["AFC (force/torque channel)"]["vs_constant_feed"]
    assert d["n"] == 2 and d["low"] <= d["diff"] <= d["high"]
    assert "afc_min_feed_factor" in data["AFC (force/torque channel)"]["afc_log_means"]


def test_shopfloor_validation_from_the_tuned_file(tmp_path):
    """``--tuned``: the shipped file's rows on validation, each against the machine's
    constant feed at every allowance, with the reasons episodes fail."""
    from agents.bench.tune import SHOPFLOOR_TUNED_FILE

    printed, data = run_benchmark_json(
        "shopfloor_validation.py --env machining_envs/ContouringFeed-v0 "
        f"--tuned {SHOPFLOOR_TUNED_FILE} --validation 2",
        tmp_path / "x.json",
    )
    assert "| LookAheadFeed |" in printed
    la = data["agents"]["LookAheadFeed"]
    assert len(la["vs_constant_feed"]) == 3 and la["verdict"]
    assert set(la["fails"]) == {"unfinished", "broken", "overloaded", "over the limit"}
    assert data["env_kwargs"]["actuation"]["max_rate_per_s"] == 2.5


def test_shopfloor_ceiling_script_sweeps_the_constant_feed(tmp_path):
    printed, rows = run_benchmark_json(
        "shopfloor_ceiling.py --env machining_envs/Turning-v0 --setpoints 0.8 --episodes 2",
        tmp_path / "c.json",
    )
    assert "| shop floor | 0.8 |" in printed
    assert [r["machine"] for r in rows] == ["ideal", "shop floor"]
    assert all(len(r["kept"]) == 3 for r in rows)
