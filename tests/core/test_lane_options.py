"""What the envs share through ``core``: a core's options passed on by name
(``LaneCore.OPTIONS``, ``from_options``), a split's checks made once
(``LaneCore._extremes_pass``), the workpiece tables (``SegmentTables``) and the process
packages' exports and entry points (``core.lazy``)."""

import inspect

import gymnasium as gym
import numpy as np
import pytest

import machining_envs
from machining_envs.contouring.env import ContouringEnv, ContouringVectorEnv
from machining_envs.contouring.feed_env import ContouringFeedEnv, ContouringFeedVectorEnv
from machining_envs.contouring.feed_lanes import FeedCore
from machining_envs.contouring.lanes import ContouringCore
from machining_envs.core.lanes import LaneCore
from machining_envs.core.lazy import by_module, env_entry_points, process_package
from machining_envs.core.workpieces import SegmentTables
from machining_envs.drilling.env import MicroDrillingEnv, MicroDrillingVectorEnv
from machining_envs.drilling.lanes import DrillingCore
from machining_envs.milling.env import EndMillingEnv, EndMillingVectorEnv
from machining_envs.milling.lanes import MillingCore
from machining_envs.turning.env import TurningEnv, TurningVectorEnv
from machining_envs.turning.lanes import TurningCore

FACES = [
    (TurningCore, TurningEnv, TurningVectorEnv),
    (MillingCore, EndMillingEnv, EndMillingVectorEnv),
    (DrillingCore, MicroDrillingEnv, MicroDrillingVectorEnv),
    (ContouringCore, ContouringEnv, ContouringVectorEnv),
    (FeedCore, ContouringFeedEnv, ContouringFeedVectorEnv),
]


@pytest.mark.parametrize("core_cls, single, vector", FACES, ids=lambda c: c.__name__)
def test_every_core_option_is_an_argument_of_both_envs(core_cls, single, vector):
    """An env passes its core the arguments named as the core's keyword-only parameters:
    each must be an argument of both env faces (``overrides`` their ``**`` catch-all)."""
    options = core_cls.OPTIONS
    assert options == tuple(
        p.name
        for p in inspect.signature(core_cls.__init__).parameters.values()
        if p.kind is p.KEYWORD_ONLY
    )
    assert "params" in options and "overrides" in options
    for env_cls in (single, vector):
        assert set(options) <= set(inspect.signature(env_cls).parameters)


@pytest.mark.parametrize("core_cls, single, vector", FACES, ids=lambda c: c.__name__)
def test_a_vector_env_takes_the_options_of_its_single_env(core_cls, single, vector):
    """The vector env's signature is the single env's (its options keyword-only, their
    defaults the same) without ``render_mode``, with ``num_envs``, ``num_threads`` and
    ``autoreset_mode``; its name and task are the single env's."""
    ones = dict(inspect.signature(single).parameters)
    many = dict(inspect.signature(vector).parameters)
    assert list(many)[:2] == ["num_envs", "scenario"] and many["scenario"] == ones["scenario"]
    assert "render_mode" not in many and {"num_threads", "autoreset_mode"} <= set(many)
    for name, p in ones.items():
        if name not in ("scenario", "render_mode", "overrides"):
            assert many[name].kind is p.KEYWORD_ONLY and many[name].default == p.default
    assert vector.env_name == single.__name__ and vector.task is single.task
    assert vector.core_cls is core_cls


def test_a_vector_env_refuses_what_its_single_env_refuses():
    with pytest.raises(TypeError, match="positional argument"):
        MicroDrillingVectorEnv(2, "train", "voltage")  # options are keyword-only
    with pytest.raises(ValueError, match="render_mode='human'.*do not render"):
        TurningVectorEnv(2, render_mode="human")
    with pytest.raises(ValueError, match="control must be one of"):
        MicroDrillingVectorEnv(2, control="current")


class _Stub(LaneCore):
    """A core with nothing of the engine (for what ``LaneCore`` itself does)."""

    start = set_action = set_actions = step = outcome = None
    step_arrays = clipped_count = lane_info = info_arrays = None


def test_from_options_reads_the_options_by_name_and_nothing_else():
    class Core(_Stub):
        def __init__(self, owner, n, scenario, *, gain, limit=2.0):
            self.got = (owner, n, scenario, gain, limit)

    assert Core.OPTIONS == ("gain", "limit")
    given = {"gain": 3.0, "limit": 4.0, "render_mode": "human", "self": None}
    core = Core.from_options("Env", 5, "train", given)
    assert core.got == ("Env", 5, "train", 3.0, 4.0)
    with pytest.raises(KeyError, match="limit"):
        Core.from_options("Env", 1, "train", {"gain": 1.0})


