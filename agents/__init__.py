"""Agents for the machining envs: the papers' classical controllers and RL policies.

Every agent follows Stable-Baselines3's ``predict`` signature, so classical controllers and
SB3 models run under one harness (and under SB3's own ``evaluate_policy``)::

    action, state = agent.predict(obs, state=None, episode_start=None, deterministic=True)
"""

from agents.base import Agent
from agents.contouring import ConstantOverride, HInf2DOF, LookAheadFeed, PIPosition
from agents.drilling import PD, NoControl, PeckDrilling, SlidingMode
from agents.milling import FixedGainIntegral, IntegralACC, MillingConstantFeed
from agents.turning import ConstantFeed, FixedGainPI, VariableGainPI

__all__ = [
    "Agent",
    "ConstantFeed",
    "FixedGainPI",
    "VariableGainPI",
    "FixedGainIntegral",
    "IntegralACC",
    "MillingConstantFeed",
    "ConstantOverride",
    "LookAheadFeed",
    "HInf2DOF",
    "PIPosition",
]
__all__ += ["NoControl", "PD", "PeckDrilling", "SlidingMode"]
