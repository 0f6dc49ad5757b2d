"""Statistics of a benchmark: per-agent score summaries with intervals, paired comparisons.

The inputs are the harness's episode rows; every agent met the same episodes (the same
seeds), so comparisons are paired. An agent may be several policies (a learned agent's
training seeds, the ``policy_seed`` of its rows): each contributes its own column.

- ``iqm`` and its 95 % interval: the interquartile mean of the charged values (the score's
  per-episode values, :meth:`PrimaryScore.charged`) with rliable's stratified bootstrap
  (episodes resampled within each training seed; a classical agent is one stratum);
- ``paired_difference``: the mean over episodes of (reference - agent), the agent's value
  averaged over its seeds, with a 95 % bootstrap interval over episodes (scipy), positive
  when the agent is better (lower values are better);
- ``probability_of_improvement``: rliable's P(agent better than reference) on an episode,
  ties counting one half;
- ``verdict``: the agent against the reference at every allowance of steps over the limit
  (``machining_envs.core.score.ALLOWANCES``): *better* only where the paired interval is
  above zero at each, *worse* only where below at each (:func:`verdict`);
- ``seed_count_shares``: each training seed's share of episodes that count.

rliable needs the ``bench`` extra (``pip install 'machining-envs[bench]'``).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from machining_envs.core.score import ALLOWANCES, OVER_LIMIT_SHARE, PrimaryScore

__all__ = [
    "AgentStats",
    "score_matrix",
    "iqm_interval",
    "agent_stats",
    "paired_difference",
    "verdict",
    "allowance_sweep",
    "seed_count_shares",
    "VERDICTS",
    "BOOTSTRAP_REPS",
]

#: The verdicts :func:`verdict` gives.
VERDICTS = ("better", "worse", "depends on the allowance", "unresolved")

#: Bootstrap resamples for every interval (rliable's default is 50 000; 2 000 keeps the
#: interval's end points within about 1 % of it at 100 episodes and the table fast).
BOOTSTRAP_REPS = 2000


def _rliable():
    try:
        from rliable import library, metrics
    except ImportError as e:  # pragma: no cover - exercised without the extra
        raise ImportError(
            "the benchmark's statistics need rliable: pip install 'machining-envs[bench]'"
        ) from e
    return library, metrics


@dataclass(frozen=True)
class AgentStats:
    """One agent's summary over its episodes (values in the score's units)."""

    mean: float
    iqm: float
    iqm_low: float
    iqm_high: float
    count_rate: float
    efficiency: float
    n_episodes: int
    n_seeds: int


def score_matrix(
    rows: Sequence[dict],
    score: PrimaryScore,
    failed_value: float,
    allowance: float = OVER_LIMIT_SHARE,
):
    """``(seeds, matrix)``: the episode seeds in order and the charged values as an array
    ``(n_episodes, n_policy_seeds)`` (one column per ``policy_seed``; one column for rows
    without it), an episode counting at ``allowance``. Every policy must have run the same
    episodes."""
    by_policy: dict = {}
    for r in rows:
        by_policy.setdefault(r.get("policy_seed", 0), {})[r["seed"]] = score.charged(
            r, failed_value, allowance
        )
    seeds = sorted(next(iter(by_policy.values())))
    for p, vals in by_policy.items():
        if sorted(vals) != seeds:
            raise ValueError(f"policy seed {p} ran other episodes than the rest")
    m = np.array([[by_policy[p][s] for p in sorted(by_policy)] for s in seeds], dtype=float)
    return seeds, m


@contextlib.contextmanager
def rliable_seed(seed: int) -> Iterator[None]:
    """Make rliable's bootstrap draws depend on ``seed`` alone. Its stratified bootstrap
    (rliable 1.2, ``StratifiedBootstrap.update_indices``) draws the resamples from numpy's
    global generator (``np.random.choice``), not from the ``random_state`` it is given, so
    its intervals moved from run to run; this seeds the global generator for the call and
    puts the caller's state back afterwards."""
    # The legacy global generator is what rliable draws from.
    state = np.random.get_state()  # noqa: NPY002
    np.random.seed(seed)  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(state)  # noqa: NPY002


def iqm(scores) -> np.float64:
    """The interquartile mean of all of ``scores``: rliable's ``aggregate_iqm``, which is
    scipy's ``trim_mean(scores, 0.25, axis=None)``, by the same arithmetic (numpy's
    partition at the quartile cuts, then the mean of the middle half; NaN where a score is
    NaN or there is none), so the same numbers to the last bit. It skips scipy's
    argument-handling wrapper, which is most of ``trim_mean``'s cost, and the bootstrap
    calls it 2000 times per interval (0.78 -> 0.15 s per interval)."""
    x = np.asarray(scores, dtype=np.float64).ravel()
    if x.size == 0 or np.isnan(x).any():
        return np.float64(np.nan)
    lo = int(0.25 * x.size)
    hi = x.size - lo
    return np.mean(np.partition(x, (lo, hi - 1))[lo:hi])


def iqm_interval(m: np.ndarray, seed: int = 0) -> tuple[float, float, float]:
    """IQM of ``m`` (runs x strata: episodes x policy seeds, or policy seeds x 1) with its
    95 % stratified-bootstrap interval (rliable): ``(iqm, low, high)``."""
    import warnings

    library, _ = _rliable()
    with warnings.catch_warnings(), rliable_seed(seed):
        # rliable passes arch a RandomState, which arch has deprecated (and rliable's
        # resampling does not use: see rliable_seed).
        warnings.simplefilter("ignore", FutureWarning)
        point, ci = library.get_interval_estimates(
            {"a": np.asarray(m, dtype=float)},
            lambda x: np.array([iqm(x)]),
            reps=BOOTSTRAP_REPS,
            random_state=np.random.RandomState(seed),
        )
    return float(point["a"][0]), float(ci["a"][0, 0]), float(ci["a"][1, 0])


