"""Position controllers for the contouring envs: a PI loop per axis, and their common runner.

Every controller here is a discrete linear system per axis from the set point and the
measured position to the velocity command, designed once from the env's nominal parameters
(``machining_envs.servo``) and run as difference equations in ``predict``. It reads only the
observation: the set point and the tracking error (the table's position is their
difference).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import block_diag

from agents.base import Agent, unwrap
from machining_envs.envs.contouring import ERROR_SCALE_MM, POSITION_SCALE_MM, ContouringEnv
from machining_envs.plants.contouring import AXES, ContouringParams
from machining_envs.servo import ServoDesign, pi_design

__all__ = ["LinearServoAgent", "PIPosition", "contouring_params"]

_I = ContouringEnv.OBS_INDEX


def contouring_params(env) -> ContouringParams:
    """The nominal parameters of a (possibly wrapped) ``ContouringEnv``."""
    base = unwrap(env)
    if not isinstance(base, ContouringEnv):
        raise TypeError(f"a contouring controller needs a ContouringEnv, got {type(base).__name__}")
    return base.params


class LinearServoAgent(Agent):
    """Runs one discrete controller per axis (``ServoDesign``) on Contouring-v0 observations.

    State per env: both axes' controller states, then the table's position at the episode's
    start (the origin the controllers' inputs are taken from; see ``machining_envs.servo``).
    """

    obs_dim = 14

    def __init__(
        self, designs: tuple[ServoDesign, ServoDesign], command_max_mm_s: float, name: str
    ):
        if len(designs) != 2:
            raise ValueError(f"designs must hold one ServoDesign per axis, got {len(designs)}")
        self.designs = tuple(designs)
        self.name = name
        self.command_max_mm_s = float(command_max_mm_s)
        self._nx = sum(d.n_states for d in designs)
        self.state_size = self._nx + 2
        # Both axes as one block-diagonal system on inputs [r_x, y_x, r_y, y_y], as one
        # matrix: [xi, inputs] @ M = [next xi, commands].
        a = block_diag(*(d.a for d in designs))
        b = block_diag(*(d.b for d in designs))
        c = block_diag(*(d.c for d in designs))
        d = block_diag(*(d.d for d in designs))
        self._m = np.block([[a.T, c.T], [b.T, d.T]])

    @staticmethod
    def _positions(obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Set points and table positions (n, 2), mm, from a batch of observations."""
        i, j = _I["reference"], _I["error"]
        r = obs[:, i : i + 2] * POSITION_SCALE_MM
        return r, r - obs[:, j : j + 2] * ERROR_SCALE_MM

    def initial_state(self, n: int, obs: np.ndarray) -> np.ndarray:
        st = np.zeros((n, self.state_size))
        st[:, self._nx :] = self._positions(obs)[1]
        return st

    def _act(self, obs, state):
        r, y = self._positions(obs)
        nx = self._nx
        origin = state[:, nx:]
        z = np.empty((obs.shape[0], nx + 4))
        z[:, :nx] = state[:, :nx]
        z[:, nx::2] = r - origin
        z[:, nx + 1 :: 2] = y - origin
        out = z @ self._m
        state[:, :nx] = out[:, :nx]
        return out[:, nx:] / self.command_max_mm_s

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """As :meth:`Agent.predict`; one env's observation with a carried state and no new
        episode takes a shorter path (the servo runs 5000 times a simulated second)."""
        if (
            state is not None
            and isinstance(observation, np.ndarray)
            and observation.shape == (self.obs_dim,)
            and isinstance(state, np.ndarray)
            and state.shape == (1, self.state_size)
            and (
                episode_start is None
                or (
                    isinstance(episode_start, np.ndarray)
                    and episode_start.size == 1
                    and not episode_start.item()
                )
            )
        ):
            nx = self._nx
            o = observation.tolist()
            i, j = _I["reference"], _I["error"]
            st = state.copy()
            ox, oy = st[0, nx:].tolist()
            rx, ry = o[i] * POSITION_SCALE_MM, o[i + 1] * POSITION_SCALE_MM
            yx, yy = rx - o[j] * ERROR_SCALE_MM, ry - o[j + 1] * ERROR_SCALE_MM
            z = np.concatenate([st[0, :nx], (rx - ox, yx - ox, ry - oy, yy - oy)])
            out = z @ self._m
            st[0, :nx] = out[:nx]
            umax = self.command_max_mm_s
            ux, uy = (out[nx:] / umax).tolist()
            act = [min(max(ux, -1.0), 1.0), min(max(uy, -1.0), 1.0)]
            return np.array(act, dtype=np.float32), st
        return super().predict(observation, state, episode_start, deterministic)


class PIPosition(LinearServoAgent):
    """PI position controller per axis, tuned by pole placement without overshoot.

    ``u = Kp (b r - y) + Ki int(r - y)`` with ``Kp = a/3``, ``Ki = a^2/27``, ``b = 1/3``
    for the axis ``a / (s (s + a))``: the three closed-loop poles at ``-a/3`` (the fastest
    critically damped placement) and the set-point weight that cancels one of them, so the
    step response is ``p^2 / (s + p)^2`` (no overshoot); see ``machining_envs.servo.pi_design``.
    Designed from the env's nominal parameters; discretised by Tustin at the servo rate.
    """

    @classmethod
    def from_env(cls, env) -> PIPosition:
        p = contouring_params(env)
        designs = tuple(pi_design(p, ax) for ax in AXES)
        return cls(designs, p.command_max_mm_s, "PI position")
