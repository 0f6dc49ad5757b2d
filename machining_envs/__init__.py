"""machining_envs: Gymnasium environments for feed-rate control of machine tools.

Importing the package registers every env id under the ``machining_envs/`` namespace::

    import gymnasium as gym
    import machining_envs  # or gym.make("machining_envs:machining_envs/Turning-v0")

    env = gym.make("machining_envs/Turning-v0")
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from machining_envs import contouring, drilling, milling, turning
from machining_envs.core.lazy import lazy_exports

#: The classes this package exports, loaded on first use (``import machining_envs`` only
#: registers the ids, whose entry points are strings).
_EXPORTS = {
    "CONTOURING_SCENARIOS": "machining_envs.contouring",
    "ContouringEnv": "machining_envs.contouring",
    "ContouringFeedEnv": "machining_envs.contouring",
    "FeedReward": "machining_envs.contouring",
    "ContouringParams": "machining_envs.contouring",
    "ContouringReward": "machining_envs.contouring",
    "ContouringScenario": "machining_envs.contouring",
    "Path": "machining_envs.contouring",
    "DepthProfile": "machining_envs.core.workpieces",
    "LimitReward": "machining_envs.core.reward",
    "TURNING_SCENARIOS": "machining_envs.turning",
    "TurningEnv": "machining_envs.turning",
    "TurningParams": "machining_envs.turning",
    "TurningReward": "machining_envs.turning",
    "TurningScenario": "machining_envs.turning",
    "EndMillingEnv": "machining_envs.milling",
    "MILLING_SCENARIOS": "machining_envs.milling",
    "MillingParams": "machining_envs.milling",
    "MillingReward": "machining_envs.milling",
    "MillingScenario": "machining_envs.milling",
    "DRILLING_SCENARIOS": "machining_envs.drilling",
    "DrillingParams": "machining_envs.drilling",
    "DrillingReward": "machining_envs.drilling",
    "DrillingScenario": "machining_envs.drilling",
    "MicroDrillingEnv": "machining_envs.drilling",
}
__all__ = [*_EXPORTS, "ENV_IDS"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
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
