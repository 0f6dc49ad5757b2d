"""The contract between the envs and a process's engine: :class:`LaneCore`.

A process's engine (``<process>/lanes.py``) holds N episodes as arrays, one row per lane,
and steps them all with one compiled kernel. The single env (:class:`~machining_envs.core
.env.LaneEnv`) drives a core of one lane, the vector env
(:class:`~machining_envs.core.vector.LaneVectorEnv`) a core of N, so that lane ``i`` and
the single env run the same code to the last bit. The envs talk to a core only through
the public methods and attributes below; everything else of it is the process's own.

Also here: the per-lane bookkeeping every core shares (:class:`LaneNames`,
:class:`LaneObjects`) and the steps of starting many lanes together (:func:`start_each`,
:func:`split_batch`, :func:`settle_batch`).
"""

from __future__ import annotations

import abc
import inspect

import numpy as np
from gymnasium import spaces

from machining_envs.core.actuation import ActuationLanes, configure_lane, resolve_actuation
from machining_envs.core.env import check_episode_time, check_scenario_spec, resolve_params
from machining_envs.core.reward import resolve_reward
from machining_envs.core.sensors import PowerSensorLanes, resolve_power_sensor

__all__ = [
    "CachedKernelArgs",
    "FeedRegulationCore",
    "LaneCore",
    "LaneNames",
    "LaneObjects",
    "start_each",
    "split_batch",
    "settle_batch",
    "lane_truth",
]


