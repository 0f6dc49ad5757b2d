"""Variable-gain (adaptive) PI force controller of Noh, Kim & Kim (1992), after Masory & Koren."""

from __future__ import annotations

import numpy as np

from agents.base import Agent
from agents.pid import TurningIO, _positive

__all__ = ["VariableGainPI"]


class VariableGainPI(Agent):
    r"""PI controller whose gain holds the open-loop gain ``K = Kh Kp`` constant, eq. (15)-(16).

    .. math:: K_h = K / \hat K_p, \qquad \hat K_p = F_c / U

    ``Kp_hat`` is the measured force (counts) over the command now applied (counts): exact
    in steady state, since there ``F_c = K_p U`` (eq. 11). The PI law is that of
    :class:`~agents.pid.FixedGainPI` with Kh recomputed every sample.

    Start-up guard: while the command is below ``min_command_fraction`` of its range or the
    force below ``min_force_fraction`` of the reference, ``Fc / U`` is meaningless (0/0 at
    rest), so the previous estimate is kept; the first comes from the nominal model,
    eq. (11) at the reference force, the observed spindle speed and ``design_depth_mm``.

    Parameters
    ----------
    io : TurningIO
    k : float
        Designed open-loop gain K (paper: 0.5, inside the stable range 0 < K < 0.807).
    kgh : float
        Kgh = 1 + Kg/Kh (paper: 1.9).
    """

    state_size = 3  # [U_{k-1}, E_{k-1}, Kp_hat]
    obs_dim = 7

    def __init__(
        self,
        io: TurningIO,
        k: float = 0.5,
        kgh: float = 1.9,
        design_depth_mm: float = 2.0,
        min_command_fraction: float = 0.01,
        min_force_fraction: float = 0.05,
    ):
        self.io = io
        self.k = _positive("k", k, 100.0)
        self.kgh = _positive("kgh", kgh, 100.0)
        self.design_depth_mm = _positive("design_depth_mm", design_depth_mm, 10.0)
        self.min_command = (
            _positive("min_command_fraction", min_command_fraction, 1.0) * io.command_max
        )
        self.min_force_fraction = _positive("min_force_fraction", min_force_fraction, 1.0)
        self.name = f"adaptive PI K={k:g}"

    @classmethod
    def from_env(cls, env, k: float = 0.5, kgh: float = 1.9, **kwargs) -> VariableGainPI:
        return cls(TurningIO.from_env(env), k, kgh, **kwargs)

    def nominal_process_gain(self, spindle_rpm: np.ndarray, force_ref_N: np.ndarray) -> np.ndarray:
        """Kp of eq. (11) for the nominal plant at the reference force and the design depth."""
        p = self.io.params
        feed = p.feed_for_force(force_ref_N, self.design_depth_mm)
        return p.process_gain(spindle_rpm, self.design_depth_mm, feed)

    def initial_state(self, n, obs):
        st = np.zeros((n, self.state_size))
        fr_N = self.io.force_scale_N * obs[:, 1]
        fr_N = np.where(fr_N > 0, fr_N, self.io.force_scale_N)
        st[:, 2] = self.nominal_process_gain(self.io.spindle_rpm(obs), fr_N)
        return st

    def _act(self, obs, state):
        fm, fr = self.io.force_counts(obs)
        u_prev = state[:, 0]
        ok = (u_prev >= self.min_command) & (fm >= self.min_force_fraction * fr)
        kp_hat = np.where(ok, fm / np.where(ok, u_prev, 1.0), state[:, 2])
        kh = self.k / kp_hat
        e = fr - fm
        u = np.clip(u_prev + kh * (self.kgh * e - state[:, 1]), 0.0, self.io.command_max)
        state[:, 0] = u
        state[:, 1] = e
        state[:, 2] = kp_hat
        return self.io.action(u)
