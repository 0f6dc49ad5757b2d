"""The paper's H-infinity two-degree-of-freedom position controller, as an agent.

The design (``machining_envs.servo.hinf_2dof_design``) is synthesised once per axis model
with python-control's ``hinfsyn`` and cached; ``predict`` only runs its difference
equations (``agents.position.LinearServoAgent``).
"""

from __future__ import annotations

from agents.position import LinearServoAgent, contouring_params
from machining_envs.plants.contouring import AXES
from machining_envs.servo import HINF_RHO, hinf_2dof_design

__all__ = ["HInf2DOF"]


class HInf2DOF(LinearServoAgent):
    """Hoyle-Hyde-Limebeer 2-DOF H-infinity loop-shaping controller per axis (paper §4).

    Feedforward ``K1`` on the set point and feedback ``K2`` on the measured position,
    designed together so that the loop follows the reference model ``M0 = 500/(s + 500)``
    robustly, with the paper's loop-shaping weight ``W = 1e6/(s + 1e-3)``; the constant
    prefilter makes the steady state exact. ``gammas`` holds the achieved H-infinity norm
    of each axis's design (X, Y).

    >>> import gymnasium as gym
    >>> import machining_envs
    >>> agent = HInf2DOF.from_env(gym.make("machining_envs/Contouring-v0"))
    >>> [round(g, 2) for g in agent.gammas]
    [5.83, 6.01]
    """

    @classmethod
    def from_env(cls, env, rho: float = HINF_RHO) -> HInf2DOF:
        p = contouring_params(env)
        designs = tuple(hinf_2dof_design(p, ax, rho=rho) for ax in AXES)
        return cls(designs, p.command_max_mm_s, "H-inf 2-DOF")

    @property
    def gammas(self) -> tuple[float, float]:
        """Achieved gamma of the X and Y designs."""
        return tuple(float(d.gamma) for d in self.designs)
