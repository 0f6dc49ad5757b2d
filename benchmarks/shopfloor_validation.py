"""Shop-floor check on ``validation``: classical agents tuned for the shop-floor machine.

Tunes each agent by the protocol of ``agents.bench.tune`` (Optuna, ``train`` episodes) on
the machine of the ``shopfloor`` split (``SHOPFLOOR_ACTUATION``; on the lathe a 2.2 kW
spindle) given as env options, then runs 100 ``validation`` episodes with the same machine
and compares each feedback agent with the tuned constant feed, episode by episode (paired
bootstrap interval of the machining-time difference, positive: faster than the constant
feed). The held-out ``shopfloor`` split itself is not touched.

    python benchmarks/shopfloor_validation.py --env machining_envs/Turning-v0 --out x.json
    python benchmarks/shopfloor_validation.py --env machining_envs/EndMilling-v0 --only afc
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import time

import gymnasium as gym

from agents import AdaptiveFeedControl, ConstantFeed, MillingConstantFeed
from agents.bench.tune import TuningBudget, tune_agent
from agents.eval import evaluate, task_of
from agents.eval.stats import paired_difference
from agents.turning import DelayAwarePI
from machining_envs.core.actuation import SHOPFLOOR_ACTUATION
from machining_envs.core.splits import split_seeds
from machining_envs.turning.scenarios import SHOPFLOOR_SPINDLE_POWER_W

MACHINES = {
    "machining_envs/Turning-v0": {
        "actuation": dataclasses.asdict(SHOPFLOOR_ACTUATION),
        "spindle_power_W": SHOPFLOOR_SPINDLE_POWER_W,
    },
    "machining_envs/EndMilling-v0": {"actuation": dataclasses.asdict(SHOPFLOOR_ACTUATION)},
}


#: --only's names of the runs.
KEYS = {
    "afc": "AFC (force/torque channel)",
    "afc-power": "AFC (spindle power)",
    "delay-aware": "delay-aware PI",
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--env", default="machining_envs/Turning-v0", choices=sorted(MACHINES))
    ap.add_argument("--trials", type=int, default=30)
    ap.add_argument("--episodes", type=int, default=16)
    ap.add_argument("--validation", type=int, default=100)
    ap.add_argument("--out", default=None)
    ap.add_argument("--only", nargs="*", default=None, choices=sorted(KEYS),
                    help="the runs to make besides the constant feed")  # fmt: skip
    args = ap.parse_args()
    machine = MACHINES[args.env]
    constant = ConstantFeed if "Turning" in args.env else MillingConstantFeed
    runs = {
        "constant feed": (constant, machine),
        "AFC (force/torque channel)": (AdaptiveFeedControl, machine),
        "AFC (spindle power)": (AdaptiveFeedControl, {**machine, "power_sensor": True}),
    }
    if "Turning" in args.env:
        runs["delay-aware PI"] = (DelayAwarePI, machine)
    if args.only:
        keep = {KEYS[k] for k in args.only} | {"constant feed"}
        runs = {k: v for k, v in runs.items() if k in keep}
    budget = TuningBudget(args.trials, args.episodes)
    env = gym.make(args.env)
    score, failed = task_of(env).score, task_of(env).score.failed_value(env)
    env.close()
    seed = split_seeds("validation", args.validation)[0]
    out, rows = {}, {}
    for label, (cls, kwargs) in runs.items():
        t0 = time.perf_counter()
        entry = tune_agent(cls, args.env, budget, kwargs, verbose=True)
        factory = functools.partial(cls.from_env, **entry["params"])
        ev = evaluate(factory, args.env, ["validation"], args.validation, seed, env_kwargs=kwargs)
        rows[label] = ev.rows
        s = score(ev.rows, failed)
        out[label] = {"tuned": entry, "validation": s, "wall_s": time.perf_counter() - t0}
        extra = {k: sum(r[k] for r in ev.rows) / len(ev.rows) for k in ev.rows[0]
                 if k.startswith("afc_")}  # fmt: skip
        out[label]["afc_log_means"] = extra
        print(f"{label}: kept {s['valid']:.0%}, score {s['score']:.2f} s {extra}", flush=True)
    ref = rows["constant feed"]
    for label in list(runs)[1:]:
        d = paired_difference(ref, rows[label], score, failed)
        out[label]["vs_constant_feed"] = d
        print(f"{label} vs constant feed: {d}", flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(out, f, indent=1, default=float)


if __name__ == "__main__":
    main()
