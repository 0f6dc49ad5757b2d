"""Shop-floor check on ``validation``: classical agents tuned for the shop-floor machine.

Tunes each agent by the protocol of ``agents.bench.tune`` (Optuna, ``train`` episodes) on
the machine of the ``shopfloor`` split (``SHOPFLOOR_ACTUATION``; on the lathe a 2.2 kW
spindle) given as env options, then runs 100 ``validation`` episodes with the same machine
and compares each feedback agent with the tuned constant feed, episode by episode (paired
bootstrap interval of the machining-time difference, positive: faster than the constant
feed). The held-out ``shopfloor`` split itself is not touched.

    python benchmarks/shopfloor_validation.py --env machining_envs/Turning-v0 --out x.json
    python benchmarks/shopfloor_validation.py --env machining_envs/EndMilling-v0 --only afc

With ``--tuned FILE`` (e.g. ``agents/bench/tuned_shopfloor.json``, written by
``machining-bench tune --machine docs/my_cnc.yml``) nothing is tuned: the benchmark's
shop-floor rows (the spec's ``machine_tuned`` at the file's settings, with the file's env
options) run on ``validation`` and each is compared with the spec's ``machine_reference``
by the benchmark's verdict rule (paired intervals at every allowance, overload ceiling on):

    python benchmarks/shopfloor_validation.py --env machining_envs/EndMilling-v0 \
        --tuned agents/bench/tuned_shopfloor.json
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


def reasons(rows, score) -> dict:
    """How many episodes fail at the 2 % allowance, by first reason."""
    out = {"unfinished": 0, "broken": 0, "overloaded": 0, "over the limit": 0}
    for r in rows:
        if r.get("finished", 0.0) != 1.0:
            out["unfinished"] += 1
        elif r.get("breakage", 0.0) != 0.0 or r.get("diverged", 0.0) != 0.0:
            out["broken"] += 1
        elif r.get("overloaded", 0.0) != 0.0:
            out["overloaded"] += 1
        elif not score.counts(r):
            out["over the limit"] += 1
    return out


def from_file(env_id: str, path: str, n: int, out: str | None) -> None:
    """The ``--tuned`` check (module docstring): one table line per row."""
    from agents.bench.declarations import benchmark_spec
    from agents.bench.tune import load_tuned, machine_tuned_factory
    from agents.eval.stats import allowance_sweep
    from machining_envs.core.score import ALLOWANCES

    spec = benchmark_spec(env_id)
    tuned = load_tuned(path)
    kwargs = {**spec.env_kwargs, **tuned.get("env_kwargs", {}).get(env_id, {})}
    env = gym.make(env_id, **kwargs)
    score, failed = task_of(env).score, task_of(env).score.failed_value(env)
    env.close()
    seed = split_seeds("validation", n)[0]
    rows, out_data = {}, {"env_kwargs": kwargs, "agents": {}}
    for cls in spec.machine_classes:
        f = machine_tuned_factory(cls, env_id, tuned)
        if f is None:
            print(f"{cls.__name__}: no settings in {path}")
            continue
        t0 = time.perf_counter()
        rows[cls] = evaluate(f, env_id, ["validation"], n, seed, env_kwargs=kwargs).rows
        print(f"{cls.__name__}: {time.perf_counter() - t0:.0f} s", flush=True)
    ref = rows[spec.machine_reference]
    k = score.scale
    print(f"\n{env_id}, {n} validation episodes, settings of {path}")
    print(
        f"| agent | kept at {' / '.join(f'{a:.1%}' for a in ALLOWANCES)} | mean "
        f"{score.label} (counting) | score | "
        + " | ".join(f"vs constant feed at {a:.1%}" for a in ALLOWANCES)
        + " | verdict |"
    )
    print("|---" * (5 + len(ALLOWANCES)) + "|")
    for cls, rs in rows.items():
        kept = [sum(score.counts(r, a) for r in rs) / len(rs) for a in ALLOWANCES]
        vals = [r[score.value_key] for r in rs if score.counts(r)]
        mean = sum(vals) / len(vals) if vals else float("nan")
        s = score(rs, failed)
        entry = {
            "kept": kept,
            "mean_counting": mean,
            "score": s,
            "fails": reasons(rs, score),
            "params": tuned["envs"][env_id][cls.__name__]["params"],
        }
        if "afc_stop" in rs[0]:
            entry["afc_stops"] = sum(r["afc_stop"] for r in rs)
        cells, verdict = ["reference"] * len(ALLOWANCES), "reference"
        if cls is not spec.machine_reference:
            diffs, verdict = allowance_sweep(ref, rs, score, failed)
            entry["vs_constant_feed"], entry["verdict"] = diffs, verdict
            cells = [
                f"{d['diff'] * k:+.1f} [{d['low'] * k:+.1f}, {d['high'] * k:+.1f}]" for d in diffs
            ]
        out_data["agents"][cls.__name__] = entry
        print(
            f"| {cls.__name__} | "
            + " / ".join(f"{x:.0%}" for x in kept)
            + f" | {mean * k:.4g} | {s['score'] * k:.4g} | "
            + " | ".join(cells)
            + f" | {verdict} |",
            entry["fails"],
            entry.get("afc_stops", ""),
            flush=True,
        )
    if out:
        with open(out, "w") as fh:
            json.dump(out_data, fh, indent=1, default=float)


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
    ap.add_argument(
        "--env",
        default="machining_envs/Turning-v0",
        choices=sorted({*MACHINES, "machining_envs/ContouringFeed-v0"}),
    )
    ap.add_argument(
        "--tuned",
        default=None,
        metavar="FILE",
        help="run the settings of this tuned file instead of tuning",
    )
    ap.add_argument("--trials", type=int, default=30)
    ap.add_argument("--episodes", type=int, default=16)
    ap.add_argument("--validation", type=int, default=100)
    ap.add_argument("--out", default=None)
    ap.add_argument(
        "--only",
        nargs="*",
        default=None,
        choices=sorted(KEYS),
        help="the runs to make besides the constant feed",
    )
    args = ap.parse_args()
    if args.tuned is not None:
        from_file(args.env, args.tuned, args.validation, args.out)
        return
    if args.env not in MACHINES:
        ap.error(f"--env {args.env} needs --tuned (this script tunes {sorted(MACHINES)})")
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
        extra = {
            k: sum(r[k] for r in ev.rows) / len(ev.rows) for k in ev.rows[0] if k.startswith("afc_")
        }
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
