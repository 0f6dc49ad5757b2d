"""Micro-drilling: hold the drilling torque as chips pile up, by the spindle speed (Cheong & Cho).

``plant`` (valve, spindle, chip-packing torque and thrust), ``scenarios`` (the paper's
drills, the train/test distributions), ``metrics`` (torque statistics, drilling time; the
task), ``env`` (``MicroDrilling-v0``).
"""

from machining_envs.core.lazy import lazy_exports

#: What this package exports, and the module each comes from (loaded on first use, so
#: that registering the ids imports none of the physics).
_EXPORTS = {
    "DrillingReward": "machining_envs.drilling.env",
    "MicroDrillingEnv": "machining_envs.drilling.env",
    "MicroDrillingVectorEnv": "machining_envs.drilling.env",
    "DrillingLanes": "machining_envs.drilling.plant",
    "DrillingParams": "machining_envs.drilling.plant",
    "DrillingPlant": "machining_envs.drilling.plant",
    "DRILLING_SCENARIOS": "machining_envs.drilling.scenarios",
    "DrillingScenario": "machining_envs.drilling.scenarios",
}
__all__ = [*_EXPORTS, "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

#: The env ids of this process and their entry points (registered by ``machining_envs``).
ENTRY_POINTS = {
    "machining_envs/MicroDrilling-v0": "machining_envs.drilling.env:MicroDrillingEnv",
}
#: Their native vector envs (``gym.make_vec(id, num_envs=N)``).
VECTOR_ENTRY_POINTS = {
    "machining_envs/MicroDrilling-v0": "machining_envs.drilling.env:MicroDrillingVectorEnv",
}
