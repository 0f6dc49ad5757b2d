"""The operating-points script: what it changes in a cut, and a tiny end-to-end run."""

import pytest

from tests.benchmark_scripts import load_benchmark, run_benchmark
from tests.helpers import MILLING, TURNING


@pytest.fixture(scope="module")
def points():
    return load_benchmark("operating_points")


def test_each_point_changes_one_thing_of_a_validation_cut(points):
    (cut,) = points.base_scenarios(MILLING, 1, 5500)
    deeper = points.moved(MILLING, cut, "deepest", 4.0)
    depths = (*deeper.profile.start_depths_mm, *deeper.profile.end_depths_mm)
    assert max(depths) == pytest.approx(4.0)
    assert deeper.profile.edges_mm == cut.profile.edges_mm
    assert deeper.spindle_scale == cut.spindle_scale
    harder = points.moved(MILLING, cut, "coefficient", 1.25)
    assert harder.torque_coefficient_scale == pytest.approx(
        min(cut.torque_coefficient_scale * 1.25, 2.0)
    )
    assert harder.profile == cut.profile
    (tcut,) = points.base_scenarios(TURNING, 1, 5500)
    slow = points.moved(TURNING, tcut, "spindle_rpm", 300.0)
    assert slow.spindle_rpm == 300.0 and slow.profile == tcut.profile


def test_operating_points_script_runs_the_learned_row_against_the_reference():
    printed = run_benchmark(
        "operating_points.py --env machining_envs/Turning-v0 --episodes 2 --points Kf_x_1.25"
    )
    assert "turning_ppo_residual_ref85 against AdaptiveFeedControl (tuned)" in printed
    (line,) = [x for x in printed.splitlines() if x.startswith("Kf x 1.25:")]
    assert "reference keeps" in line and "0.5%:" in line and "2.0%:" in line
