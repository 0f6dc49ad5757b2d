"""The agent protocol: Stable-Baselines3's ``predict`` signature for classical controllers.

A controller keeps its integrators and estimates in ``state``, an array of shape
``(n_envs, state_size)`` returned by ``predict`` and passed back on the next call, the way
SB3's recurrent policies carry their hidden state. Rows where ``episode_start`` is true are
reset before acting. Observations may be one env's ``(obs_dim,)`` or a batch
``(n_envs, obs_dim)``; the action comes back in the same layout.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Agent", "unwrap"]


def unwrap(env):
    """The innermost env of a (possibly wrapped) gymnasium env."""
    return getattr(env, "unwrapped", env)


class Agent:
    """Base class of the classical controllers.

    Subclasses set ``name`` and ``state_size`` and implement :meth:`initial_state` and
    :meth:`_act`, which maps a batch of observations and states (updated in place) to a
    batch of actions in ``[-1, 1]``.
    """

    name: str = "agent"
    state_size: int = 0
    obs_dim: int | None = None

    def initial_state(self, n: int, obs: np.ndarray) -> np.ndarray:
        """State of ``n`` fresh episodes whose first observations are ``obs`` (n, obs_dim)."""
        return np.zeros((n, self.state_size))

    def _act(self, obs: np.ndarray, state: np.ndarray) -> np.ndarray:
        raise NotImplementedError  # pragma: no cover - abstract

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-compatible: ``(action, state) = predict(obs, state, episode_start, deterministic)``.

        ``deterministic`` is accepted for compatibility; classical controllers are always
        deterministic.
        """
        obs = np.asarray(observation, dtype=np.float64)
        single = obs.ndim == 1
        batch = obs[None, :] if single else obs
        if batch.ndim != 2 or (self.obs_dim is not None and batch.shape[1] != self.obs_dim):
            raise ValueError(
                f"{self.name}: observation must have shape ({self.obs_dim},) or "
                f"(n_envs, {self.obs_dim}), got {obs.shape}"
            )
        n = batch.shape[0]
        if state is None:
            st = self.initial_state(n, batch)
        else:
            st = np.array(state, dtype=np.float64, copy=True).reshape(n, self.state_size)
            if episode_start is not None:
                starts = np.asarray(episode_start, dtype=bool).reshape(-1)
                if starts.size != n:
                    raise ValueError(
                        f"{self.name}: episode_start has {starts.size} entries for {n} observations"
                    )
                if starts.any():
                    st[starts] = self.initial_state(int(starts.sum()), batch[starts])
        action = np.clip(self._act(batch, st), -1.0, 1.0).astype(np.float32)
        return (action[0] if single else action), st

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"
