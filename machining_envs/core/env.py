"""What every env shares: action scaling, bad-input checks, keyword checks, plots, and
:class:`LaneEnv`, the base of the single envs."""

from __future__ import annotations

import abc
import difflib
import math
from collections.abc import Iterable, Sequence

import gymnasium as gym
import numpy as np

from machining_envs.core.actuation import configure_lane
from machining_envs.core.metrics import note_severity

__all__ = [
    "ActionMap",
    "LaneEnv",
    "check_action",
    "episode_ended",
    "real_actions",
    "check_overrides",
    "render_signals",
    "present_frame",
    "check_render_mode",
    "check_episode_time",
    "check_scenario_spec",
    "resolve_scenario",
    "scenario_option",
    "check_reward_weights",
    "EpisodeLog",
    "LaneNames",
    "LaneObjects",
    "start_each",
    "record_step",
]


ACTION_MAPS = ("linear", "log")


class ActionMap:
    """Map between the agent's ``Box(-1, 1)`` action and a physical command range.

    ``scale="linear"``: the command is affine in the action. ``scale="log"``: it rises
    exponentially over ``decades`` decades,
    ``c = c_min + (c_max - c_min) (10^(k (a + 1) / 2) - 1) / (10^k - 1)``: action -1 is still
    ``c_min`` and +1 ``c_max``, but every step of ``2 / k`` in the action multiplies the
    command (above ``c_min``) by about ten, so a policy has the same relative resolution
    at every size of command.

    >>> m = ActionMap(0.0, 150.0, scale="log", decades=3.0)
    >>> round(m.action_to_command(-1.0), 9), round(m.action_to_command(1.0), 9)
    (0.0, 150.0)
    >>> round(float(m.command_to_action(m.action_to_command(0.25))), 12)
    0.25
    """

    def __init__(
        self, command_min: float, command_max: float, scale: str = "linear", decades: float = 3.0
    ):
        if not (
            math.isfinite(command_min) and math.isfinite(command_max) and command_max > command_min
        ):
            raise ValueError(
                f"command range must be finite with command_max > command_min, got "
                f"[{command_min}, {command_max}]"
            )
        if scale not in ACTION_MAPS:
            raise ValueError(f"action map scale must be one of {list(ACTION_MAPS)}, got {scale!r}")
        if not (isinstance(decades, (int, float)) and 0.5 <= decades <= 6):
            raise ValueError(f"decades must be in [0.5, 6], got {decades!r}")
        self.command_min = float(command_min)
        self.command_max = float(command_max)
        self.scale = scale
        self.decades = float(decades)
        self._half = 0.5 * (self.command_max - self.command_min)
        self._mid = 0.5 * (self.command_max + self.command_min)
        self._span = self.command_max - self.command_min
        self._g = 10.0**self.decades - 1.0
        self._c = 0.5 * math.log(10.0) * self.decades

    def action_to_command(self, action):
        """Physical command for an action in [-1, 1] (array or scalar)."""
        if isinstance(action, float):  # the envs' step: plain floats, no array overhead
            if self.scale == "linear":
                return self._mid + self._half * action
            return self.command_min + self._span * math.expm1(self._c * (action + 1.0)) / self._g
        a = np.asarray(action, dtype=np.float64)
        if self.scale == "linear":
            return self._mid + self._half * a
        return self.command_min + self._span * np.expm1(self._c * (a + 1.0)) / self._g

    def command_to_action(self, command):
        """Action in [-1, 1] for a physical command (not clipped; on the log map a command
        below ``command_min`` gives an action below -1)."""
        c = np.asarray(command, dtype=np.float64)
        if self.scale == "linear":
            return (c - self._mid) / self._half
        x = np.maximum((c - self.command_min) * self._g / self._span, -1.0 + 1e-15)
        return np.log1p(x) / self._c - 1.0


def real_actions(action, env_name: str) -> np.ndarray:
    """``action`` as a float64 array if it is made of real numbers (Python or numpy ints and
    floats), else ``ValueError`` naming the env: strings, bytes, complex numbers, booleans
    and objects are refused, never converted (``"0.3"`` is not an action, and ``True`` is
    most likely a mistake)."""
    if isinstance(action, (str, bytes, bool, np.bool_, complex, dict, set)):
        raise ValueError(f"{env_name}: action must be real numbers, got {action!r:.60}")
    try:
        a = np.asarray(action)
    except (TypeError, ValueError):
        raise ValueError(f"{env_name}: action must be real numbers, got {action!r:.60}") from None
    if a.dtype.kind not in "iuf":
        raise ValueError(
            f"{env_name}: action must be real numbers, got {action!r:.60} (dtype {a.dtype})"
        )
    return a.astype(np.float64, copy=False)


