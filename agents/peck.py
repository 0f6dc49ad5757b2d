"""Peck drilling: the industrial way to drill deep micro holes, as a baseline.

The drill feeds at the nominal feed velocity for ``q`` mm, retracts at rapid speed until its
point is out of the hole (the chips leave with it), rapids back to just above the bottom and
feeds on; the spindle runs at the nominal voltage throughout. Safe, because the chips never
pack deeper than ``q``; slow, because every peck costs the trip out and back.
"""

from __future__ import annotations

import numpy as np

from agents.base import Agent
from agents.drilling import _OBS_DIM, DrillingIO, _in_range, _positive

__all__ = ["PeckDrilling"]

_FEED, _OUT, _BACK = 0.0, 1.0, 2.0


class PeckDrilling(Agent):
    """Peck drilling on ``control="feed"``: feed ``q`` mm, retract out of the hole, return.

    Parameters
    ----------
    io : DrillingIO
    peck_diameters : float
        Peck depth ``q`` in drill diameters (default 1: chips pack at most one diameter deep,
        a usual choice for micro drills in steel).
    clearance_mm : float
        How far above the surface the point retracts, mm (default 0.1).
    approach_gap_mm : float
        Where the rapid return stops above the hole's bottom, mm; the rest is fed at the
        nominal feed (default 0.05).
    rapid_mm_s : float or None
        Retract and return speed, mm/s (default the stage's ``feed_speed_max_mm_s``).
    """

    # [phase (0 feed, 1 out, 2 back), depth at which to retract next (mm), started]
    state_size = 3
    obs_dim = _OBS_DIM

    def __init__(
        self,
        io: DrillingIO,
        peck_diameters: float = 1.0,
        clearance_mm: float = 0.1,
        approach_gap_mm: float = 0.05,
        rapid_mm_s: float | None = None,
    ):
        io.require("feed", "PeckDrilling")
        self.io = io
        p = io.params
        self.peck_diameters = _positive("peck_diameters", peck_diameters, 100.0)
        self.clearance_mm = _in_range("clearance_mm", clearance_mm, 0.0, p.retract_limit_mm)
        self.approach_gap_mm = _in_range("approach_gap_mm", approach_gap_mm, 0.0, 5.0)
        rapid = p.feed_speed_max_mm_s if rapid_mm_s is None else rapid_mm_s
        self.rapid_mm_s = _in_range("rapid_mm_s", rapid, 1e-3, p.feed_speed_max_mm_s)
        self.feed_mm_s = p.feed_velocity_mm_s
        self.name = f"peck q={peck_diameters:g}D"

    @classmethod
    def from_env(cls, env, **kwargs) -> PeckDrilling:
        return cls(DrillingIO.from_env(env), **kwargs)

    def _act(self, obs, state):
        io = self.io
        ts = io.sample_time_s
        pos, depth, _ = io.lengths_mm(obs)
        q = self.peck_diameters * io.diameter_mm(obs)
        first = state[:, 2] == 0.0
        state[:, 1] = np.where(first, depth + q, state[:, 1])
        phase = np.where(first, _FEED, state[:, 0])
        # Transitions, then the command of the phase.
        to_out = (phase == _FEED) & (depth >= state[:, 1] - 1e-9)
        phase = np.where(to_out, _OUT, phase)
        to_back = (phase == _OUT) & (pos <= -self.clearance_mm + 1e-9)
        phase = np.where(to_back, _BACK, phase)
        state[:, 1] = np.where(to_back, depth + q, state[:, 1])
        stop = depth - self.approach_gap_mm
        to_feed = (phase == _BACK) & (pos >= stop - 1e-9)
        phase = np.where(to_feed, _FEED, phase)
        back = np.minimum(self.rapid_mm_s, np.maximum((stop - pos) / ts, self.feed_mm_s))
        v = np.where(
            phase == _FEED,
            self.feed_mm_s,
            np.where(
                phase == _OUT,
                -np.minimum(self.rapid_mm_s, (pos + self.clearance_mm) / ts + 1e-3),
                back,
            ),
        )
        state[:, 0] = phase
        state[:, 2] = 1.0
        return io.action(v)
