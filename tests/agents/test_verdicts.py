"""The verdict column: an agent against the reference at every allowance of steps over the
limit, on synthetic paired scores; each training seed's share of counting episodes."""

import numpy as np
import pytest

from agents.eval.stats import VERDICTS, allowance_sweep, seed_count_shares, verdict
from machining_envs.core.score import ALLOWANCES, REGULATION_SCORE
from tests.helpers import episode_rows


def test_the_rule_on_intervals():
    assert verdict([(0.1, 1.0)] * 3) == "better"
    assert verdict([(-1.0, -0.1)] * 3) == "worse"
    assert verdict([(-1.0, 1.0)] * 3) == "unresolved"
    assert verdict([(-1.0, 1.0), (-1.0, 1.0), (0.1, 1.0)]) == "depends on the allowance"
    assert verdict([(-2.0, -1.0), (-1.0, 1.0), (0.1, 1.0)]) == "depends on the allowance"
    assert set(VERDICTS) == {"better", "worse", "depends on the allowance", "unresolved"}
    with pytest.raises(ValueError, match="intervals"):
        verdict([])


def test_a_win_at_two_per_cent_that_is_a_loss_at_half_a_per_cent_depends_on_it():
    """The agent is 5 s faster on every episode but runs 1.5 % of its steps over the limit:
    at the 2 % allowance every episode counts and it wins; at 0.5 % and 1 % none counts and
    it is charged the failure cost (200 s) on each: a loss. The verdict says so."""
    rng = np.random.default_rng(0)
    base = 60.0 + rng.normal(0.0, 5.0, 60)
    ref = episode_rows(base, np.zeros(60))
    agent = episode_rows(base - 5.0, np.full(60, 0.015))
    diffs, v = allowance_sweep(ref, agent, REGULATION_SCORE, 200.0)
    assert [d["diff"] > 0 for d in diffs] == [False, False, True]
    assert diffs[0]["high"] < 0 and diffs[2]["low"] > 0
    assert v == "depends on the allowance"
    # The same agent inside 0.5 %: better at every allowance.
    clean = episode_rows(base - 5.0, np.full(60, 0.004))
    assert allowance_sweep(ref, clean, REGULATION_SCORE, 200.0)[1] == "better"
    # Noise either way: unresolved.
    noisy = episode_rows(base + rng.normal(0.0, 5.0, 60), np.zeros(60))
    assert allowance_sweep(ref, noisy, REGULATION_SCORE, 200.0)[1] == "unresolved"
    # Slower everywhere: worse.
    slow = episode_rows(base + 5.0, np.zeros(60))
    assert allowance_sweep(ref, slow, REGULATION_SCORE, 200.0)[1] == "worse"


def test_the_ceiling_makes_an_episode_fail_at_every_allowance():
    """An episode whose load passed the overload ceiling does not count, whatever its share
    of steps over the limit: a fast agent that overloads every cut loses at every
    allowance."""
    base = np.linspace(50.0, 70.0, 40)
    ref = episode_rows(base, np.zeros(40))
    over = episode_rows(base - 10.0, np.zeros(40), overloaded=1.0)
    assert not any(REGULATION_SCORE.counts(r, a) for r in over for a in ALLOWANCES)
    assert allowance_sweep(ref, over, REGULATION_SCORE, 200.0)[1] == "worse"


def test_each_seed_keeps_its_share_of_counting_episodes():
    good = episode_rows(np.full(10, 30.0), np.zeros(10), policy_seed=0)
    bad = episode_rows(np.full(10, 30.0), [0.0] * 7 + [0.03] * 3, policy_seed=1)
    shares = seed_count_shares(good + bad, REGULATION_SCORE)
    assert shares == {0: 1.0, 1: 0.7}
    assert seed_count_shares(bad, REGULATION_SCORE, allowance=0.05) == {1: 1.0}


def test_the_reference_is_the_tuned_agent_with_the_lowest_validation_score():
    from agents.bench.tune import best_tuned

    tuned = {"envs": {"e": {"A": {"validation_score": 3.0}, "B": {"validation_score": 2.0}}}}
    assert best_tuned("e", tuned) == "B"
    assert best_tuned("other", tuned) is None
    assert best_tuned("machining_envs/Turning-v0") == "AdaptiveFeedControl"


def test_allowance_cells_print_each_difference_with_its_interval():
    from agents.eval.stats import allowance_cells

    d = {"diff": 1.234, "low": -0.5, "high": 2.0}
    assert allowance_cells([d, d], allowances=(0.005, 0.02)) == (
        "0.5%: +1.23 [-0.50, +2.00], 2.0%: +1.23 [-0.50, +2.00]"
    )
