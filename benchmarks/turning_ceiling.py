"""How much a supervisor of Turning-v0's tuned AFC could gain, measured on ``validation``.

Two numbers bound what a policy that moves the AFC's force reference can win:

- **Where the limit is passed.** For every step of the tuned AFC over the limit, whether it
  lies within ``--near`` seconds of a change of workpiece segment (a depth step the
  controller cannot see coming).
- **The reference chosen after the fact.** The tuned AFC runs the same episodes with each
  reference of ``--refs``; for every episode the smallest charged time over them is the
  score of a supervisor that knew the workpiece in advance and held one reference over it.
  Its paired gain over the tuned AFC, at each allowance of the verdict, is an estimate of
  the room a learned reference knob has (a time-varying reference could gain more).
- **A fixed overload brake** (``--brake``). The tuned AFC lowers its override by integral
  action, over several samples; the same AFC with one rule added (on a sample whose load is
  over the limit, the override cut to ``--brake-cut`` x itself and that sample's feed to
  ``--brake-hold`` x the AFC's) runs at each reference of ``--brake-refs``, paired against
  the tuned AFC. It measures what a supervisor that cuts the feed at once on an excursion
  can gain; it is a measurement, not an agent of the library.

``test`` and ``ood`` are never run::

    python benchmarks/turning_ceiling.py                     # 100 episodes
    python benchmarks/turning_ceiling.py --episodes 20 --refs 0.7 0.9
    python benchmarks/turning_ceiling.py --brake --brake-refs 0.8 0.85 0.9
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from agents import AdaptiveFeedControl
from agents.afc import _OVR
from agents.bench.tune import load_tuned
from agents.eval.harness import evaluate_validation
from agents.eval.stats import allowance_cells, allowance_sweep
from agents.rl.callbacks import evaluation_setup
from machining_envs.core.score import ALLOWANCES

ENV = "machining_envs/Turning-v0"
#: References tried for the after-the-fact choice (the tuned one is always added).
REFS = (0.70, 0.75, 0.85, 0.88, 0.91, 0.94, 0.97)


class OverloadBrake(AdaptiveFeedControl):
    """The AFC with a fixed overload brake (the module's ``--brake``): on a sample whose load
    is over the observed limit, the override is cut to ``cut`` x itself (the integral
    restarts there) and the feed of that sample to ``hold`` x the AFC's."""

    def __init__(self, *args, cut: float = 0.7, hold: float = 0.6, **kwargs):
        super().__init__(*args, **kwargs)
        self.cut, self.hold = cut, hold

    def _act(self, obs, state):
        u = super()._act(obs, state)[:, 0]
        load, limit = self.load_units(obs)
        over = load > limit
        state[:, _OVR] = np.where(over, self.cut * state[:, _OVR], state[:, _OVR])
        command = self.command_map.action_to_command(u)
        command = np.where(over, self.hold * command, command)
        return self.command_map.command_to_action(command)[:, None]


def steps_near_segment_change(trajectory: dict, near_steps: int) -> tuple[int, int]:
    """``(steps over the limit within near_steps of a segment change, all such steps)``."""
    cost = np.asarray(trajectory["cost"]) > 0
    changes = np.flatnonzero(np.diff(np.asarray(trajectory["segment"])) != 0) + 1
    over = np.flatnonzero(cost)
    if over.size == 0:
        return 0, 0
    if changes.size == 0:
        return 0, int(over.size)
    gap = np.min(np.abs(over[:, None] - changes[None, :]), axis=1)
    return int(np.sum(gap <= near_steps)), int(over.size)


def hindsight_gain(charged: dict[float, np.ndarray], tuned_ref: float) -> np.ndarray:
    """Per episode and allowance: the tuned reference's charged time minus the smallest
    over all references (``charged[ref]`` is episodes x allowances). Never negative."""
    best = np.min(np.stack(list(charged.values())), axis=0)
    return charged[tuned_ref] - best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--episodes", type=int, default=100, help="validation episodes")
    ap.add_argument("--refs", type=float, nargs="+", default=REFS)
    ap.add_argument("--near", type=float, default=1.5, help="seconds around a segment change")
    ap.add_argument("--brake", action="store_true", help="measure the fixed overload brake")
    ap.add_argument("--brake-refs", type=float, nargs="+", default=(0.85, 0.9))
    ap.add_argument("--brake-cut", type=float, default=0.7, help="override cut, in (0, 1]")
    ap.add_argument("--brake-hold", type=float, default=0.6, help="feed held, in [0, 1]")
    a = ap.parse_args(argv)
    for flag, values in (("--refs", a.refs), ("--brake-refs", a.brake_refs)):
        for r in values:
            if not 0.0 < r <= 1.5:
                raise SystemExit(f"{flag}: each reference must be in (0, 1.5], got {r}")
    if not 0.0 < a.brake_cut <= 1.0:
        raise SystemExit(f"--brake-cut must be in (0, 1], got {a.brake_cut}")
    if not 0.0 <= a.brake_hold <= 1.0:
        raise SystemExit(f"--brake-hold must be in [0, 1], got {a.brake_hold}")
    tuned = load_tuned()["envs"][ENV]["AdaptiveFeedControl"]["params"]
    tuned_ref = float(tuned["reference"])
    refs = sorted({*map(float, a.refs), tuned_ref})
    metrics_fn, score, failed = evaluation_setup(ENV, {})
    charged = {}
    for ref in refs:
        t0 = time.perf_counter()
        params = dict(tuned, reference=ref)
        ev = evaluate_validation(
            lambda env, p=params: AdaptiveFeedControl.from_env(env, **p),
            ENV,
            a.episodes,
            metrics_fn=metrics_fn,
            keep_trajectories=ref == tuned_ref,
        )
        charged[ref] = np.array(
            [[score.charged(r, failed, al) for al in ALLOWANCES] for r in ev.rows]
        )
        counts = [np.mean([score.counts(r, al) for r in ev.rows]) for al in ALLOWANCES]
        tag = " (tuned)" if ref == tuned_ref else ""
        print(
            f"reference {ref:.3f}{tag}: mean charged "
            + " / ".join(f"{c:.2f}" for c in charged[ref].mean(0))
            + " s, counts "
            + " / ".join(f"{c:.0%}" for c in counts)
            + f" ({time.perf_counter() - t0:.1f} s)",
            flush=True,
        )
        if ref == tuned_ref:
            tuned_rows = ev.rows
            dt = ev.trajectories[0]["t_s"][1] - ev.trajectories[0]["t_s"][0]
            near_steps = int(round(a.near / dt))
            pairs = [steps_near_segment_change(t, near_steps) for t in ev.trajectories]
            near, total = (sum(p[i] for p in pairs) for i in (0, 1))
            print(
                f"tuned AFC: {near} of {total} steps over the limit lie within {a.near} s "
                "of a segment change",
                flush=True,
            )
    gain = hindsight_gain(charged, tuned_ref)
    print(
        "reference chosen per episode after the fact, paired gain over the tuned AFC at "
        + " / ".join(f"{al:.1%}" for al in ALLOWANCES)
        + ": "
        + " / ".join(f"{g:+.2f}" for g in gain.mean(0))
        + " s"
    )
    if a.brake:
        for ref in a.brake_refs:
            t0 = time.perf_counter()
            ev = evaluate_validation(
                lambda env, p=dict(tuned, reference=ref): OverloadBrake.from_env(
                    env, cut=a.brake_cut, hold=a.brake_hold, **p
                ),
                ENV,
                a.episodes,
                metrics_fn=metrics_fn,
            )
            diffs, verdict = allowance_sweep(tuned_rows, ev.rows, score, failed)
            counts = [np.mean([score.counts(r, al) for r in ev.rows]) for al in ALLOWANCES]
            print(
                f"overload brake (cut {a.brake_cut:g}, hold {a.brake_hold:g}) at reference "
                f"{ref:.3f}: counts "
                + " / ".join(f"{c:.0%}" for c in counts)
                + f"; against the tuned AFC {allowance_cells(diffs)}; {verdict} "
                f"({time.perf_counter() - t0:.1f} s)",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
