"""Micro-drilling: hold the drilling torque as chips pile up, by the spindle speed (Cheong & Cho).

``plant`` (valve, spindle, chip-packing torque and thrust), ``scenarios`` (the paper's
drills, the train/test distributions), ``metrics`` (torque statistics, drilling time; the
task), ``env`` (``MicroDrilling-v0``).
"""

from machining_envs.core.lazy import process_package

#: What this package exports, by the module each comes from (loaded on first use, so that
#: registering the ids imports none of the physics), and the env ids of this process with
#: their entry points, single and native vector env (registered by ``machining_envs``).
__all__, __getattr__, __dir__, ENTRY_POINTS, VECTOR_ENTRY_POINTS = process_package(
    __name__,
    {"MicroDrilling-v0": ("env", "MicroDrillingEnv", "MicroDrillingVectorEnv")},
    env=("DrillingReward", "MicroDrillingEnv", "MicroDrillingVectorEnv"),
    plant=("DrillingLanes", "DrillingParams", "DrillingPlant"),
    scenarios=("DRILLING_SCENARIOS", "DrillingScenario"),
)
