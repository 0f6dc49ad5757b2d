"""Contouring: two feed axes following corners, circles and involutes (Choi et al.).

``plant`` (the two axis drives), ``paths`` (toolpaths: lines, arcs, involutes), ``servo``
(the CNC's position loops, PI and H-infinity 2-DOF, designed once), ``scenarios``,
``metrics`` (contour error, cycle time; the two tasks), ``env`` (``Contouring-v0``: the
axis commands) and ``feed_env`` (``ContouringFeed-v0``: the feed override over a servo).
"""

from machining_envs.core.lazy import lazy_exports

#: What this package exports, and the module each comes from (loaded on first use, so
#: that registering the ids imports none of the physics).
_EXPORTS = {
    "ContouringEnv": "machining_envs.contouring.env",
    "ContouringReward": "machining_envs.contouring.env",
    "ContouringVectorEnv": "machining_envs.contouring.env",
    "ContouringFeedEnv": "machining_envs.contouring.feed_env",
    "ContouringFeedVectorEnv": "machining_envs.contouring.feed_env",
    "FeedReward": "machining_envs.contouring.feed_env",
    "Path": "machining_envs.contouring.paths",
    "ContouringParams": "machining_envs.contouring.plant",
    "ContouringPlant": "machining_envs.contouring.plant",
    "CONTOURING_SCENARIOS": "machining_envs.contouring.scenarios",
    "ContouringScenario": "machining_envs.contouring.scenarios",
}
__all__ = [*_EXPORTS, "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

#: The env ids of this process and their entry points (registered by ``machining_envs``).
ENTRY_POINTS = {
    "machining_envs/Contouring-v0": "machining_envs.contouring.env:ContouringEnv",
    "machining_envs/ContouringFeed-v0": "machining_envs.contouring.feed_env:ContouringFeedEnv",
}
#: Their native vector envs (``gym.make_vec(id, num_envs=N)``).
VECTOR_ENTRY_POINTS = {
    "machining_envs/Contouring-v0": "machining_envs.contouring.env:ContouringVectorEnv",
    "machining_envs/ContouringFeed-v0": (
        "machining_envs.contouring.feed_env:ContouringFeedVectorEnv"
    ),
}
