"""The base of the single envs (:class:`LaneEnv`: reset and step over a core of one lane)
and what every env checks of its keywords and scenarios. Actions are
``machining_envs.core.actions``, rendering ``machining_envs.core.rendering``."""

from __future__ import annotations

import abc
import difflib
import math
from collections.abc import Iterable

import gymnasium as gym
import numpy as np

from machining_envs.core.actions import check_action
from machining_envs.core.checks import PY_NUMBER_TYPES, is_real
from machining_envs.core.metrics import note_severity
from machining_envs.core.rendering import (
    EpisodeLog,
    check_render_mode,
    present_frame,
    ready_to_render,
    record_step,
    render_signals,
)

__all__ = [
    "LaneEnv",
    "FeedRegulationEnv",
    "episode_ended",
    "check_overrides",
    "check_episode_time",
    "check_scenario_spec",
    "resolve_scenario",
    "scenario_option",
]


def episode_ended(env_name: str) -> RuntimeError:
    """The error every single env raises when ``step()`` is called after an episode ended.

    Once a step has returned ``terminated`` or ``truncated``, the episode is over: the tool
    broke, the part is finished or the time is up, and there is no next state to return.
    The env refuses the step rather than return a made-up transition; call ``reset()``.
    (The vector envs reset finished lanes themselves, see ``machining_envs.core.vector``.)
    """
    return RuntimeError(
        f"{env_name}: the episode has ended (a step returned terminated or truncated); "
        f"call reset() before step()"
    )


