"""The agent protocol: Stable-Baselines3's ``predict`` signature for classical controllers.

A controller keeps its integrators and estimates in ``state``, an array of shape
``(n_envs, state_size)`` returned by ``predict`` and passed back on the next call, the way
SB3's recurrent policies carry their hidden state. Rows where ``episode_start`` is true are
reset before acting. Observations may be one env's ``(obs_dim,)`` or a batch
``(n_envs, obs_dim)``; the action comes back in the same layout.
"""

from __future__ import annotations

import numpy as np

from machining_envs.core.checks import PY_NUMBER_TYPES, check_range

__all__ = [
    "Agent",
    "ProcessController",
    "SETPOINT_SEARCH",
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


class ProcessController(Agent):
    """A controller designed from what a process's env tells of its nominal machine.

    Subclasses set ``io_type``, a class whose ``from_env(env)`` reads the env's nominal
    constants (``agents.turning.TurningIO``, ...), and take that object as the first
    argument of ``__init__``.
    """

    io_type: type

    @classmethod
    def from_env(cls, env, *args, **kwargs):
        """The controller for ``env``, designed from its nominal constants only:
        ``cls(cls.io_type.from_env(env), *args, **kwargs)``, with the settings of the
        class's own parameters. ``TypeError`` if ``env`` is not of the controller's process.
        """
        return cls(cls.io_type.from_env(env), *args, **kwargs)
