"""machining_envs: Gymnasium environments for feed-rate control of machine tools.

Importing the package registers every env id under the ``machining_envs/`` namespace::

    import gymnasium as gym
    import machining_envs  # or gym.make("machining_envs:machining_envs/Turning-v0")

    env = gym.make("machining_envs/Turning-v0")
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from machining_envs import contouring, drilling, milling, turning
from machining_envs.contouring import (
    CONTOURING_SCENARIOS,
    ContouringEnv,
    ContouringFeedEnv,
    ContouringParams,
    ContouringReward,
    ContouringScenario,
    FeedReward,
    Path,
)
from machining_envs.core.workpieces import DepthProfile
from machining_envs.drilling import (
    DRILLING_SCENARIOS,
    DrillingParams,
    DrillingReward,
    DrillingScenario,
    MicroDrillingEnv,
)
from machining_envs.milling import (
    MILLING_SCENARIOS,
    EndMillingEnv,
    MillingParams,
    MillingReward,
    MillingScenario,
)
from machining_envs.turning import (
    TURNING_SCENARIOS,
    TurningEnv,
    TurningParams,
    TurningReward,
    TurningScenario,
)

__all__ = [
    "CONTOURING_SCENARIOS",
    "ContouringEnv",
    "ContouringFeedEnv",
    "FeedReward",
    "ContouringParams",
    "ContouringReward",
    "ContouringScenario",
    "Path",
    "DepthProfile",
    "TURNING_SCENARIOS",
    "TurningEnv",
    "TurningParams",
    "TurningReward",
    "TurningScenario",
    "ENV_IDS",
    "EndMillingEnv",
    "MILLING_SCENARIOS",
    "MillingParams",
    "MillingReward",
    "MillingScenario",
    "DRILLING_SCENARIOS",
    "DrillingParams",
    "DrillingReward",
    "DrillingScenario",
    "MicroDrillingEnv",
]
__version__ = "0.1.0"

#: Every env id this package registers, with its entry point (each process declares its own).
_ENTRY_POINTS = {
    **turning.ENTRY_POINTS,
    **milling.ENTRY_POINTS,
    **drilling.ENTRY_POINTS,
    **contouring.ENTRY_POINTS,
}
#: Native vector envs of the ids that have one (``gym.make_vec(id, num_envs=N)``).
_VECTOR_ENTRY_POINTS = {
    **turning.VECTOR_ENTRY_POINTS,
    **milling.VECTOR_ENTRY_POINTS,
    **drilling.VECTOR_ENTRY_POINTS,
    **contouring.VECTOR_ENTRY_POINTS,
}
ENV_IDS = tuple(_ENTRY_POINTS)

for _id, _entry in _ENTRY_POINTS.items():
    if _id not in registry:
        register(id=_id, entry_point=_entry, vector_entry_point=_VECTOR_ENTRY_POINTS.get(_id))