def check_overrides(owner: str, overrides: dict, allowed: Iterable[str]) -> None:
    """``TypeError`` for keyword arguments that are not parameter names, with a suggestion."""
    allowed = list(allowed)
    for key in overrides:
        if key not in allowed:
            close = difflib.get_close_matches(key, allowed, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise TypeError(f"{owner}() got an unexpected keyword argument {key!r}{hint}")


def check_episode_time(max_episode_time_s) -> float:
    """The time limit as a float if it lies in (0, 100000] s, else ``ValueError``."""
    if not (is_real(max_episode_time_s, PY_NUMBER_TYPES) and 0 < max_episode_time_s <= 1e5):
        raise ValueError(f"max_episode_time_s must be in (0, 100000], got {max_episode_time_s!r}")
    return float(max_episode_time_s)


def _scenario_error(spec, scenario_cls: type, names) -> ValueError:
    return ValueError(
        f"scenario must be a {scenario_cls.__name__} or one of {sorted(names)}, got {spec!r}"
    )


def check_scenario_spec(spec, scenario_cls: type, names) -> None:
    """``ValueError`` unless ``spec`` is a ``scenario_cls`` or one of the scenario ``names``."""
    if not isinstance(spec, scenario_cls) and spec not in names:
        raise _scenario_error(spec, scenario_cls, names)


def resolve_scenario(spec, rng: np.random.Generator, scenario_cls: type, factories: dict):
    """The scenario ``spec`` asks for: a ``scenario_cls`` as it is, a name of ``factories``
    drawn from ``rng`` (``factories[spec](rng)``); anything else raises ``ValueError``."""
    if isinstance(spec, scenario_cls):
        return spec
    if isinstance(spec, str) and spec in factories:
        return factories[spec](rng)
    raise _scenario_error(spec, scenario_cls, factories)


def scenario_option(options: dict | None, default):
    """The scenario asked for in ``reset(options=...)``; ``options`` must be a dict or None
    (``TypeError`` naming it), and any other option is a ``ValueError``."""
    if options is not None and not isinstance(options, dict):
        raise TypeError(
            f"reset options must be a dict such as {{'scenario': 'test'}} or None, "
            f"got {type(options).__name__} {options!r:.40}"
        )
    options = dict(options or {})
    spec = options.pop("scenario", default)
    if options:
        raise ValueError(f"reset options may only hold 'scenario', got {sorted(options)}")
    return spec


def resolve_params(owner: str, params, params_cls: type, default, overrides: dict):
    """The nominal parameter set: ``params`` (or ``default()``) with ``overrides`` applied.

    Unknown override names raise ``TypeError`` (see :func:`check_overrides`); a ``params``
    of the wrong type raises ``ValueError``.
    """
    import dataclasses

    check_overrides(owner, overrides, [f.name for f in dataclasses.fields(params_cls)])
    if params is None:
        params = default()
    if not isinstance(params, params_cls):
        raise ValueError(f"params must be a {params_cls.__name__}, got {type(params).__name__}")
    return params.replace(**overrides) if overrides else params


class LaneEnv(gym.Env, abc.ABC):
    """The single env of a process whose physics is a core of lanes: the core of one lane
    that its vector env holds N of, so that a lane and the single env run the same code.

    A subclass builds its core (a :class:`~machining_envs.core.lanes.LaneCore` of one lane)
    in ``__init__`` from its arguments (:meth:`_open`) and says how an episode is drawn
    (:meth:`_draw`); how an action is checked (:meth:`_set_action`) and what it keeps of a
    new episode (:meth:`_began`) have defaults (one number; the plant) it may override;
    ``reset``, ``step``, ``render`` and the command map are shared. ``_LOG_FIELDS`` names what a rendered episode records of ``info``
    (:class:`EpisodeLog`).
    """

    #: A single env renders its episode as an image or in a window (at ``render_fps``
    #: samples a second, which a process may change).
    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}
    _LOG_FIELDS: dict[str, str] = {}
    #: The episode's plant (the process's lanes of one lane, their true parameters in
    #: ``plant.params``), set at every reset (:meth:`_began`); None before the first.
    plant = None
    #: The env's id without its namespace (``"Turning-v0"``): the window ``render`` shows.
    _ID: str = ""

    def _open(self, core_cls: type, given: dict):
        """Build a ``core_cls`` of one lane from the env's arguments ``given`` (its
        ``__init__``'s ``locals()``: ``scenario``, ``render_mode`` and the core's options,
        named as the core names them, ``LaneCore.from_options``), adopt it and return it."""
        core = core_cls.from_options(type(self).__name__, 1, given["scenario"], given)
        self._adopt(core, given["scenario"], given["render_mode"])
        return core

    def _adopt(self, core, scenario, render_mode) -> None:
        """Take ``core`` (of one lane) and give the env the public attributes every env
        has: ``params``, ``reward_weights``, ``max_episode_time_s``, ``default_scenario``
        (``scenario``), ``render_mode`` (checked), ``command_map`` and the two spaces."""
        self._core = core
        self.params = core.params
        self.reward_weights = core.reward_weights
        self.max_episode_time_s = core.max_episode_time_s
        self.default_scenario = scenario
        self.render_mode = check_render_mode(render_mode, self.metadata["render_modes"])
        self.command_map = core.command_map
        self.action_space = core.action_space
        self.observation_space = core.observation_space
        self.scenario = None
        self._started = False
        self._ended = False
        self._log = EpisodeLog(self._LOG_FIELDS)

    # ---- the command map, for classical agents -----------------------------------------
    def action_to_command(self, action):
        """The physical command for an action in [-1, 1] (``command_map``; its unit is in
        the env's Action Space)."""
        return self.command_map.action_to_command(action)

    def command_to_action(self, command):
        """The action in [-1, 1] for a physical command (``command_map``)."""
        return self.command_map.command_to_action(command)

    # ---- what a subclass says --------------------------------------------------------------
    def _set_action(self, action) -> None:
        """Check ``action`` (``ValueError`` naming the env) and write it into lane 0 of the
        core, with whether it was clipped (``core.set_action``): by default one number in
        [-1, 1] (:func:`~machining_envs.core.actions.check_action`); an env whose action is
        a vector overrides it."""
        self._core.set_action(0, *check_action(action, type(self).__name__))

    def _outcome(self) -> tuple[float, bool, bool]:
        """Lane 0's reward, terminated and truncated after a step, as Python values."""
        return self._core.outcome(0)

    @property
    def _n_clipped(self) -> int:
        """Actions clipped so far this episode (``info["n_action_clipped"]``)."""
        return self._core.clipped_count(0)

    def _began(self, core) -> None:
        """Called when an episode has started (``self.scenario`` is set): what the env
        keeps of it; by default its ``plant``, the core's lanes (one lane). An env whose
        core has no ``lanes`` overrides it."""
        self.plant = core.lanes

    @abc.abstractmethod
    def _draw(self):
        """The episode so far (``self._log``) drawn as an RGB array, for :meth:`render`."""

    def _noted(self, info: dict) -> dict:
        """``info`` with the step's ``excess`` over the limit and the scenario's
        ``overload_ratio`` (the class's ``task.limit_keys``,
        :func:`machining_envs.core.metrics.note_severity`)."""
        task = getattr(type(self), "task", None)
        keys = getattr(task, "limit_keys", None)
        return note_severity(info, keys, getattr(self.scenario, "overload_ratio", math.inf))

    # ---- gymnasium API -------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        core = self._core
        spec = scenario_option(options, self.default_scenario)
        check_scenario_spec(spec, *core.scenario_types)  # refused: the episode goes on
        super().reset(seed=seed)  # (after the checks: refused options keep the generator)
        self._started = False  # a start that raises part-way leaves nothing to step
        core.start(0, spec, self.np_random)
        self._started = True
        self._ended = False
        self.scenario = core.scenarios[0]
        info = self._noted(core.lane_info(0))
        self._began(core)
        self._log = EpisodeLog(self._LOG_FIELDS)
        if self.render_mode is not None:
            self._log.record(info)
        return core.obs[0].copy(), info

    def step(self, action):
        if not self._started:
            raise RuntimeError(f"{type(self).__name__}: call reset() before step()")
        if self._ended:
            raise episode_ended(type(self).__name__)
        self._set_action(action)
        core = self._core
        core.step()
        info = self._noted(core.lane_info(0))
        record_step(self, self._log, info)
        reward, terminated, truncated = self._outcome()
        self._ended = terminated or truncated
        return core.obs[0].copy(), reward, terminated, truncated, info

    def render(self):
        """The episode so far: an RGB array (``render_mode="rgb_array"``), or shown in a
        window (``"human"``, returns None); None, with a warning, without a render mode."""
        if not ready_to_render(self):
            return None
        return present_frame(self._draw(), self.render_mode, self._ID)


