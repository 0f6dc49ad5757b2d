"""The declared pieces of turning's and milling's benchmarks: the robustness grid (each cell
one constant depth at the grid's speed) and the MPC oracle, both picklable (``--jobs`` sends
specs to other processes)."""

import pickle

import pytest

from agents.bench.milling import PROCESS as MILLING_PROCESS
from agents.bench.turning import PROCESS as TURNING_PROCESS


@pytest.mark.parametrize(
    "process, speed_field, length_mm",
    [(TURNING_PROCESS, "spindle_rpm", 45.0), (MILLING_PROCESS, "spindle_scale", 40.0)],
    ids=["turning", "milling"],
)
def test_grid_cells_are_constant_depth_cuts_at_the_grid_speed(process, speed_field, length_mm):
    grid = process.benchmarks[0].robustness
    for x in grid.x_values:
        for y in grid.y_values:
            sc = grid.scenario(x, y)
            assert sc.name == f"grid_{x:g}_{y:g}" and getattr(sc, speed_field) == x
            assert sc.profile.edges_mm == (0.0, length_mm)
            assert sc.profile.start_depths_mm == sc.profile.end_depths_mm == (y,)
    assert pickle.loads(pickle.dumps(grid)).scenario(x, y) == sc


def test_the_oracles_are_imported_when_built():
    """The turning and milling oracles are declared by import path (CasADi loads only when
    the benchmark builds one); built, each is its process's MPC oracle."""
    pytest.importorskip("casadi")
    import gymnasium as gym

    from agents.oracle import MillingMPCOracle, TurningMPCOracle

    for process, cls in ((TURNING_PROCESS, TurningMPCOracle), (MILLING_PROCESS, MillingMPCOracle)):
        spec = process.benchmarks[0]
        oracle = pickle.loads(pickle.dumps(spec.oracle))(gym.make(spec.env_id))
        assert type(oracle) is cls


def test_expected_seconds_is_the_longer_of_rows_and_oracle():
    from agents.bench.declarations import BENCHMARKS

    by_id = {s.env_id: s for s in BENCHMARKS}
    milling = by_id["machining_envs/EndMilling-v0"]
    assert milling.expected_seconds == max(
        milling.rows_seconds, milling.oracle_seconds * milling.oracle_episodes
    )
    contouring = by_id["machining_envs/Contouring-v0"]
    assert contouring.oracle is None
    assert contouring.expected_seconds == contouring.rows_seconds
    # With --jobs 2 the two longest envs start at once, the others fill in after them.
    longest = sorted(BENCHMARKS, key=lambda s: -s.expected_seconds)[:2]
    assert {s.env_id for s in longest} == {contouring.env_id, milling.env_id}
