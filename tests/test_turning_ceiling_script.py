"""The Turning-v0 ceiling script: its two measures, and a tiny end-to-end run."""

import numpy as np
import pytest

from tests.benchmark_scripts import load_benchmark, run_benchmark


@pytest.fixture(scope="module")
def ceiling():
    return load_benchmark("turning_ceiling")


def test_steps_over_the_limit_are_placed_against_segment_changes(ceiling):
    traj = {"cost": [0, 1, 0, 0, 0, 0, 0, 1, 1], "segment": [0, 0, 0, 1, 1, 1, 1, 1, 1]}
    # the change is at step 3: step 1 is 2 away, steps 7 and 8 are 4 and 5 away
    assert ceiling.steps_near_segment_change(traj, 2) == (1, 3)
    assert ceiling.steps_near_segment_change(traj, 5) == (3, 3)
    assert ceiling.steps_near_segment_change({"cost": [1, 1], "segment": [0, 0]}, 9) == (0, 2)
    assert ceiling.steps_near_segment_change({"cost": [0, 0], "segment": [0, 1]}, 9) == (0, 0)


def test_the_after_the_fact_choice_takes_each_episodes_best_reference(ceiling):
    charged = {0.8: np.array([[10.0, 9.0], [200.0, 7.0]]), 0.9: np.array([[8.0, 9.5], [6.0, 7.0]])}
    gain = ceiling.hindsight_gain(charged, 0.8)
    assert gain.tolist() == [[2.0, 0.0], [194.0, 0.0]]
    assert (ceiling.hindsight_gain(charged, 0.9) >= 0).all()


def test_turning_ceiling_script_runs_on_validation():
    printed = run_benchmark("turning_ceiling.py --episodes 2 --refs 0.7 0.9")
    assert "(tuned)" in printed and "reference 0.700" in printed and "reference 0.900" in printed
    assert "steps over the limit lie within 1.5 s" in printed
    assert "after the fact, paired gain over the tuned AFC" in printed
