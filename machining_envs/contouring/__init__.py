"""Contouring: two feed axes following corners, circles and involutes (Choi et al.).

``plant`` (the two axis drives), ``paths`` (toolpaths: lines, arcs, involutes), ``servo``
(the CNC's position loops, PI and H-infinity 2-DOF, designed once), ``scenarios``,
``metrics`` (contour error, cycle time; the two tasks), ``env`` (``Contouring-v0``: the
axis commands) and ``feed_env`` (``ContouringFeed-v0``: the feed override over a servo).
"""

from machining_envs.core.lazy import by_module, env_entry_points, lazy_exports

#: What this package exports, by the module each comes from (loaded on first use, so that
#: registering the ids imports none of the physics).
_EXPORTS = by_module(
    __name__,
    env=("ContouringEnv", "ContouringReward", "ContouringVectorEnv"),
    feed_env=("ContouringFeedEnv", "ContouringFeedVectorEnv", "FeedReward"),
    paths=("Path",),
    plant=("ContouringParams", "ContouringPlant"),
    scenarios=("CONTOURING_SCENARIOS", "ContouringScenario"),
)
__all__ = [*_EXPORTS, "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

#: The env ids of this process and their entry points, single and native vector env
#: (registered by ``machining_envs``).
ENTRY_POINTS, VECTOR_ENTRY_POINTS = env_entry_points(
    __name__,
    {
        "Contouring-v0": ("env", "ContouringEnv", "ContouringVectorEnv"),
        "ContouringFeed-v0": ("feed_env", "ContouringFeedEnv", "ContouringFeedVectorEnv"),
    },
)
