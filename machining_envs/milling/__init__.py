"""End milling: hold the cutting torque by the feed (Park & Yoon 1986; Ahn & Choi).

``plant`` (feed servo, average-force model and its calibration, torque sensor),
``scenarios`` (the paper's step and taper workpieces, the train/test distributions),
``metrics`` (eq. 20 machining time, MRR; the task), ``env`` (``EndMilling-v0``).
"""

from machining_envs.core.lazy import by_module, env_entry_points, lazy_exports

#: What this package exports, by the module each comes from (loaded on first use, so that
#: registering the ids imports none of the physics).
_EXPORTS = by_module(
    __name__,
    env=("EndMillingEnv", "EndMillingVectorEnv", "MillingReward"),
    plant=("MillingParams", "MillingPlant"),
    scenarios=("MILLING_SCENARIOS", "MillingScenario"),
)
__all__ = [*_EXPORTS, "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

#: The env ids of this process and their entry points, single and native vector env
#: (registered by ``machining_envs``).
ENTRY_POINTS, VECTOR_ENTRY_POINTS = env_entry_points(
    __name__,
    {"EndMilling-v0": ("env", "EndMillingEnv", "EndMillingVectorEnv")},
)
