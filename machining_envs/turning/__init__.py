"""Turning: hold the cutting force by the feed (Noh, Kim & Kim 1992).

``plant`` (feed servo, force law, sensor), ``scenarios`` (stepped and tapered bars, the
train/test distributions), ``metrics`` (the task: metrics and primary score), ``env``
(``Turning-v0``).
"""

from machining_envs.turning.env import TurningEnv, TurningReward, TurningVectorEnv
from machining_envs.turning.plant import TurningParams, TurningPlant
from machining_envs.turning.scenarios import TURNING_SCENARIOS, TurningScenario

__all__ = [
    "TurningEnv",
    "TurningVectorEnv",
    "TurningReward",
    "TurningParams",
    "TurningPlant",
    "TurningScenario",
]
__all__ += ["TURNING_SCENARIOS", "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]

#: The env ids of this process and their entry points (registered by ``machining_envs``).
ENTRY_POINTS = {"machining_envs/Turning-v0": "machining_envs.turning.env:TurningEnv"}
#: Their native vector envs (``gym.make_vec(id, num_envs=N)``).
VECTOR_ENTRY_POINTS = {"machining_envs/Turning-v0": "machining_envs.turning.env:TurningVectorEnv"}
