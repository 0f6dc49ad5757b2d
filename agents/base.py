"""The agent protocol: Stable-Baselines3's ``predict`` signature for classical controllers.

A controller keeps its integrators and estimates in ``state``, an array of shape
``(n_envs, state_size)`` returned by ``predict`` and passed back on the next call, the way
SB3's recurrent policies carry their hidden state. Rows where ``episode_start`` is true are
reset before acting. Observations may be one env's ``(obs_dim,)`` or a batch
``(n_envs, obs_dim)``; the action comes back in the same layout.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass

import numpy as np

from machining_envs.core.checks import PY_NUMBER_TYPES, check_range

__all__ = [
    "Agent",
    "ProcessController",
    "CommandIO",
    "SETPOINT_SEARCH",
    "SETPOINT",
    "Setting",
    "tunable",
    "unwrap",
    "unwrap_as",
    "check_setting",
    "check_positive",
    "check_positive_number",
    "check_observation",
    "observation_field",
]


#: The search range (low, high, log scale) of a regulator's ``setpoint``, its share of the
#: observed limit, in every ``TUNABLE``: the papers regulate at the limit (1.0); tuning may
#: keep a margin below it, down to half.
SETPOINT_SEARCH = (0.5, 1.0, False)


@dataclass(frozen=True)
class Setting:
    """One keyword setting of a controller: its default, the values it accepts and, for a
    free parameter, the range tuning searches.

    A controller lists its settings in ``SETTINGS`` (name -> ``Setting``, in the order of
    its constructor's arguments after the design input); :meth:`Agent.configure` checks
    them and keeps each as an attribute of the same name, and those with a ``search``
    range are the class's ``TUNABLE`` (:func:`tunable`).
    """

    default: object
    """The value when none is given (``None``: the controller works one out)."""
    hi: float | None = 1e9
    """The largest value accepted; ``None``: the controller checks the value itself (a
    range that depends on the machine). ``None`` is accepted where it is the default."""
    lo: float = 0.0
    """The smallest value accepted (excluded while ``lo_open``)."""
    lo_open: bool = True
    """Accept ``(lo, hi]`` rather than ``[lo, hi]``."""
    search: tuple[float, float, bool] | None = None
    """The range tuning searches, ``(low, high, log scale)``; ``None``: not tuned."""

    def check(self, name: str, value, types: tuple[type, ...] | None = None):
        """``value`` checked by :func:`check_setting` (as a float), or as given where the
        range is the controller's own or ``value`` is a ``None`` default."""
        if self.hi is None or (value is None and self.default is None):
            return value
        kind = {} if types is None else {"types": types}
        return check_setting(name, value, self.lo, self.hi, lo_open=self.lo_open, **kind)


#: A regulator's ``setpoint``: its share of the observed limit, in (0, 1.5], 1.0 (the
#: papers' choice) by default, searched over :data:`SETPOINT_SEARCH`.
SETPOINT = Setting(1.0, hi=1.5, search=SETPOINT_SEARCH)


def tunable(settings: dict[str, Setting], *names: str) -> dict[str, tuple[float, float, bool]]:
    """The free parameters of ``settings`` (those with a search range) and their search
    ranges: a class's ``TUNABLE``, in the table's order or that of ``names`` (the order
    tuning draws them in)."""
    names = names or tuple(settings)
    return {k: settings[k].search for k in names if settings[k].search is not None}


def observation_field(index: int, obs_index: dict | None) -> str:
    """The name of entry ``index`` of an observation whose fields start at the indices of
    ``obs_index`` (an env's ``OBS_INDEX``): ``"observation[5] (history[1])"``, or
    ``"observation[5]"`` without names."""
    if not obs_index:
        return f"observation[{index}]"
    starts = sorted((i, name) for name, i in obs_index.items() if i <= index)
    if not starts:
        return f"observation[{index}]"
    start, name = starts[-1]
    width = sorted(i for i in obs_index.values() if i > start)
    single = bool(width) and width[0] == start + 1
    field = name if single else f"{name}[{index - start}]"
    return f"observation[{index}] ({field})"


def check_observation(who: str, obs: np.ndarray, obs_index: dict | None = None) -> None:
    """``ValueError`` naming ``who`` and the first non-finite entry of ``obs`` (a batch
    ``(n, obs_dim)``), so that NaN or inf never reaches a controller's state."""
    bad = ~np.isfinite(obs)
    if bad.any():
        lane, index = (int(v) for v in np.argwhere(bad)[0])
        where = f" of env {lane}" if obs.shape[0] > 1 else ""
        raise ValueError(
            f"{who}: {observation_field(index, obs_index)}{where} is {obs[lane, index]!r} "
            "(not finite); the state passed in is left unchanged"
        )


def unwrap(env):
    """The innermost env of a (possibly wrapped) gymnasium env."""
    return getattr(env, "unwrapped", env)


def unwrap_as(env, env_cls: type, who: str):
    """The innermost env of ``env``, which must be an ``env_cls``.

    Parameters
    ----------
    env : gymnasium.Env
        The env, possibly wrapped.
    env_cls : type
        The env class the controller is built for.
    who : str
        The controller, for the message (``"a turning controller"``).

    Raises
    ------
    TypeError
        ``"{who} needs a {env_cls}, got {class of the innermost env}"`` (``an`` before a
        vowel).
    """
    base = unwrap(env)
    if not isinstance(base, env_cls):
        name = env_cls.__name__
        article = "an" if name[:1] in "AEIOU" else "a"
        raise TypeError(f"{who} needs {article} {name}, got {type(base).__name__}")
    return base


def check_setting(name: str, value, lo: float, hi: float, **kind) -> float:
    """A controller setting as a float if it is a finite number in ``[lo, hi]``.

    ``machining_envs.core.checks.check_range`` with the bounds printed by ``:g``; ``kind``
    is its ``lo_open``, ``types`` and ``allow_bool``. ``ValueError``: ``"{name} must be in
    [lo, hi], got {value!r}"``.
    """
    return check_range(name, value, lo, hi, bound_format="g", **kind)


def check_positive(name: str, value, hi: float = 1e9, **kind) -> float:
    """A controller setting (a gain, a time) as a float if it is a finite number in ``(0, hi]``.

    See :func:`check_setting`; the message is ``"{name} must be in (0, hi], got {value!r}"``.

    >>> check_positive("kc", 0.2, 1e6)
    0.2
    >>> check_positive("kc", 0, 1e6)
    Traceback (most recent call last):
    ...
    ValueError: kc must be in (0, 1e+06], got 0
    """
    return check_setting(name, value, 0, hi, lo_open=True, **kind)


def check_positive_number(name: str, value, hi: float = 1e9) -> float:
    """:func:`check_positive` of a setting that must be a Python ``int`` or ``float``
    (``machining_envs.core.checks.PY_NUMBER_TYPES``: no bool, no array, no numpy scalar
    but ``np.float64``, a ``float``).

    >>> check_positive_number("setpoint", 0.9, 1.5)
    0.9
    >>> check_positive_number("setpoint", np.float32(0.5), 1.5)
    Traceback (most recent call last):
    ...
    ValueError: setpoint must be in (0, 1.5], got np.float32(0.5)
    """
    return check_positive(name, value, hi, types=PY_NUMBER_TYPES)


class Agent:
    """Base class of the classical controllers.

    Subclasses set ``name`` and ``state_size`` and implement :meth:`initial_state` and
    :meth:`_act`, which maps a batch of observations and states (updated in place) to a
    batch of actions in ``[-1, 1]``.
    """

    name: str = "agent"
    state_size: int = 0
    obs_dim: int | None = None
    #: The env's ``OBS_INDEX`` (field name -> first index), for error messages.
    obs_index: dict | None = None
    #: The keyword settings (:class:`Setting`) that :meth:`configure` checks and keeps. A
    #: class that lists them gets ``TUNABLE`` (its free parameters and their search ranges
    #: for ``agents.bench.tune``) from them unless it declares its own.
    SETTINGS: dict[str, Setting] = {}
    #: What counts as a number in a setting (``None``: any real number; a process's
    #: controllers may take Python numbers only, ``PY_NUMBER_TYPES``).
    setting_types: tuple[type, ...] | None = None
    _settings_signature = inspect.Signature([])

    def __init_subclass__(cls, **kwargs):
        """A class that lists its own ``SETTINGS`` gets the signature they make (its
        ``__init__``'s named arguments, then the settings with their defaults) and, unless it
        declares one, the ``TUNABLE`` they make."""
        super().__init_subclass__(**kwargs)
        if "SETTINGS" not in cls.__dict__:
            return
        if "TUNABLE" not in cls.__dict__:
            cls.TUNABLE = tunable(cls.SETTINGS)
        kind = inspect.Parameter.POSITIONAL_OR_KEYWORD
        cls._settings_signature = inspect.Signature(
            [inspect.Parameter(k, kind, default=s.default) for k, s in cls.SETTINGS.items()]
        )
        named = [
            p
            for p in list(inspect.signature(cls.__init__).parameters.values())[1:]
            if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
        ]
        cls.__signature__ = inspect.Signature(
            named + list(cls._settings_signature.parameters.values())
        )

    def configure(self, args: tuple, kwargs: dict) -> None:
        """Binds the constructor's further ``args`` and ``kwargs`` to ``SETTINGS`` (in order,
        then by name; ``TypeError`` as for a call), checks each (``ValueError`` naming it
        and its range) and keeps it as an attribute of its name."""
        try:
            given = self._settings_signature.bind(*args, **kwargs).arguments
        except TypeError as e:
            raise TypeError(f"{type(self).__name__}(): {e}") from None
        for name, setting in self.SETTINGS.items():
            value = given.get(name, setting.default)
            setattr(self, name, setting.check(name, value, self.setting_types))

    def initial_state(self, n: int, obs: np.ndarray) -> np.ndarray:
        """State of ``n`` fresh episodes whose first observations are ``obs`` (n, obs_dim)."""
        return np.zeros((n, self.state_size))

    def _act(self, obs: np.ndarray, state: np.ndarray) -> np.ndarray:
        raise NotImplementedError  # pragma: no cover - abstract

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-compatible: ``(action, state) = predict(obs, state, episode_start, deterministic)``.

        ``deterministic`` is accepted for compatibility; classical controllers are always
        deterministic. The state passed in is never modified (a new one is returned).

        Raises
        ------
        ValueError
            The observation is not real numbers of shape ``(obs_dim,)`` or ``(n_envs,
            obs_dim)``, an entry is NaN or infinite (the message names the entry), or
            ``state`` / ``episode_start`` do not fit the observations or ``state`` is not
            finite.
        """
        batch, single, st = self._checked_step(observation, state, episode_start)
        # np.clip's numbers without its wrapper (a few microseconds a call)
        action = np.minimum(np.maximum(self._act(batch, st), -1.0), 1.0).astype(np.float32)
        return (action[0] if single else action), st

    def _checked_step(
        self, observation, state, episode_start
    ) -> tuple[np.ndarray, bool, np.ndarray]:
        """What :meth:`predict` acts on: the observations as a checked float batch
        ``(n, obs_dim)``, whether one env's observation was given, and the state (a new
        array: ``initial_state`` where ``state`` is None, else ``state`` checked, with the
        rows of the envs whose ``episode_start`` is set started again)."""
        batch, single = self._observations(observation)
        n = batch.shape[0]
        if state is None:
            return batch, single, self.initial_state(n, batch)
        st = self._state(state, n)
        if episode_start is not None:
            starts = self._starts(episode_start, n)
            if starts.any():
                st[starts] = self.initial_state(int(starts.sum()), batch[starts])
        return batch, single, st

    def _observations(self, observation) -> tuple[np.ndarray, bool]:
        """The observations as a float batch ``(n, obs_dim)``, checked, and whether one env's
        observation was given."""
        if isinstance(observation, (str, bytes)):
            raise ValueError(f"{self.name}: observation must be real numbers, got {observation!r}")
        try:
            obs = np.asarray(observation)
            if obs.dtype.kind not in "biuf":
                raise TypeError
            obs = obs.astype(np.float64, copy=False)
        except (TypeError, ValueError):
            raise ValueError(
                f"{self.name}: observation must be real numbers of shape ({self.obs_dim},) or "
                f"(n_envs, {self.obs_dim}), got {observation!r:.80}"
            ) from None
        single = obs.ndim == 1
        batch = obs[None, :] if single else obs
        if batch.ndim != 2 or (self.obs_dim is not None and batch.shape[1] != self.obs_dim):
            raise ValueError(
                f"{self.name}: observation must have shape ({self.obs_dim},) or "
                f"(n_envs, {self.obs_dim}), got {obs.shape}"
            )
        check_observation(self.name, batch, self.obs_index)
        return batch, single

    def _state(self, state, n: int) -> np.ndarray:
        """A checked copy of the state passed in, shape ``(n, state_size)``."""
        try:
            st = np.array(state, dtype=np.float64, copy=True)
        except (TypeError, ValueError):
            raise ValueError(
                f"{self.name}: state must be the array predict() returned, got {state!r:.80}"
            ) from None
        if st.size != n * self.state_size:
            raise ValueError(
                f"{self.name}: state must have shape ({n}, {self.state_size}) for {n} "
                f"observation(s), got {st.shape}"
            )
        st = st.reshape(n, self.state_size)
        if not np.isfinite(st).all():
            lane, index = (int(v) for v in np.argwhere(~np.isfinite(st))[0])
            raise ValueError(
                f"{self.name}: state[{lane}, {index}] is {st[lane, index]!r} (not finite)"
            )
        return st

    def _starts(self, episode_start, n: int) -> np.ndarray:
        starts = np.asarray(episode_start, dtype=bool).reshape(-1)
        if starts.size != n:
            raise ValueError(
                f"{self.name}: episode_start has {starts.size} entries for {n} observations"
            )
        return starts

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


class CommandIO:
    """What a feed-regulation controller's machine description (``TurningIO``,
    ``MillingIO``) shares: commands in counts back to actions, through the env's
    ``command_map`` where the description keeps one, else affinely over
    ``[0, command_max]``."""

    command_max: float
    command_map = None

    def action(self, command: np.ndarray) -> np.ndarray:
        """Actions (n, 1) for commands (n,) in counts."""
        if self.command_map is not None:
            return self.command_map.command_to_action(command)[:, None]
        return (2.0 * command / self.command_max - 1.0)[:, None]


class ProcessController(Agent):
    """A controller designed from what a process's env tells of its nominal machine.

    Subclasses set ``io_type``, a class whose ``from_env(env)`` reads the env's nominal
    constants (``agents.turning.TurningIO``, ...), and take that object as the first
    argument of ``__init__``.
    """

    io_type: type

    def __init__(self, io, *args, **kwargs):
        """``io``, an ``io_type``; then the class's ``SETTINGS`` by position or name
        (:meth:`configure`), and :meth:`_setup`."""
        self.io = io
        self.configure(args, kwargs)
        self._setup()

    def _setup(self) -> None:
        """What the controller works out once its settings are kept (its ``name``, ...)."""

    @classmethod
    def from_env(cls, env, *args, **kwargs):
        """The controller for ``env``, designed from its nominal constants only:
        ``cls(cls.io_type.from_env(env), *args, **kwargs)``, with the settings of the
        class's own parameters. ``TypeError`` if ``env`` is not of the controller's process.
        """
        return cls(cls.io_type.from_env(env), *args, **kwargs)
