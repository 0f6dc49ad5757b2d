"""Contouring: two feed axes following corners, circles and involutes (Choi et al.).

``plant`` (the two axis drives), ``paths`` (toolpaths: lines, arcs, involutes), ``servo``
(the CNC's position loops, PI and H-infinity 2-DOF, designed once), ``scenarios``,
``metrics`` (contour error, cycle time; the two tasks), ``env`` (``Contouring-v0``: the
axis commands) and ``feed_env`` (``ContouringFeed-v0``: the feed override over a servo).
"""

from machining_envs.core.lazy import process_package

#: What this package exports, by the module each comes from (loaded on first use, so that
#: registering the ids imports none of the physics), and the env ids of this process with
#: their entry points, single and native vector env (registered by ``machining_envs``).
__all__, __getattr__, __dir__, ENTRY_POINTS, VECTOR_ENTRY_POINTS = process_package(
    __name__,
    {
        "Contouring-v0": ("env", "ContouringEnv", "ContouringVectorEnv"),
        "ContouringFeed-v0": ("feed_env", "ContouringFeedEnv", "ContouringFeedVectorEnv"),
    },
    env=("ContouringEnv", "ContouringReward", "ContouringVectorEnv"),
    feed_env=("ContouringFeedEnv", "ContouringFeedVectorEnv", "FeedReward"),
    paths=("Path",),
    plant=("ContouringParams", "ContouringPlant"),
    scenarios=("CONTOURING_SCENARIOS", "ContouringScenario"),
)
