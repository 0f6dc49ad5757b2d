"""The seed gate: its rule on hand-made episode rows, the edge episodes it builds, and the
fixed replacement rule for failing seeds."""

import math

import pytest

from agents.rl.gate import (
    EDGES,
    GATE_SHARE,
    GateResult,
    gate_scenarios,
    gate_verdict,
    gated_seeds,
    next_seeds,
    train_range,
)
from machining_envs.core.score import REGULATION_SCORE


def _row(counts=True, overloaded=0.0, over=0.0):
    """A regulation episode that counts (finished, nothing broke, no time over the limit)
    unless told otherwise."""
    return {
        "machining_time_s": 30.0,
        "finished": 1.0 if counts else 0.0,
        "breakage": 0.0,
        "diverged": 0.0,
        "time_over_limit": over,
        "overloaded": overloaded,
    }


def test_nine_of_ten_counting_passes_eight_of_ten_fails():
    assert GATE_SHARE == 0.9
    v = gate_verdict([_row()] * 9 + [_row(counts=False)], REGULATION_SCORE)
    assert v.passed and (v.n, v.counting, v.overloaded) == (10, 9, 0)
    assert v.counting_share == pytest.approx(0.9)
    v = gate_verdict([_row()] * 8 + [_row(counts=False)] * 2, REGULATION_SCORE)
    assert not v.passed and v.counting == 8


def test_a_single_overload_fails_even_when_every_other_episode_counts():
    rows = [_row()] * 39 + [_row(overloaded=1.0)]
    v = gate_verdict(rows, REGULATION_SCORE)
    assert v.overloaded == 1 and not v.passed
    # and an episode over the limit too often does not count
    v = gate_verdict([_row()] * 17 + [_row(over=0.05)] * 3, REGULATION_SCORE)
    assert v.counting == 17 and not v.passed


def test_the_verdict_is_grouped_by_label_and_checks_its_inputs():
    rows = [_row(), _row(counts=False), _row(), _row()]
    v = gate_verdict(rows, REGULATION_SCORE, labels=["validation", "rpm=low", "rpm=low", "x"])
    assert v.by_group == {
        "validation": {"n": 1, "counting": 1, "overloaded": 0},
        "rpm=low": {"n": 2, "counting": 1, "overloaded": 0},
        "x": {"n": 1, "counting": 1, "overloaded": 0},
    }
    assert isinstance(v, GateResult) and not v.passed  # 3 of 4
    assert v.as_dict()["counting_share"] == 0.75
    with pytest.raises(ValueError, match="rows"):
        gate_verdict([], REGULATION_SCORE)
    with pytest.raises(ValueError, match="share"):
        gate_verdict(rows, REGULATION_SCORE, share=1.5)
    with pytest.raises(ValueError, match="labels"):
        gate_verdict(rows, REGULATION_SCORE, labels=["a"])


def test_replacement_seeds_follow_every_seed_tried():
    assert next_seeds([0, 1, 2, 3, 4], 2) == [5, 6]
    assert next_seeds([3, 0], 1) == [4]
    assert next_seeds([], 3) == [0, 1, 2]


def _fake_gate(failing):
    def gate(model):
        ok = model not in failing
        return GateResult(ok, 10, 10 if ok else 5, 0)

    return gate


def test_failing_seeds_are_replaced_by_the_next_ones_and_reported():
    rounds = []

    def train_many(seeds):
        rounds.append(list(seeds))
        return {s: s for s in seeds}  # the "model" of a seed is the seed

    out = gated_seeds([0, 1, 2, 3, 4], train_many, _fake_gate({1, 3, 5}))
    assert rounds == [[0, 1, 2, 3, 4], [5, 6], [7]]
    assert out["passed"] == [0, 2, 4, 6, 7] and out["failed"] == [1, 3, 5]
    assert out["replacements"] == [5, 6, 7] and out["complete"]
    assert out["verdicts"][1]["passed"] is False


def test_replacements_stop_at_the_budget_and_say_the_set_is_incomplete():
    out = gated_seeds([0, 1], lambda s: {k: k for k in s}, _fake_gate({0, 1, 2, 3}))
    assert out["replacements"] == [2, 3] and not out["complete"]
    assert out["passed"] == []
    out = gated_seeds([0], lambda s: {k: k for k in s}, _fake_gate({0}), max_replacements=0)
    assert out["replacements"] == [] and not out["complete"]
    with pytest.raises(ValueError, match="seeds"):
        gated_seeds([1, 1], lambda s: {}, _fake_gate(set()))


