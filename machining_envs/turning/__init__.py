"""Turning: hold the cutting force by the feed (Noh, Kim & Kim 1992).

``plant`` (feed servo, force law, sensor), ``scenarios`` (stepped and tapered bars, the
train/test distributions), ``metrics`` (the task: metrics and primary score), ``env``
(``Turning-v0``).
"""

from machining_envs.core.lazy import by_module, env_entry_points, lazy_exports

#: What this package exports, by the module each comes from (loaded on first use, so that
#: registering the ids imports none of the physics).
_EXPORTS = by_module(
    __name__,
    env=("TurningEnv", "TurningReward", "TurningVectorEnv"),
    plant=("TurningParams", "TurningPlant"),
    scenarios=("TURNING_SCENARIOS", "TurningScenario"),
)
__all__ = [*_EXPORTS, "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

#: The env ids of this process and their entry points, single and native vector env
#: (registered by ``machining_envs``).
ENTRY_POINTS, VECTOR_ENTRY_POINTS = env_entry_points(
    __name__,
    {"Turning-v0": ("env", "TurningEnv", "TurningVectorEnv")},
)