class LaneCore(abc.ABC):
    """The engine of N lanes of one process, as the envs see it.

    Construction
    ------------
    ``Core(owner, n, scenario, **options)``: ``owner`` names the env in error messages,
    ``n`` is the number of lanes and ``scenario`` the default one; the options are the
    core's keyword-only parameters (:attr:`OPTIONS`), the env arguments of the same names,
    which an env passes on with :meth:`from_options`.

    Attributes a core sets in ``__init__``
    ---------------------------------------
    ``n`` (lanes), ``params`` (the nominal parameters), ``reward_weights``,
    ``max_episode_time_s``, ``command_map`` (an :class:`~machining_envs.core.actions
    .ActionMap`), ``action_space`` and ``observation_space`` (of one lane), ``obs``
    (``(n, *obs_shape)`` float32, every lane's observation as it stands), ``scenarios``
    (a :class:`LaneObjects` of every lane's scenario), ``names`` (:class:`LaneNames`),
    ``rngs`` (the lanes' noise generators) and ``blocks`` (the
    :class:`~machining_envs.core.compiled.blocks.LaneBlocks` the kernel steps). The class
    attribute ``scenario_types`` is ``(scenario class, scenario names)``. A core with CNC
    actuation (``machining_envs.core.actuation``) also has ``actuation`` (the env's option),
    ``act_lanes`` and ``actuation_lanes()``, which makes its
    :class:`~machining_envs.core.actuation.ActuationLanes` (what :func:`settle_batch` uses).

    One step
    --------
    An env writes the checked actions (:meth:`set_action` for one lane,
    :meth:`set_actions` for all), calls :meth:`step`, and reads :meth:`outcome` (one lane)
    or :meth:`step_arrays` (all), then :meth:`lane_info` or :meth:`info_arrays`.

    Pickling
    --------
    Attributes named in ``VIEWS`` are views of the core's tables (named columns) or a cache
    of the kernel's arguments (``_args``, which holds views); they are left out of a
    pickle and made again on loading (:meth:`bind_views`; ``_args`` is set to None).
    """

    #: The names of the attributes that are views of the core's tables (see Pickling).
    VIEWS: frozenset[str] = frozenset()
    #: The core's options: its ``__init__``'s keyword-only parameters (set per class).
    OPTIONS: tuple[str, ...] = ()

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        parameters = inspect.signature(cls.__init__).parameters.values()
        cls.OPTIONS = tuple(p.name for p in parameters if p.kind is p.KEYWORD_ONLY)

    @classmethod
    def from_options(cls, owner: str, n: int, scenario, given: dict) -> LaneCore:
        """A core of ``n`` lanes whose options are read by name from ``given``: an env's
        ``__init__`` arguments (its ``locals()``), which name them as the core does."""
        return cls(owner, n, scenario, **{name: given[name] for name in cls.OPTIONS})

    # ---- starting episodes ---------------------------------------------------------------
    @abc.abstractmethod
    def start(self, lane: int, spec, rng: np.random.Generator) -> None:
        """Start a new episode in ``lane`` on the scenario ``spec`` (a scenario object or a
        name drawn from ``rng``); the lane's noise then draws from ``rng``. A scenario the
        parameters refuse raises ``ValueError``."""

    def start_lanes(self, lanes: np.ndarray, spec, rngs) -> None:
        """:meth:`start` of each lane ``k`` of ``lanes`` on ``spec`` with ``rngs[k]``; a
        core that can start a split's lanes together overrides it (same numbers)."""
        start_each(self, lanes, spec, rngs)

    def batches(self, factory) -> bool:
        """Whether :meth:`start_lanes` may start the scenarios of the split ``factory``
        together (:func:`split_batch`); by default never."""
        return False

    def _extremes_pass(self, factory, check) -> bool:
        """Whether every scenario of ``factory.extremes`` (the two ends of a split's
        ranges) passes ``check`` (returns true, raises no ``ValueError``): what
        :meth:`batches` asks of a split before its lanes start together, worked out once
        per factory and kept in the core's ``_batch_ok``."""
        ok = self._batch_ok.get(factory)
        if ok is None:
            try:
                ok = all(check(sc) for sc in factory.extremes)
            except ValueError:
                ok = False
            self._batch_ok[factory] = ok
        return ok

    # ---- one step ------------------------------------------------------------------------
    @abc.abstractmethod
    def set_action(self, lane: int, action, clipped: bool) -> None:
        """Write ``lane``'s checked action (a float in [-1, 1], or a list of them for a
        vector action) and whether it was clipped."""

    @abc.abstractmethod
    def set_actions(self, actions: np.ndarray) -> None:
        """Write every lane's finite action ``(n, *action_shape)``; actions outside the box
        are clipped and marked."""

    @abc.abstractmethod
    def step(self) -> None:
        """Advance every lane by one control period."""

    @abc.abstractmethod
    def outcome(self, lane: int) -> tuple[float, bool, bool]:
        """``lane``'s reward, terminated and truncated after a step, as Python values."""

    @abc.abstractmethod
    def step_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every lane's reward, terminated and truncated after a step (views: copy them)."""

    @abc.abstractmethod
    def clipped_count(self, lane: int) -> int:
        """The actions of ``lane`` clipped so far this episode."""

    # ---- info --------------------------------------------------------------------------
    @abc.abstractmethod
    def lane_info(self, lane: int) -> dict:
        """``lane``'s info as it stands, as Python values (the single env's ``info``)."""

    @abc.abstractmethod
    def info_arrays(self) -> dict:
        """Every lane's info as it stands, as new arrays of length ``n`` (the vector env's
        ``info``; a key only some lanes hold comes with its ``"_" + key`` mask)."""

    # ---- pickling ----------------------------------------------------------------------
    def bind_views(self) -> None:  # noqa: B027 (a core without views has nothing to do)
        """Name the columns of the core's tables (the attributes of ``VIEWS``)."""

    def __getstate__(self) -> dict:
        # A pickled view is a copy: the views are made anew on loading.
        return {k: v for k, v in self.__dict__.items() if k not in self.VIEWS}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        if "_args" in self.VIEWS:  # a cache of the kernel's arguments, views among them
            self._args = None
        self.bind_views()


class CachedKernelArgs(abc.ABC):
    """For a :class:`LaneCore` whose kernel takes its arguments in one table
    (``core.compiled.packed``): the arguments, built by :meth:`_make_kernel_args`, kept in
    ``_args`` until the plant (``lanes``) replaces its arrays (a new ``lanes.version``)."""

    _args: tuple | None = None
    _args_version: int = -1

    def _kernel_args(self) -> tuple:
        """The kernel's arguments as they stand, from the cache while it holds."""
        version = self.lanes.version
        if self._args is None or self._args_version != version:
            self._args = self._make_kernel_args()
            self._args_version = version
        return self._args

    @abc.abstractmethod
    def _make_kernel_args(self) -> tuple:
        """The kernel's arguments, built anew."""


