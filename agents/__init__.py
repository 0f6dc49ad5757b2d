"""Agents for the machining envs: the papers' classical controllers and RL policies.

Every agent follows Stable-Baselines3's ``predict`` signature, so classical controllers and
SB3 models run under one harness (and under SB3's own ``evaluate_policy``)::

    action, state = agent.predict(obs, state=None, episode_start=None, deterministic=True)
"""

from agents.adaptive import VariableGainPI
from agents.base import Agent
from agents.drilling import PD, NoControl
from agents.feed import ConstantOverride
from agents.hinf import HInf2DOF
from agents.integral import FixedGainIntegral, IntegralACC, MillingConstantFeed
from agents.peck import PeckDrilling
from agents.pid import ConstantFeed, FixedGainPI
from agents.position import PIPosition
from agents.sliding_mode import SlidingMode

__all__ = [
    "Agent",
    "ConstantFeed",
    "FixedGainPI",
    "VariableGainPI",
    "FixedGainIntegral",
    "IntegralACC",
    "MillingConstantFeed",
    "ConstantOverride",
    "HInf2DOF",
    "PIPosition",
]
__all__ += ["NoControl", "PD", "PeckDrilling", "SlidingMode"]
