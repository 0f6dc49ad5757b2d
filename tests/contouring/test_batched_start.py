"""ContouringFeed-v0's lanes started at once (``FeedCore.start_lanes``): the same episodes
as lane by lane, for every scenario name, each lane's scenario built when read."""

import math

import numpy as np
import pytest

from machining_envs.contouring.paths import SEGMENT_COLUMNS, Path, smooth_table
from machining_envs.contouring.scenarios import CONTOURING_SCENARIOS
from tests.helpers import CONTOURING_FEED, started_together_and_one_by_one

N = 12
#: The names ContouringFeed-v0 takes (a step command has no path to feed along).
FEED_SCENARIOS = sorted(k for k in CONTOURING_SCENARIOS if not k.startswith("paper_step"))
BATCHED = {"train", "validation", "test", "ood", "shopfloor"}


def _arrays(obj) -> dict:
    return {k: v for k, v in vars(obj).items() if isinstance(v, np.ndarray)}


@pytest.mark.parametrize("spec", FEED_SCENARIOS)
def test_lanes_started_together_start_as_one_by_one(spec):
    """Every array of the env and of the servo loops, every lane's scenario, truth, name,
    info and generator: the same, bit for bit."""
    one, many, _ = started_together_and_one_by_one(CONTOURING_FEED, spec, N)
    assert many._batch_ok.get(CONTOURING_SCENARIOS[spec], False) == (spec in BATCHED)
    for a, b in ((one, many), (one.loops, many.loops)):
        arrays_a, arrays_b = _arrays(a), _arrays(b)
        assert arrays_a.keys() == arrays_b.keys()
        for name, arr in arrays_a.items():
            np.testing.assert_array_equal(arr, arrays_b[name], err_msg=name, strict=True)
    for k in range(N):
        if spec in BATCHED:  # left to lane_info, which builds it from the arrays
            assert many.episode_info[k] is None
        sa, sb = one.scenarios[k], many.scenarios[k]
        np.testing.assert_array_equal(sa.path.table(), sb.path.table(), strict=True)
        assert (sa.path.length, sa.path.start, sa.path.end, sa.path.name) == (
            sb.path.length,
            sb.path.start,
            sb.path.end,
            sb.path.name,
        )
        fields = ("name", "feed_mm_s", "load_steps", "inertia_scale", "dwell_s", "actuation")
        assert [getattr(sa, f) for f in fields] == [getattr(sb, f) for f in fields], k
        assert one.truths[k] == many.truths[k], k
        assert one.names[k] == many.names[k]
        ia, ib = one.lane_info(k), many.lane_info(k)
        assert ia.keys() == ib.keys()
        for key, value in ia.items():
            np.testing.assert_array_equal(value, ib[key], err_msg=key, strict=True)
        assert repr(one.episode_info[k]) == repr(many.episode_info[k]), k
    acts = [c.act_lanes for c in (one, many)]
    assert (acts[0] is None) == (acts[1] is None) == (spec != "shopfloor")
    if acts[0] is not None:
        for name, arr in _arrays(acts[0]).items():
            np.testing.assert_array_equal(arr, _arrays(acts[1])[name], err_msg=name)


def test_each_lane_draws_from_its_own_generator_and_leaves_it_where_a_reset_does():
    """After the batched restart, each lane's generator stands where the single env's
    reset leaves it (the per-lane path of the first env)."""
    one, many, lanes = started_together_and_one_by_one(CONTOURING_FEED, "train", N)
    for k in range(N):
        state = one.rngs.generators[k].bit_generator.state
        assert state == many.rngs.generators[k].bit_generator.state, k


@pytest.mark.parametrize("ranges", [CONTOURING_SCENARIOS["train"], CONTOURING_SCENARIOS["ood"]])
def test_the_compiled_table_is_the_paths_own(ranges):
    """``smooth_table`` (a batch's tables, compiled) against ``Path.table`` of the same
    drawn numbers, over many draws: lines' lengths through CPython's hypot, arcs' ends
    through libm's sines and cosines, the unwrapped headings, the bounding circles."""
    rng = np.random.default_rng(7)
    lo, hi = ranges.segments
    for _ in range(300):
        n = int(rng.integers(lo, hi + 1))
        draws = rng.random((5, n))
        heading = float(rng.uniform(-math.pi, math.pi))
        args = (ranges.line, ranges.radius, ranges.sweep, 0.4)
        path = Path._smooth(draws.tolist(), heading, *args, (0.0, 0.0), "p")
        tab = np.full((hi + 1, SEGMENT_COLUMNS), np.nan)
        ends = smooth_table(draws, n, heading, *(np.array(a) for a in args[:3]), 0.4, tab)
        np.testing.assert_array_equal(tab[:n], path.table(), strict=True)
        assert ends == (path.length, *path.start, *path.end)
        assert np.isnan(tab[n:]).all()  # nothing written past the path's rows


def test_the_circle_keys_come_and_go_with_the_lanes_on_circles():
    """A vector step's info holds the circle keys (with their masks) while some lane's path
    is a circle, and not once none is: circle lanes restarted on a split's paths together
    (``start_lanes``) or one by one (``start``) leave the count ``info_arrays`` reads."""
    import gymnasium as gym

    venv = gym.make_vec(CONTOURING_FEED, num_envs=6)
    specs = ["paper_circle", "train", "paper_circle", "train", "paper_corner", "train"]
    venv.reset(seed=0, options={"scenario": specs})
    core = venv.unwrapped._core
    _, _, _, _, info = venv.step(np.zeros((6, 1), dtype=np.float32))
    assert core._circles == 2
    np.testing.assert_array_equal(info["_circle_radius_mm"], core.has_circle, strict=True)
    np.testing.assert_array_equal(info["circle_radius_mm"][[0, 2]], [10.0, 10.0])
    core.start_lanes(np.array([0, 1]), "train", venv.unwrapped.lane_rngs)  # one circle left
    assert core._circles == 1 and "circle_radius_mm" in core.info_arrays()
    core.start(2, "paper_corner", venv.unwrapped.lane_rngs[2])  # none
    assert core._circles == 0 and not core.has_circle.any()
    assert not any(k.startswith(("circle", "_circle")) for k in core.info_arrays())
    core.start(5, "paper_circle", venv.unwrapped.lane_rngs[5])
    core.start(5, "paper_circle", venv.unwrapped.lane_rngs[5])  # (counted once)
    assert core._circles == 1 and core.info_arrays()["_circle_radius_mm"].tolist() == [
        False,
        False,
        False,
        False,
        False,
        True,
    ]
    venv.close()
