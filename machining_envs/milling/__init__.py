"""End milling: hold the cutting torque by the feed (Park & Yoon 1986; Ahn & Choi).

``plant`` (feed servo, average-force model and its calibration, torque sensor),
``scenarios`` (the paper's step and taper workpieces, the train/test distributions),
``metrics`` (eq. 20 machining time, MRR; the task), ``env`` (``EndMilling-v0``).
"""

from machining_envs.core.lazy import process_package

#: What this package exports, by the module each comes from (loaded on first use, so that
#: registering the ids imports none of the physics), and the env ids of this process with
#: their entry points, single and native vector env (registered by ``machining_envs``).
__all__, __getattr__, __dir__, ENTRY_POINTS, VECTOR_ENTRY_POINTS = process_package(
    __name__,
    {"EndMilling-v0": ("env", "EndMillingEnv", "EndMillingVectorEnv")},
    env=("EndMillingEnv", "EndMillingVectorEnv", "MillingReward"),
    plant=("MillingParams", "MillingPlant"),
    scenarios=("MILLING_SCENARIOS", "MillingScenario"),
)
