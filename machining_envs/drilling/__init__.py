"""Micro-drilling: hold the drilling torque as chips pile up, by the spindle speed (Cheong & Cho).

``plant`` (valve, spindle, chip-packing torque and thrust), ``scenarios`` (the paper's
drills, the train/test distributions), ``metrics`` (torque statistics, drilling time; the
task), ``env`` (``MicroDrilling-v0``).
"""

from machining_envs.drilling.env import DrillingReward, MicroDrillingEnv, MicroDrillingVectorEnv
from machining_envs.drilling.plant import DrillingLanes, DrillingParams, DrillingPlant
from machining_envs.drilling.scenarios import DRILLING_SCENARIOS, DrillingScenario

__all__ = ["MicroDrillingEnv", "MicroDrillingVectorEnv", "DrillingReward", "DrillingParams"]
__all__ += ["DrillingPlant", "DrillingLanes", "DrillingScenario", "DRILLING_SCENARIOS"]
__all__ += ["ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]

#: The env ids of this process and their entry points (registered by ``machining_envs``).
ENTRY_POINTS = {
    "machining_envs/MicroDrilling-v0": "machining_envs.drilling.env:MicroDrillingEnv",
}
#: Their native vector envs (``gym.make_vec(id, num_envs=N)``).
VECTOR_ENTRY_POINTS = {
    "machining_envs/MicroDrilling-v0": "machining_envs.drilling.env:MicroDrillingVectorEnv",
}