#: The measured loads a feed-regulation env (turning, end milling) observes besides the
#: newest, newest first.
REGULATION_HISTORY = 3
#: Where each field of a feed-regulation env's observation starts (its ``OBS_INDEX``): the
#: measured load over its limit, the limit, the previous action, the spindle speed over
#: 1000 rpm and the ``REGULATION_HISTORY`` measured loads before.
REGULATION_OBS_INDEX = {"measured": 0, "limit": 1, "prev_action": 2, "spindle": 3, "history": 4}


class FeedRegulationCore(CachedKernelArgs, LaneCore):
    """The part of a :class:`LaneCore` that the feed-regulation processes (turning, end
    milling) share: the command is a feed velocity from 0 to ``params.command_max``, every
    ``params.sample_time_s``, the observation has the layout ``REGULATION_OBS_INDEX``, the
    reward is a :class:`~machining_envs.core.reward.LimitReward`, the CNC's actuation and the
    optional spindle-power sensor (the load channel) are options, and a split's lanes start
    in one batch. A subclass keeps its compiled arithmetic; it calls :meth:`_set_regulation`
    and :meth:`_set_cnc` first in its ``__init__``, starts a batch of lanes in :meth:`_start_batch` and builds
    its infos with :meth:`_info`.

    It keeps, besides :class:`LaneCore`'s attributes, ``reward`` and ``flags`` (per lane:
    diverged, breakage, finished, terminated, truncated, ...), ``n_clipped``, ``power_sensor``
    and the plant ``lanes`` (its ``out_segment``)."""

    #: ``(nominal parameters' class, its default set (a classmethod), reward weights'
    #: class)``, set per process.
    option_types: tuple

    def _set_regulation(
        self, owner: str, n: int, scenario, params, reward, max_episode_time_s, overrides
    ) -> None:
        """The options every regulation core checks, in order: ``params`` (of the class
        :attr:`option_types` names, its default set if None, with ``overrides``), the reward
        weights, the episode time and the default scenario (one of :attr:`scenario_types`)."""
        params_type, defaults, reward_type = self.option_types
        self.n = n
        self.params = resolve_params(owner, params, params_type, defaults, overrides)
        self.reward_weights = resolve_reward(reward, reward_type)
        self._w = self.reward_weights.weights()
        self.max_episode_time_s = check_episode_time(max_episode_time_s)
        check_scenario_spec(scenario, *self.scenario_types)

    def _set_cnc(self, actuation, power_sensor) -> None:
        """The spindle-power sensor (the load channel) and the CNC's actuation, made now if
        the option sets it (its checks failing here), else when a scenario first brings its
        own."""
        sensor = resolve_power_sensor(power_sensor)
        self.power_sensor = sensor and PowerSensorLanes(sensor, self.n, self.params.sample_time_s)
        self.actuation = resolve_actuation(actuation)
        self.act_lanes = None if self.actuation is None else self.actuation_lanes()

    def actuation_lanes(self) -> ActuationLanes:
        """The CNC's actuation between the commands and the servo, every lane on the env's
        option until its scenario says otherwise."""
        p = self.params
        return ActuationLanes(self.n, p.command_max, 0.0, p.sample_time_s, self.actuation)

    def _set_regulation_spaces(self, load_range: tuple[float, float], rpm_max: float) -> None:
        """The action space (one action in [-1, 1]) and the observation space of the layout
        ``REGULATION_OBS_INDEX``: the measured load and the last ``REGULATION_HISTORY`` ones
        in ``load_range`` (over the limit), the limit, the previous action and the spindle
        speed over 1000 rpm (at most ``rpm_max`` / 1000)."""
        lo, hi = load_range
        history = REGULATION_HISTORY
        low = np.array([lo, 0.0, -1.0, 0.0] + [lo] * history, dtype=np.float32)
        high = np.array([hi, 10.0, 1.0, rpm_max / 1000.0] + [hi] * history, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)

    def start_lanes(self, lanes: np.ndarray, spec, rngs) -> None:
        """:meth:`start` for each lane ``k`` of ``lanes`` on the scenario ``spec``, drawn
        with ``rngs[k]``: the same episodes, the same numbers. A split's scenarios (a name
        such as ``"train"``) are drawn and started for all lanes in two compiled calls
        (:meth:`_start_batch`), and a lane's scenario and true parameters are built only
        when read (``scenarios[k]``, ``truths[k]``)."""
        factory = split_batch(self, lanes, spec, rngs, self.scenario_types[1])
        if factory is None:
            return
        self._start_batch(lanes, factory)
        if self.power_sensor:
            self._sense_power(lanes)

    @abc.abstractmethod
    def _start_batch(self, lanes: np.ndarray, factory) -> None:
        """Start ``lanes`` on the scenarios the split ``factory`` draws for them (their
        generators bound by :func:`split_batch`)."""

    @abc.abstractmethod
    def _sense_power(self, lanes=None) -> None:
        """The drive's power reading into the observations (option ``power_sensor``,
        ``machining_envs.core.sensors``): of ``lanes`` that start, else a step of all."""

    def step_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.reward, self.flags[:, 3], self.flags[:, 4]

    def clipped_count(self, lane: int) -> int:
        return int(self.n_clipped[lane])

    def _info(self, lane, head: tuple, flags, signals: dict, episode: dict, finish) -> dict:
        """An info in the keys' order every regulation env shows: ``head`` is ``(t_s,
        command, action_clipped)``, ``flags`` the lane's (or lanes') ``(diverged, breakage,
        finished)``, then the process's ``signals`` and ``episode`` keys (the last of these
        ``scenario``) around the segment; ``lane`` is an int (one lane's info: ``machining_time_s`` = ``finish`` when it
        finished) or None (every lane's, as arrays: ``machining_time_s`` with its mask)."""
        t_s, command, clipped = head
        diverged, breakage, finished = flags
        one = lane is not None
        info = {
            "t_s": t_s,
            "command": command,
            "action_clipped": clipped,
            "n_action_clipped": int(self.n_clipped[lane]) if one else self.n_clipped.copy(),
            "breakage": breakage,
            "diverged": diverged,
            "finished": finished,
            **signals,
            "segment": int(self.lanes.out_segment[lane]) if one else self.lanes.out_segment.copy(),
            **episode,
        }
        sensor = self.power_sensor
        if not one:
            info["machining_time_s"] = finish
            info["_machining_time_s"] = finished.copy()
        elif finished:
            info["machining_time_s"] = finish
        if sensor:
            info.update(sensor.lane_info(lane) if one else sensor.info_arrays())
        return info