class FeedRegulationEnv(LaneEnv):
    """The single env of a process that holds a cutting load under its limit by the feed
    (turning, end milling; its core a :class:`~machining_envs.core.lanes.FeedRegulationCore`):
    it keeps the core's ``actuation`` and ``power_sensor`` options as attributes, and
    ``render()`` draws the load (true, measured and the limit), the feed and the depth of cut.

    A subclass names its load in :attr:`_LOAD` and its depth's label in :attr:`_DEPTH_LABEL`,
    and says the limit and the title of the plot (:meth:`_limit`, :meth:`_title`).
    """

    #: The cutting load render() draws: ``(info key, axis label, legend)``.
    _LOAD: tuple[str, str, str]
    #: The axis label of the depth of cut render() draws.
    _DEPTH_LABEL: str

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        #: The signals render() draws: name -> the info key each is read from.
        cls._LOG_FIELDS = {
            "t": "t_s",
            "load": cls._LOAD[0],
            "measured": "measured",
            "feed": "feed_mm_per_rev",
            "depth": "depth_mm",
        }

    def _open(self, core_cls: type, given: dict):
        core = super()._open(core_cls, given)
        #: The spindle-power sensor's settings (option ``power_sensor``), None when off.
        self.power_sensor = core.power_sensor and core.power_sensor.sensor
        #: The CNC's actuation (option ``actuation``), None when ideal.
        self.actuation = core.actuation
        return core

    @abc.abstractmethod
    def _limit(self) -> float:
        """The episode's limit of the load, drawn as a line."""

    @abc.abstractmethod
    def _title(self) -> str:
        """The plot's title."""

    def _draw(self):
        log = self._log
        _, axis, legend = self._LOAD
        limit = [self._limit()] * len(log["t"])
        load = [(legend, log["load"], "C0-"), ("measured", log["measured"], "C1-")]
        panels = [
            (axis, [*load, ("limit", limit, "k--")]),
            ("feed (mm/rev)", [("feed", log["feed"], "C2-")]),
            (self._DEPTH_LABEL, [("depth", log["depth"], "C3-")]),
        ]
        return render_signals(log["t"], panels, self._title())
