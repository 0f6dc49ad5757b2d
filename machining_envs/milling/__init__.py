"""End milling: hold the cutting torque by the feed (Park & Yoon 1986; Ahn & Choi).

``plant`` (feed servo, average-force model and its calibration, torque sensor),
``scenarios`` (the paper's step and taper workpieces, the train/test distributions),
``metrics`` (eq. 20 machining time, MRR; the task), ``env`` (``EndMilling-v0``).
"""

from machining_envs.milling.env import EndMillingEnv, EndMillingVectorEnv, MillingReward
from machining_envs.milling.plant import MillingParams, MillingPlant
from machining_envs.milling.scenarios import MILLING_SCENARIOS, MillingScenario

__all__ = [
    "EndMillingEnv",
    "EndMillingVectorEnv",
    "MillingReward",
    "MillingParams",
    "MillingPlant",
    "MillingScenario",
]
__all__ += ["MILLING_SCENARIOS", "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]

#: The env ids of this process and their entry points (registered by ``machining_envs``).
ENTRY_POINTS = {"machining_envs/EndMilling-v0": "machining_envs.milling.env:EndMillingEnv"}
#: Their native vector envs (``gym.make_vec(id, num_envs=N)``).
VECTOR_ENTRY_POINTS = {
    "machining_envs/EndMilling-v0": "machining_envs.milling.env:EndMillingVectorEnv"
}
