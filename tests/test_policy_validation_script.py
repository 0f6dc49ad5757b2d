"""The policy validation script runs end to end on a tiny budget (numbers not judged)."""

import json

import numpy as np
import pytest

from agents.eval.stats import VERDICTS
from tests.benchmark_scripts import load_benchmark, run_benchmark


def test_policy_validation_script_compares_every_seed_with_the_best_tuned_agent(tmp_path):
    out = tmp_path / "v.json"
    ppo = "agents/rl/pretrained/turning_ppo_residual"
    td3 = "agents/rl/pretrained/turning_td3_residual"
    printed = run_benchmark(
        f"policy_validation.py --env machining_envs/Turning-v0 {ppo} {td3} --episodes 2 "
        f"--no-gate --baseline {td3} --out {out}"
    )
    assert "reference AdaptiveFeedControl" in printed
    assert f"{ppo} vs {td3}:" in printed
    data = json.loads(out.read_text())
    assert data["reference"] == "AdaptiveFeedControl" and data["episodes"] == 2
    row = data["policies"][ppo]
    assert sorted(row["seeds"]) == ["0", "1", "2", "3", "4"]
    assert set(row["diffs"]) == {"0.005", "0.01", "0.02"}
    for d in (*row["diffs"].values(), *row["vs_baseline"]["diffs"].values()):
        assert d["n"] == 2 and d["low"] <= d["diff"] <= d["high"]
    assert "vs_baseline" not in data["policies"][td3]
    # each seed is also compared alone (at 2 %, the score's own allowance: the reference's
    # mean less the seed's), and the seeds' differences average to the pooled one
    alone = [row["seeds"][k]["diffs"]["0.02"]["diff"] for k in sorted(row["seeds"])]
    assert row["diffs"]["0.02"]["diff"] == pytest.approx(np.mean(alone))
    for k, entry in row["seeds"].items():
        assert entry["diffs"]["0.02"]["diff"] == pytest.approx(
            data["reference_mean"] - entry["mean"]
        )
        assert entry["verdict"] in VERDICTS and set(entry["diffs"]) == set(row["diffs"])
        assert f"{ppo} seed {k}: counts" in printed
    assert "; alone 0.5%:" in printed


def test_policy_validation_script_compares_tuned_rows_on_their_own_env(tmp_path):
    """``--tuned``: a tuned classical row (here the peck cycle on control="voltage_feed",
    its ENV_KWARGS) against the reference on the same episodes, without policy folders."""
    out = tmp_path / "t.json"
    printed = run_benchmark(
        "policy_validation.py --env machining_envs/MicroDrilling-v0 --tuned VoltagePeck "
        f"--reference NoControl --episodes 2 --out {out}"
    )
    assert "reference NoControl" in printed and "VoltagePeck (tuned): counts" in printed
    data = json.loads(out.read_text())
    assert data["policies"] == {} and set(data["tuned"]) == {"VoltagePeck"}
    row = data["tuned"]["VoltagePeck"]
    assert set(row["diffs"]) == {"0.005", "0.01", "0.02"}
    for d in row["diffs"].values():
        assert d["n"] == 2 and d["low"] <= d["diff"] <= d["high"]


def test_a_shipped_folders_own_policy_counts_as_its_seed_0():
    """end_milling_ppo keeps seed 0 in the folder itself: the script ran seeds 1-4 only."""
    from agents.rl import PRETRAINED_DIR

    module = load_benchmark("policy_validation")
    found = module.seed_models(PRETRAINED_DIR / "end_milling_ppo")
    assert [s for s, _ in found] == [0, 1, 2, 3, 4]
    assert found[0][1].parent.name == "end_milling_ppo"


def test_the_check_can_run_on_validation_episodes_kept_apart(tmp_path):
    module = load_benchmark("policy_validation")
    means = {}
    for args in (("2", "0"), ("1", "0"), ("1", "1")):
        out = tmp_path / f"{'_'.join(args)}.json"
        module.main(
            ["--tuned", "ConstantFeed", "--reference", "AdaptiveFeedControl", "--episodes"]
            + [args[0], "--first-episode", args[1], "--out", str(out)]
        )
        data = json.loads(out.read_text())
        assert data["first_episode"] == int(args[1])
        means[args] = data["reference_mean"]
    # episodes 0 and 1 together are episode 0 and episode 1 apart
    assert means[("2", "0")] == pytest.approx((means[("1", "0")] + means[("1", "1")]) / 2)
    with pytest.raises(SystemExit):
        module.main(["--tuned", "ConstantFeed", "--episodes", "10", "--first-episode", "4995"])