def check_action(action, env_name: str) -> tuple[float, bool]:
    """Return the action as a float in [-1, 1] and whether it had to be clipped.

    Anything but real numbers raises ``ValueError`` naming the env (:func:`real_actions`);
    so do NaN and inf; a finite action outside the box is clipped (the caller counts it in
    ``info``).
    """
    if isinstance(action, np.ndarray) and action.shape == (1,) and action.dtype.kind == "f":
        v = float(action[0])
    else:
        a = real_actions(action, env_name).reshape(-1)
        if a.size != 1:
            raise ValueError(
                f"{env_name}: action must hold one value, got shape {np.shape(action)}"
            )
        v = float(a[0])
    if not math.isfinite(v):
        raise ValueError(f"{env_name}: action must be finite, got {v!r}")
    if v > 1.0:
        return 1.0, True
    if v < -1.0:
        return -1.0, True
    return v, False


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


def render_signals(
    t: Sequence[float],
    panels: Sequence[tuple[str, Sequence[tuple[str, Sequence[float], str]]]],
    title: str,
) -> np.ndarray:
    """Plot stacked panels of signals against time and return the image as an RGB array.

    ``panels`` is a list of ``(y label, [(legend, values, style), ...])``.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - matplotlib is a dependency
        raise ImportError("rendering needs matplotlib: pip install matplotlib") from exc
    fig = Figure(figsize=(7, 2.0 * len(panels) + 0.6), dpi=80)
    canvas = FigureCanvasAgg(fig)
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (ylabel, lines) in zip(axes, panels, strict=True):
        for label, values, style in lines:
            ax.plot(t, values, style, label=label, lw=1.2)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        if len(lines) > 1:
            ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title, fontsize=10)
    fig.tight_layout()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def present_frame(img: np.ndarray, render_mode: str, window: str):
    """What ``render()`` returns: the image for ``"rgb_array"``; for ``"human"`` the image is
    shown in a matplotlib window named ``window`` and ``None`` is returned."""
    if render_mode != "human":
        return img
    import matplotlib.pyplot as plt

    plt.figure(window)
    plt.clf()
    plt.imshow(img)
    plt.axis("off")
    plt.pause(0.001)
    return None


def check_render_mode(render_mode, modes) -> str | None:
    """``render_mode`` if it is None or one of ``modes``, else ``ValueError``."""
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"render_mode must be None or one of {modes}, got {render_mode!r}")
    return render_mode


def check_episode_time(max_episode_time_s) -> float:
    """The time limit as a float if it lies in (0, 100000] s, else ``ValueError``."""
    ok = isinstance(max_episode_time_s, (int, float)) and not isinstance(max_episode_time_s, bool)
    if not (ok and 0 < max_episode_time_s <= 1e5):
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


def resolve_reward(reward, reward_cls: type):
    """Reward weights from ``None`` (defaults), a dict of weights, or a ``reward_cls``."""
    import dataclasses

    if isinstance(reward, dict):
        check_overrides(
            reward_cls.__name__, reward, [f.name for f in dataclasses.fields(reward_cls)]
        )
        reward = reward_cls(**reward)
    if reward is None:
        return reward_cls()
    if not isinstance(reward, reward_cls):
        raise ValueError(
            f"reward must be a {reward_cls.__name__} or a dict, got {type(reward).__name__}"
        )
    return reward


def check_reward_weights(reward) -> None:
    """``ValueError`` unless every field of the reward dataclass ``reward`` is a finite
    number >= 0, not a bool (the first that is not is named: ``"reward weight {name} must
    be a finite number >= 0, got {value!r}"``). Call it from the dataclass's
    ``__post_init__``.
    """
    import dataclasses

    for f in dataclasses.fields(reward):
        v = getattr(reward, f.name)
        if not (
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0
        ):
            raise ValueError(f"reward weight {f.name} must be a finite number >= 0, got {v!r}")


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
    (``core._batches(factory)`` says whether it may), each lane ``k`` now drawing from
    ``rngs[k]``; or None, after starting each lane by ``core.start``, with all its checks
    (another name, a scenario object, a split the batch does not take)."""
    factory = factories.get(spec) if isinstance(spec, str) else None
    if not core._batches(factory):
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
                core.act_lanes, k, actuation, core.actuation, core._actuation_lanes
            )
    core.names.set_many(lanes, name, ks)
    return ks


