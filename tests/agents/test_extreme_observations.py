"""Every classical agent's law on extreme but finite observations: -1e30, 1e30, 0, the
denormals and float32's largest, in every entry alone and in all at once, from a fresh start
and from a running state. No action and no state entry may be NaN or infinite, and the
agent acts finitely on valid observations afterwards."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import agents as a
from tests.agents.test_robustness import CLASSICAL, IDS

AGENTS = [
    *CLASSICAL,
    ("machining_envs/ContouringFeed-v0", {}, a.LookAheadFeed.from_env),
    ("machining_envs/ContouringFeed-v0", {}, a.ContourAFC.from_env),
]
AGENT_IDS = [*IDS, "LookAheadFeed-ContouringFeed-v0", "ContourAFC-ContouringFeed-v0"]
#: Finite values a broken sensor, a unit mistake or a fuzzer may put in an observation.
EXTREMES = (-1e30, 1e30, 0.0, 5e-324, -5e-324, 1e-30, 3.4e38, -3.4e38)


def _patterns(obs: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """One row per extreme value in all entries, and per value in each entry alone (the
    others as in ``obs``)."""
    rows, labels = [], []
    for v in EXTREMES:
        rows.append(np.full(obs.size, v))
        labels.append(f"every entry {v!r}")
        for i in range(obs.size):
            r = obs.astype(np.float64)
            r[i] = v
            rows.append(r)
            labels.append(f"observation[{i}] = {v!r}")
    return np.array(rows), labels


@pytest.mark.parametrize("env_id,kwargs,factory", AGENTS, ids=AGENT_IDS)
def test_extreme_finite_observations_give_finite_actions_and_states(env_id, kwargs, factory):
    env = gym.make(env_id, **kwargs)
    agent = factory(env)
    obs, _ = env.reset(seed=0)
    state, start = None, np.ones(1, dtype=bool)
    for _ in range(5):
        action, state = agent.predict(obs, state, start)
        start[:] = False
        obs, *_ = env.step(action)
    env.close()
    extreme, labels = _patterns(obs)
    n = len(extreme)
    valid = np.repeat(obs[None, :].astype(np.float64), n, axis=0)
    bad = set()
    for fresh in (True, False):
        st = None if fresh else np.repeat(np.asarray(state).reshape(1, -1), n, axis=0)
        starts = np.full(n, fresh)
        for t in range(25):  # 20 extreme steps, then 5 valid ones
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # an overflow to a clipped inf
                try:
                    act, st = agent.predict(extreme if t < 20 else valid, st, starts)
                except ValueError as err:  # a non-finite state handed back, say
                    pytest.fail(f"{agent.name}, {'fresh' if fresh else 'running'}, step {t}: {err}")
            starts[:] = False
            act = np.asarray(act).reshape(n, -1)
            sta = np.asarray(st, dtype=np.float64).reshape(n, -1)
            for k in np.flatnonzero(~(np.isfinite(act).all(1) & np.isfinite(sta).all(1))):
                bad.add(f"{labels[k]} ({'fresh' if fresh else 'running'}, step {t})")
    assert not bad, f"{agent.name}: non-finite action or state for {sorted(bad)[:8]}"
