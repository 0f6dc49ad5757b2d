"""The robustness grids of turning and milling: each cell one constant depth at the grid's
speed, built by a picklable declaration (``--jobs`` sends specs to other processes)."""

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