def lane_truth(scenarios: LaneObjects, lanes: np.ndarray, nominal, i: int):
    """The true parameters of lane ``lanes[i]``'s scenario (a deferred ``truths`` entry)."""
    return scenarios[int(lanes[i])].true_params(nominal)


class EpisodeLog:
    """The signals an env keeps for ``render()``: a list per name, each fed by one ``info`` key.

    Parameters
    ----------
    fields : dict of str to str
        Name of each signal -> the ``info`` key it is read from.

    >>> log = EpisodeLog({"t": "t_s", "force": "force_N"})
    >>> log.record({"t_s": 0.1, "force_N": 950.0, "scenario": "train"})
    >>> log["t"], log["force"]
    ([0.1], [950.0])
    """

    def __init__(self, fields: dict[str, str]) -> None:
        self.fields = dict(fields)
        self._signals: dict[str, list] = {name: [] for name in self.fields}

    def record(self, info: dict) -> None:
        """Append this step's value of every signal from its ``info``."""
        signals = self._signals
        for name, key in self.fields.items():
            signals[name].append(info[key])

    def __getitem__(self, name: str) -> list:
        return self._signals[name]


def record_step(env, log: EpisodeLog, info: dict) -> None:
    """The end of every env's ``step``: with a render mode, ``info`` goes into ``log``, and in
    ``"human"`` mode the window is drawn again."""
    if env.render_mode is not None:
        log.record(info)
        if env.render_mode == "human":
            env.render()


def ready_to_render(env) -> bool:
    """False (with a warning) without a render mode; ``RuntimeError`` before the first reset."""
    owner = type(env).__name__
    if env.render_mode is None:
        gym.logger.warn(
            f"{owner}.render() called without a render_mode; pass render_mode='rgb_array'"
        )
        return False
    if not env._started:
        raise RuntimeError(f"{owner}: call reset() before render()")
    return True


class LaneEnv(gym.Env, abc.ABC):
    """The single env of a process whose physics is a core of lanes: the core of one lane
    that its vector env holds N of, so that a lane and the single env run the same code.

    A subclass builds its core in ``__init__`` and hands it to :meth:`_adopt`, and says
    how an action goes in (:meth:`_set_action`), what a step gave (:meth:`_outcome`) and
    what it keeps of a new episode (:meth:`_began`); ``reset``, ``step`` and the command
    map are shared. The core provides ``start(lane, spec, rng)``, ``step()``,
    ``lane_info(lane)``, ``obs``, ``scenarios``, ``scenario_types`` (the scenario class
    and the names), ``params``, ``reward_weights``, ``max_episode_time_s``,
    ``command_map`` and the two spaces. ``_LOG_FIELDS`` names what a rendered episode
    records of ``info`` (:class:`EpisodeLog`).
    """

    _LOG_FIELDS: dict[str, str] = {}

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
    @abc.abstractmethod
    def _set_action(self, action) -> None:
        """Check ``action`` (``ValueError`` naming the env) and write it into lane 0 of the
        core, with whether it was clipped."""

    @abc.abstractmethod
    def _outcome(self) -> tuple[float, bool, bool]:
        """Lane 0's reward, terminated and truncated after a step, as Python values."""

    @abc.abstractmethod
    def _began(self, core) -> None:
        """Called when an episode has started (``self.scenario`` is set): what the env
        keeps of it (its ``plant``, its path)."""

    def _noted(self, info: dict) -> dict:
        """``info`` with the step's ``excess`` over the limit and the scenario's
        ``overload_ratio`` (the class's ``task.limit_keys``,
        :func:`machining_envs.core.metrics.note_severity`)."""
        task = getattr(type(self), "task", None)
        keys = getattr(task, "limit_keys", None)
        return note_severity(info, keys, getattr(self.scenario, "overload_ratio", math.inf))

    # ---- gymnasium API -------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        core = self._core
        spec = scenario_option(options, self.default_scenario)
        check_scenario_spec(spec, *core.scenario_types)  # refused: the episode goes on
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