def test_envs_keep_their_positional_and_keyword_arguments():
    """The faces still take their options positionally where they did, and by name."""
    env = TurningEnv("paper_405", None, None, 300.0, max_episode_time_s=50.0)
    assert env.spindle_rpm_override == 300.0 and env.max_episode_time_s == 50.0
    env = MicroDrillingEnv("train", "feed")
    assert env.control == "feed"
    with pytest.raises(TypeError, match="sensor_gian"):
        TurningEnv(sensor_gian=1.0)
    venv = EndMillingVectorEnv(3, "train", action_map="linear", num_threads=1)
    assert venv.num_envs == 3 and venv.command_map.scale == "linear"


class _Factory:
    def __init__(self, extremes):
        self.extremes = extremes


class _Core(_Stub):
    def __init__(self):
        self._batch_ok = {}


def test_extremes_pass_checks_a_split_once_and_refuses_on_value_error():
    core = _Core()
    calls = []

    def check(sc):
        calls.append(sc)
        if sc == "bad":
            raise ValueError("refused")
        return sc != "no"

    good, bad, no = _Factory(["a", "b"]), _Factory(["a", "bad"]), _Factory(["no", "a"])
    assert core._extremes_pass(good, check) is True
    assert core._extremes_pass(good, check) is True  # from the cache
    assert calls == ["a", "b"]
    assert core._extremes_pass(bad, check) is False
    assert core._extremes_pass(no, check) is False
    assert calls[-1] == "no"  # stops at the first that fails


def test_segment_tables_grow_to_the_most_segments():
    class Tables(SegmentTables):
        pass

    t = Tables()
    t._new_segment_tables(3)
    assert t.edges.shape == (3, 2) and t.d0.shape == (3, 1) and t.version == 0
    t.edges[:] = [[0.0, 5.0]] * 3
    t.fit_segments(1)
    assert t.version == 0
    t.fit_segments(3)
    assert t.edges.shape == (3, 4) and t.slope.shape == (3, 3) and t.version == 1
    np.testing.assert_array_equal(t.edges[0], [0.0, 5.0, 5.0, 5.0])  # the end repeated


def test_exports_and_entry_points_of_a_process_package():
    exports = by_module("pkg", env=("A", "B"), plant=("C",))
    assert exports == {"A": "pkg.env", "B": "pkg.env", "C": "pkg.plant"}
    single, vector = env_entry_points("pkg", {"X-v0": ("env", "XEnv", "XVectorEnv")})
    assert single == {"machining_envs/X-v0": "pkg.env:XEnv"}
    assert vector == {"machining_envs/X-v0": "pkg.env:XVectorEnv"}
    single, vector = env_entry_points("pkg", {"Y-v0": ("plain", "YEnv", None)})
    assert single == {"machining_envs/Y-v0": "pkg.plain:YEnv"} and vector == {}


def test_a_process_package_declared_in_one_call():
    names, getattr_, dir_, single, vector = process_package(
        "machining_envs.turning",
        {"X-v0": ("env", "XEnv", "XVectorEnv")},
        plant=("TurningParams",),
    )
    assert names == ["TurningParams", "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]
    from machining_envs.turning.plant import TurningParams

    assert getattr_("TurningParams") is TurningParams
    assert "TurningParams" in dir_()
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        getattr_("Nope")
    assert single == {"machining_envs/X-v0": "machining_envs.turning.env:XEnv"}
    assert vector == {"machining_envs/X-v0": "machining_envs.turning.env:XVectorEnv"}


def test_the_registered_ids_and_their_entry_points():
    expected = {
        "Turning-v0": ("turning.env", "TurningEnv"),
        "EndMilling-v0": ("milling.env", "EndMillingEnv"),
        "MicroDrilling-v0": ("drilling.env", "MicroDrillingEnv"),
        "Contouring-v0": ("contouring.env", "ContouringEnv"),
        "ContouringFeed-v0": ("contouring.feed_env", "ContouringFeedEnv"),
    }
    assert set(machining_envs.ENV_IDS) == {f"machining_envs/{k}" for k in expected}
    for name, (module, cls) in expected.items():
        spec = gym.spec(f"machining_envs/{name}")
        assert spec.entry_point == f"machining_envs.{module}:{cls}"
        vector_cls = cls.replace("Env", "VectorEnv")
        assert spec.vector_entry_point == f"machining_envs.{module}:{vector_cls}"
    from machining_envs import turning

    assert turning.TurningParams.__name__ == "TurningParams"  # the lazy export loads


@pytest.mark.parametrize("single", [TurningEnv, EndMillingEnv, MicroDrillingEnv])
def test_a_single_env_of_one_number_uses_the_default_action_check_and_plant(single):
    """``LaneEnv``'s defaults: the action is one number, checked naming the env, and the
    episode's plant is the core's lanes, None before the first reset."""
    env = single()
    assert env.plant is None
    env.reset(seed=0)
    assert env.plant is env._core.lanes
    with pytest.raises(ValueError, match=single.__name__):
        env.step(np.array([np.nan], dtype=np.float32))
    with pytest.raises(ValueError, match=single.__name__):
        env.step(np.zeros(2, dtype=np.float32))
