"""End milling: hold the cutting torque by the feed (Park & Yoon 1986; Ahn & Choi).

``plant`` (feed servo, average-force model and its calibration, torque sensor),
``scenarios`` (the paper's step and taper workpieces, the train/test distributions),
``metrics`` (eq. 20 machining time, MRR; the task), ``env`` (``EndMilling-v0``).
"""

from machining_envs.core.lazy import lazy_exports

#: What this package exports, and the module each comes from (loaded on first use, so
#: that registering the ids imports none of the physics).
_EXPORTS = {
    "EndMillingEnv": "machining_envs.milling.env",
    "EndMillingVectorEnv": "machining_envs.milling.env",
    "MillingReward": "machining_envs.milling.env",
    "MillingParams": "machining_envs.milling.plant",
    "MillingPlant": "machining_envs.milling.plant",
    "MILLING_SCENARIOS": "machining_envs.milling.scenarios",
    "MillingScenario": "machining_envs.milling.scenarios",
}
__all__ = [*_EXPORTS, "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

#: The env ids of this process and their entry points (registered by ``machining_envs``).
ENTRY_POINTS = {"machining_envs/EndMilling-v0": "machining_envs.milling.env:EndMillingEnv"}
#: Their native vector envs (``gym.make_vec(id, num_envs=N)``).
VECTOR_ENTRY_POINTS = {
    "machining_envs/EndMilling-v0": "machining_envs.milling.env:EndMillingVectorEnv"
}
