"""Micro-drilling: hold the drilling torque as chips pile up, by the spindle speed (Cheong & Cho).

``plant`` (valve, spindle, chip-packing torque and thrust), ``scenarios`` (the paper's
drills, the train/test distributions), ``metrics`` (torque statistics, drilling time; the
task), ``env`` (``MicroDrilling-v0``).
"""

from machining_envs.core.lazy import by_module, env_entry_points, lazy_exports

#: What this package exports, by the module each comes from (loaded on first use, so that
#: registering the ids imports none of the physics).
_EXPORTS = by_module(
    __name__,
    env=("DrillingReward", "MicroDrillingEnv", "MicroDrillingVectorEnv"),
    plant=("DrillingLanes", "DrillingParams", "DrillingPlant"),
    scenarios=("DRILLING_SCENARIOS", "DrillingScenario"),
)
__all__ = [*_EXPORTS, "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

#: The env ids of this process and their entry points, single and native vector env
#: (registered by ``machining_envs``).
ENTRY_POINTS, VECTOR_ENTRY_POINTS = env_entry_points(
    __name__,
    {"MicroDrilling-v0": ("env", "MicroDrillingEnv", "MicroDrillingVectorEnv")},
)