class LaneNames:
    """The scenario name of every lane, for the info's ``"scenario"`` array.

    Copying an object array costs a reference count per lane (about 8 µs at N = 1024,
    half of a milling step's info), and a vector step hands the names out once or twice
    while they change only at a reset. So :meth:`array` hands out the array itself, made
    read-only, and the next reset that changes a name writes into a copy: what a step's
    info holds never changes after it (and lanes that reset on the scenario they ran copy
    nothing)."""

    __slots__ = ("_names", "_shared")

    def __init__(self, n: int) -> None:
        self._names = np.full(n, "", dtype=object)
        self._shared = False

    def __setitem__(self, lane: int, name: str) -> None:
        if self._names[lane] != name:  # a lane that keeps its name needs no copy
            self._writable()[lane] = name

    def __getitem__(self, lane: int) -> str:
        return self._names[lane]

    def set_many(self, lanes: np.ndarray, name: str, ks: list[int] | None = None) -> None:
        """Every lane of ``lanes`` (an index array; ``ks``, the same as a list, if at hand)
        is named ``name``."""
        names = self._names
        if ks is None:
            ks = lanes.tolist()
        for k in ks:
            if names[k] != name:  # else nothing to copy or write
                self._writable()[lanes] = name
                return

    def _writable(self) -> np.ndarray:
        """The names array to write: a copy of it once it has been handed out."""
        if self._shared:
            self._names = self._names.copy()  # writable
            self._shared = False
        return self._names

    def array(self) -> np.ndarray:
        """Every lane's name, as a read-only object array that no later reset changes."""
        if not self._shared:
            self._names.flags.writeable = False
            self._shared = True
        return self._names