def agent_stats(
    rows: Sequence[dict], score: PrimaryScore, failed_value: float, seed: int = 0
) -> AgentStats:
    """Mean, IQM with its 95 % stratified-bootstrap interval, count rate and efficiency."""
    _, m = score_matrix(rows, score, failed_value)
    iqm, low, high = iqm_interval(m, seed)
    eff = [score.efficiency(r, failed_value) for r in rows]
    eff = float(np.mean(eff)) if all(math.isfinite(e) for e in eff) else math.nan
    return AgentStats(
        mean=float(m.mean()),
        iqm=iqm,
        iqm_low=low,
        iqm_high=high,
        count_rate=float(np.mean([score.counts(r) for r in rows])),
        efficiency=eff,
        n_episodes=m.shape[0],
        n_seeds=m.shape[1],
    )


def paired_difference(
    reference: Sequence[dict],
    agent: Sequence[dict],
    score: PrimaryScore,
    failed_value: float,
    seed: int = 0,
    allowance: float = OVER_LIMIT_SHARE,
) -> dict:
    """The agent against a reference agent over the episodes both ran, an episode counting
    at ``allowance`` (share of steps over the limit).

    ``diff`` (mean of reference - agent, positive when the agent is better) with
    ``low``/``high`` (95 % bootstrap interval over episodes, BCa where defined), and
    ``p_improve`` (rliable's probability of improvement: the share of episodes on which the
    agent's value, averaged over its seeds, is lower; ties count one half).
    """
    from scipy.stats import bootstrap

    _, metrics = _rliable()
    s_ref, m_ref = score_matrix(reference, score, failed_value, allowance)
    s_ag, m_ag = score_matrix(agent, score, failed_value, allowance)
    common = sorted(set(s_ref) & set(s_ag))
    if not common:
        raise ValueError("the two agents share no episode")
    ref = np.array([m_ref[s_ref.index(s)].mean() for s in common])
    ag = np.array([m_ag[s_ag.index(s)].mean() for s in common])
    d = ref - ag
    if np.ptp(d) == 0.0:
        low = high = float(d[0])
    else:
        res = bootstrap(
            (d,),
            np.mean,
            n_resamples=BOOTSTRAP_REPS,
            confidence_level=0.95,
            method="percentile",
            random_state=np.random.default_rng(seed),
        )
        low, high = float(res.confidence_interval.low), float(res.confidence_interval.high)
    # rliable's (runs x tasks) layout with each episode a task: P(-agent > -reference).
    p = float(metrics.probability_of_improvement(-ag[None, :], -ref[None, :]))
    return {"diff": float(d.mean()), "low": low, "high": high, "p_improve": p, "n": len(common)}


def verdict(intervals: Sequence[tuple[float, float]]) -> str:
    """The verdict of an agent against the reference from its paired 95 % intervals
    ``(low, high)`` of (reference - agent), one per allowance: ``"better"`` if every
    interval is above zero, ``"worse"`` if every one is below, ``"depends on the
    allowance"`` if some are resolved (above or below zero) and others not, or resolved
    both ways, and ``"unresolved"`` if none is.

    >>> verdict([(0.5, 2.0), (0.1, 1.0), (0.2, 3.0)])
    'better'
    >>> verdict([(-3.0, -1.0), (-1.0, 1.0), (1.0, 2.0)])
    'depends on the allowance'
    """
    if not intervals:
        raise ValueError("intervals must hold one (low, high) per allowance, got none")
    above = [lo > 0.0 for lo, _ in intervals]
    below = [hi < 0.0 for _, hi in intervals]
    if all(above):
        return "better"
    if all(below):
        return "worse"
    if any(above) or any(below):
        return "depends on the allowance"
    return "unresolved"


def allowance_sweep(
    reference: Sequence[dict],
    agent: Sequence[dict],
    score: PrimaryScore,
    failed_value: float,
    seed: int = 0,
    allowances: Sequence[float] = ALLOWANCES,
) -> tuple[list[dict], str]:
    """:func:`paired_difference` at each of ``allowances`` and the :func:`verdict` over
    them. A score without an over-limit share (``over_key`` None) has one comparison,
    whatever the allowance: it is repeated."""
    if score.over_key is None:
        d = paired_difference(reference, agent, score, failed_value, seed)
        diffs = [d] * len(allowances)
    else:
        diffs = [
            paired_difference(reference, agent, score, failed_value, seed, a) for a in allowances
        ]
    return diffs, verdict([(d["low"], d["high"]) for d in diffs])


def allowance_cells(diffs: Sequence[dict], allowances: Sequence[float] = ALLOWANCES) -> str:
    """The paired differences of :func:`allowance_sweep` with their intervals, one line:
    ``"0.5%: +1.20 [+0.10, +2.30], ..."``."""
    return ", ".join(
        f"{al:.1%}: {d['diff']:+.2f} [{d['low']:+.2f}, {d['high']:+.2f}]"
        for al, d in zip(allowances, diffs, strict=True)
    )


def seed_count_shares(
    rows: Sequence[dict], score: PrimaryScore, allowance: float = OVER_LIMIT_SHARE
) -> dict:
    """Each ``policy_seed``'s share of its episodes that count at ``allowance`` (rows
    without a policy seed: one entry, key 0)."""
    by: dict = {}
    for r in rows:
        by.setdefault(r.get("policy_seed", 0), []).append(score.counts(r, allowance))
    return {k: float(np.mean(v)) for k, v in sorted(by.items())}
