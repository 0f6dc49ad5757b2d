"""Agents for the machining envs: the papers' classical controllers and RL policies.

Every agent follows Stable-Baselines3's ``predict`` signature, so classical controllers and
SB3 models run under one harness (and under SB3's own ``evaluate_policy``)::

    action, state = agent.predict(obs, state=None, episode_start=None, deterministic=True)

``import agents`` loads none of them: each class is imported on first use
(``from agents import VariableGainPI`` loads the turning controllers only).
"""

from __future__ import annotations

from machining_envs.core.lazy import lazy_exports

#: The classes this package exports, loaded on first use.
_EXPORTS = {
    "Agent": "agents.base",
    "AdaptiveFeedControl": "agents.afc",
    "ConstantFeed": "agents.turning",
    "FixedGainPI": "agents.turning",
    "VariableGainPI": "agents.turning",
    "DelayAwarePI": "agents.turning",
    "FixedGainIntegral": "agents.milling",
    "IntegralACC": "agents.milling",
    "MillingConstantFeed": "agents.milling",
    "ConstantOverride": "agents.contouring",
    "LookAheadFeed": "agents.contouring",
    "ContourAFC": "agents.contouring",
    "HInf2DOF": "agents.contouring",
    "PIPosition": "agents.contouring",
    "NoControl": "agents.drilling",
    "PD": "agents.drilling",
    "PeckDrilling": "agents.drilling",
    "TorquePeck": "agents.drilling",
    "VoltagePeck": "agents.drilling",
    "VoltageTorquePeck": "agents.drilling",
    "SlidingMode": "agents.drilling",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
