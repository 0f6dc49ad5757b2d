"""machining_envs: Gymnasium environments for feed-rate control of machine tools.

Importing the package registers every env id under the ``machining_envs/`` namespace::

    import gymnasium as gym
    import machining_envs  # or gym.make("machining_envs:machining_envs/Turning-v0")

    env = gym.make("machining_envs/Turning-v0")
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from machining_envs.contouring_scenarios import CONTOURING_SCENARIOS, ContouringScenario
from machining_envs.drilling_scenarios import DRILLING_SCENARIOS, DrillingScenario
from machining_envs.envs.contouring import ContouringEnv, ContouringReward
from machining_envs.envs.contouring_feed import ContouringFeedEnv, FeedReward
from machining_envs.envs.end_milling import EndMillingEnv, MillingReward
from machining_envs.envs.micro_drilling import DrillingReward, MicroDrillingEnv
from machining_envs.envs.turning import TurningEnv, TurningReward
from machining_envs.milling_scenarios import MILLING_SCENARIOS, MillingScenario
from machining_envs.paths import Path
from machining_envs.plants.contouring import ContouringParams
from machining_envs.plants.drilling import DrillingParams
from machining_envs.plants.milling import MillingParams
from machining_envs.plants.turning import TurningParams
from machining_envs.scenarios import TURNING_SCENARIOS, TurningScenario
from machining_envs.workpieces import DepthProfile

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

#: Every env id this package registers, with its entry point (one line per env).
_ENTRY_POINTS = {
    "machining_envs/Turning-v0": "machining_envs.envs.turning:TurningEnv",
    "machining_envs/EndMilling-v0": "machining_envs.envs.end_milling:EndMillingEnv",
    "machining_envs/MicroDrilling-v0": "machining_envs.envs.micro_drilling:MicroDrillingEnv",
    "machining_envs/Contouring-v0": "machining_envs.envs.contouring:ContouringEnv",
    "machining_envs/ContouringFeed-v0": "machining_envs.envs.contouring_feed:ContouringFeedEnv",
}
ENV_IDS = tuple(_ENTRY_POINTS)

for _id, _entry in _ENTRY_POINTS.items():
    if _id not in registry:
        register(id=_id, entry_point=_entry)