class LaneObjects:
    """An object per lane (a scenario, its true parameters), each either set or left to be
    built when it is first read: a vector env that starts many lanes at once keeps their
    drawn numbers and makes the objects of the lanes someone asks for only.

    ``lanes[k]`` returns lane ``k``'s object, building it if :meth:`defer` left it so;
    ``lanes[k] = obj`` sets it. A batch of lanes shares one recipe, and each lane holds only
    the recipe's number and its place in the batch (two integers in arrays, no Python object
    per lane). ``build`` must be a module-level function or a method of a picklable object,
    so that the env pickles."""

    __slots__ = ("_items", "_batch", "_place", "_recipes", "_next", "_prune_at")

    def __init__(self, n: int) -> None:
        self._items = np.full(n, None, dtype=object)  # (None: left to a recipe, or never set)
        #: The recipe each lane's object is left to (its key in ``_recipes``), or -1.
        self._batch = np.full(n, -1, dtype=np.int64)
        #: Each lane's place in the batch its object is left to.
        self._place = np.zeros(n, dtype=np.int64)
        self._recipes: dict[int, tuple] = {}
        self._next = 0
        self._prune_at = 64

    def __getitem__(self, lane: int):
        b = self._batch[lane]
        if b >= 0:  # built before the lane forgets its recipe: an error leaves it to build
            recipe = self._recipes[int(b)]
            self._items[lane] = recipe[0](*recipe[1:], int(self._place[lane]))
            self._batch[lane] = -1
        return self._items[lane]

    def __setitem__(self, lane: int, obj) -> None:
        self._batch[lane] = -1
        self._items[lane] = obj

    def __len__(self) -> int:
        return len(self._items)

    def defer(self, lanes: np.ndarray, build, *args) -> None:
        """Lane ``lanes[i]`` (an index array, each lane once) gets the object
        ``build(*args, i)``, made when it is first read."""
        key = self._next
        self._next += 1
        self._recipes[key] = (build, *args)
        self._batch[lanes] = key
        self._place[lanes] = np.arange(lanes.size)
        self._items[lanes] = None
        if len(self._recipes) > self._prune_at:  # forget the recipes no lane is left to
            live = set(np.unique(self._batch).tolist())
            self._recipes = {k: r for k, r in self._recipes.items() if k in live}
            self._prune_at = 2 * len(self._recipes) + 64


def start_each(core, lanes: np.ndarray, spec, rngs) -> None:
    """``core.start`` of each lane ``k`` of ``lanes`` on ``spec`` (one for all, or a list of
    one per lane) with ``rngs[k]``; a start's ``ValueError`` (a scenario its parameters
    refuse) names the lane."""
    for k in lanes.tolist():
        try:
            core.start(k, spec[k] if isinstance(spec, list) else spec, rngs[k])
        except ValueError as err:
            raise ValueError(f"lane {k}: {err}") from None


def split_batch(core, lanes: np.ndarray, spec, rngs, factories: dict):
    """The first half of a core's ``start_lanes``: the split factory of ``spec`` (a name in
    ``factories``) whose scenarios ``core`` starts ``lanes`` on together
    (``core.batches(factory)`` says whether it may), each lane ``k`` now drawing from
    ``rngs[k]``; or None, after starting each lane by ``core.start``, with all its checks
    (another name, a scenario object, a split the batch does not take)."""
    factory = factories.get(spec) if isinstance(spec, str) else None
    if not core.batches(factory):
        start_each(core, lanes, spec, rngs)
        return None
    core.rngs.bind_many(lanes.tolist(), rngs)  # the scenarios are drawn with them, and the noise
    return factory


def settle_batch(core, lanes: np.ndarray, build, args: tuple, actuation, name: str) -> list[int]:
    """The bookkeeping of ``lanes`` started together by a core's ``start_lanes``: lane
    ``lanes[i]``'s scenario built when first read as ``build(*args, i)`` and its true
    parameters from that scenario (:class:`LaneObjects`), the CNC's ``actuation`` of the
    split (None: the env's option) in each lane, the split's ``name``. Returns ``lanes`` as
    a list."""
    ks = lanes.tolist()
    core.scenarios.defer(lanes, build, *args)
    core.truths.defer(lanes, lane_truth, core.scenarios, lanes.copy(), core.params)
    if actuation is not None or core.act_lanes is not None:
        for k in ks:
            core.act_lanes = configure_lane(
                core.act_lanes, k, actuation, core.actuation, core.actuation_lanes
            )
    core.names.set_many(lanes, name, ks)
    return ks


def lane_truth(scenarios: LaneObjects, lanes: np.ndarray, nominal, i: int):
    """The true parameters of lane ``lanes[i]``'s scenario (a deferred ``truths`` entry)."""
    return scenarios[int(lanes[i])].true_params(nominal)
