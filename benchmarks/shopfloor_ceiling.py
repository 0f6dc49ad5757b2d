"""What a constant feed can keep on a machine: the counting share against the feed.

For the constant feed of an env (the spec's ``machine_reference``), designed for
``--depth`` mm at each ``--setpoints`` x the limit, on ``validation`` episodes run on the
ideal actuator and on the shop-floor machine (``docs/my_cnc.yml``'s options): the share of
episodes that count at each allowance, why the others do not (over the limit too long,
past the overload ceiling, broken, unfinished) and the mean machining time of the counting
ones. Where even a constant feed keeps under 90 % at a setpoint the feedback agents beat in
time, the loss is the workpieces' (a deep segment at the limit's edge), not the agents'
tuning. ``test`` and ``shopfloor`` are not touched.

    python benchmarks/shopfloor_ceiling.py --env machining_envs/EndMilling-v0 \\
        --setpoints 0.6 0.7 0.8 0.9 1.0 --episodes 50
"""

from __future__ import annotations

import argparse
import functools
import json

import gymnasium as gym
from shopfloor_validation import reasons

from agents.bench.declarations import benchmark_spec
from agents.eval import evaluate, task_of
from machining_envs.core.machine import SHOPFLOOR_MACHINE
from machining_envs.core.score import ALLOWANCES
from machining_envs.core.splits import split_seeds


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--env", default="machining_envs/EndMilling-v0")
    ap.add_argument("--depth", type=float, default=3.0, help="design depth, mm")
    ap.add_argument("--setpoints", type=float, nargs="+", default=[0.6, 0.7, 0.8, 0.9, 1.0])
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    spec = benchmark_spec(args.env)
    cls = spec.machine_reference
    env = gym.make(args.env)
    score = task_of(env).score
    env.close()
    seed = split_seeds("validation", args.episodes)[0]
    machines = {"ideal": {}, "shop floor": SHOPFLOOR_MACHINE.env_kwargs(args.env)}
    out = []
    print(
        f"| machine | setpoint | kept at {' / '.join(f'{a:.1%}' for a in ALLOWANCES)} "
        "| fails (unfinished, broken, overloaded, over limit) | mean time of counting |"
    )
    print("|---|---|---|---|---|")
    for label, kw in machines.items():
        for sp in args.setpoints:
            f = functools.partial(cls.from_env, design_depth_mm=args.depth, setpoint=sp)
            rows = evaluate(f, args.env, ["validation"], args.episodes, seed, env_kwargs=kw).rows
            kept = [sum(score.counts(r, a) for r in rows) / len(rows) for a in ALLOWANCES]
            ok = [r[score.value_key] for r in rows if score.counts(r)]
            mean = sum(ok) / len(ok) if ok else float("nan")
            why = reasons(rows, score)
            out.append(
                {
                    "machine": label,
                    "setpoint": sp,
                    "kept": kept,
                    "fails": why,
                    "mean_counting": mean,
                }
            )
            print(
                f"| {label} | {sp:g} | "
                + " / ".join(f"{k:.0%}" for k in kept)
                + f" | {', '.join(str(v) for v in why.values())} | {mean:.1f} |",
                flush=True,
            )
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
