"""Turning: hold the cutting force by the feed (Noh, Kim & Kim 1992).

``plant`` (feed servo, force law, sensor), ``scenarios`` (stepped and tapered bars, the
train/test distributions), ``metrics`` (the task: metrics and primary score), ``env``
(``Turning-v0``).
"""

from machining_envs.core.lazy import lazy_exports

#: What this package exports, and the module each comes from (loaded on first use, so
#: that registering the ids imports none of the physics).
_EXPORTS = {
    "TurningEnv": "machining_envs.turning.env",
    "TurningReward": "machining_envs.turning.env",
    "TurningVectorEnv": "machining_envs.turning.env",
    "TurningParams": "machining_envs.turning.plant",
    "TurningPlant": "machining_envs.turning.plant",
    "TURNING_SCENARIOS": "machining_envs.turning.scenarios",
    "TurningScenario": "machining_envs.turning.scenarios",
}
__all__ = [*_EXPORTS, "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

#: The env ids of this process and their entry points (registered by ``machining_envs``).
ENTRY_POINTS = {"machining_envs/Turning-v0": "machining_envs.turning.env:TurningEnv"}
#: Their native vector envs (``gym.make_vec(id, num_envs=N)``).
VECTOR_ENTRY_POINTS = {"machining_envs/Turning-v0": "machining_envs.turning.env:TurningVectorEnv"}
