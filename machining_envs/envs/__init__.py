"""Gymnasium environments, one module per machining process."""

from machining_envs.envs.end_milling import EndMillingEnv, MillingReward
from machining_envs.envs.turning import TurningEnv, TurningReward

__all__ = ["TurningEnv", "TurningReward", "EndMillingEnv", "MillingReward"]
