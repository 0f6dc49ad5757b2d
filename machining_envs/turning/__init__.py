"""Turning: hold the cutting force by the feed (Noh, Kim & Kim 1992).

``plant`` (feed servo, force law, sensor), ``scenarios`` (stepped and tapered bars, the
train/test distributions), ``metrics`` (the task: metrics and primary score), ``env``
(``Turning-v0``).
"""

from machining_envs.core.lazy import process_package

#: What this package exports, by the module each comes from (loaded on first use, so that
#: registering the ids imports none of the physics), and the env ids of this process with
#: their entry points, single and native vector env (registered by ``machining_envs``).
__all__, __getattr__, __dir__, ENTRY_POINTS, VECTOR_ENTRY_POINTS = process_package(
    __name__,
    {"Turning-v0": ("env", "TurningEnv", "TurningVectorEnv")},
    env=("TurningEnv", "TurningReward", "TurningVectorEnv"),
    plant=("TurningParams", "TurningPlant"),
    scenarios=("TURNING_SCENARIOS", "TurningScenario"),
)