@pytest.mark.parametrize("env_id", sorted(EDGES))
def test_edge_episodes_are_validation_draws_with_one_field_at_a_train_end(env_id):
    groups = gate_scenarios(env_id, n_validation=4, per_edge=2)
    assert groups[0] == ("validation", ["validation"], 5000, 4)
    assert [g[0] for g in groups[1:]] == [e.label for e in EDGES[env_id]]
    for (_label, scenarios, seed, n), edge in zip(groups[1:], EDGES[env_id], strict=True):
        assert seed == 5000 and n == 1 and len(scenarios) == 2
        lo, hi = train_range(env_id, edge.field)
        want = lo if edge.end == "low" else hi
        for sc in scenarios:
            if edge.field == "depth":
                assert sc.profile.max_depth_mm == pytest.approx(want)
            else:
                assert getattr(sc, edge.field) == want
            assert "test" not in sc.name and "ood" not in sc.name
    # the two draws differ (they are validation episodes 5000 and 5001)
    a, b = groups[1][1]
    assert a != b


def test_train_ranges_are_the_scenario_modules():
    assert train_range("machining_envs/Turning-v0", "spindle_rpm") == (245.0, 700.0)
    assert train_range("machining_envs/EndMilling-v0", "spindle_scale") == (0.67, 1.6)
    lo, hi = train_range("machining_envs/MicroDrilling-v0", "aspect_ratio")
    assert lo < hi and math.isfinite(hi)
    with pytest.raises(ValueError, match="field"):
        train_range("machining_envs/MicroDrilling-v0", "spindle_rpm")


@pytest.mark.slow
def test_a_gated_sweep_trains_gates_and_records_its_seeds(tmp_path):
    """Two seeds of a tiny Turning-v0 training: each gated on 2 validation and 1 episode
    per edge; gate.json records every verdict and the rule."""
    pytest.importorskip("ray")
    import json

    from agents.rl.gate import gated_sweep
    from agents.rl.sweep import SweepSettings

    settings = SweepSettings("machining_envs/Turning-v0", seeds=[0, 1], n_timesteps=512, workers=2)
    out = gated_sweep(
        settings, tmp_path / "s", n_validation=2, per_edge=1, max_replacements=1, verbose=False
    )
    saved = json.loads((tmp_path / "s" / "gate.json").read_text())
    assert saved["asked"] == [0, 1] and set(saved["verdicts"]) >= {"0", "1"}
    assert sorted(out["passed"] + out["failed"]) == sorted(int(s) for s in saved["verdicts"])
    assert len(out["replacements"]) <= 1
    for v in out["verdicts"].values():
        assert v["n"] == 2 + len(EDGES["machining_envs/Turning-v0"])


def test_a_classical_agent_meets_the_same_gate_on_its_own_env():
    """``gate_agent`` runs the gate's episodes (validation first, then each edge) with the
    env's own score; PeckDrilling on its feed-controlled env."""
    from agents.bench.tune import tuned_factory
    from agents.drilling import PeckDrilling
    from agents.rl.gate import gate_agent

    env_id = "machining_envs/MicroDrilling-v0"
    v = gate_agent(tuned_factory(PeckDrilling, env_id), env_id, {"control": "feed"}, 2, 1)
    assert v.n == 2 + len(EDGES[env_id])
    assert list(v.by_group) == ["validation"] + [e.label for e in EDGES[env_id]]
    assert 0 <= v.counting <= v.n and v.passed == (v.counting >= 0.9 * v.n and not v.overloaded)


def test_the_gate_takes_the_verdict_rules_allowances():
    rows = [_row()] * 9 + [_row(over=0.01)]  # one episode 1 % of its steps over the limit
    assert gate_verdict(rows, REGULATION_SCORE).counting == 10
    assert gate_verdict(rows, REGULATION_SCORE, allowance=0.005).counting == 9


def test_a_score_without_a_share_over_the_limit_has_no_ceiling():
    """Contouring-v0 scores the largest error itself: its rows may carry ``overloaded``,
    but neither the score nor the gate counts it."""
    import dataclasses

    error_score = dataclasses.replace(REGULATION_SCORE, over_key=None)
    v = gate_verdict([_row(overloaded=1.0)] * 10, error_score)
    assert v.passed and v.overloaded == 0 and v.counting == 10
