"""Contouring: two feed axes following corners, circles and involutes (Choi et al.).

``plant`` (the two axis drives), ``paths`` (toolpaths: lines, arcs, involutes), ``servo``
(the CNC's position loops, PI and H-infinity 2-DOF, designed once), ``scenarios``,
``metrics`` (contour error, cycle time; the two tasks), ``env`` (``Contouring-v0``: the
axis commands) and ``feed_env`` (``ContouringFeed-v0``: the feed override over a servo).
"""

from machining_envs.contouring.env import ContouringEnv, ContouringReward, ContouringVectorEnv
from machining_envs.contouring.feed_env import (
    ContouringFeedEnv,
    ContouringFeedVectorEnv,
    FeedReward,
)
from machining_envs.contouring.paths import Path
from machining_envs.contouring.plant import ContouringParams, ContouringPlant
from machining_envs.contouring.scenarios import CONTOURING_SCENARIOS, ContouringScenario

__all__ = ["ContouringEnv", "ContouringReward", "ContouringFeedEnv", "FeedReward", "Path"]
__all__ += ["ContouringVectorEnv", "ContouringFeedVectorEnv"]
__all__ += ["ContouringParams", "ContouringPlant", "ContouringScenario"]
__all__ += ["CONTOURING_SCENARIOS", "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"]

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
