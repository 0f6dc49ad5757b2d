"""``machining-bench``: the command line of the library.

machining-bench benchmark [--quick] [--out results] [--seed 1000]
machining-bench reproduce turning [--out results] [--sensor-gain 17]
"""

from __future__ import annotations

import argparse
import sys

from agents.bench.declarations import PROCESSES, benchmark_spec, process

__all__ = ["main", "build_parser"]


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return v


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="machining-bench", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)

    b = sub.add_parser("benchmark", help="every agent on every env; table, CSV, report, plots")
    b.add_argument(
        "--quick", action="store_true", help="fewer episodes (a couple of minutes on 2 cores)"
    )
    b.add_argument("--out", default="results", help="output folder (default: results)")
    b.add_argument("--seed", type=int, default=1000, help="first episode seed (default: 1000)")

    r = sub.add_parser("reproduce", help="run a paper's experiments; paper vs ours")
    r.add_argument("process", choices=[p.name for p in PROCESSES], help="which paper")
    r.add_argument("--out", default="results", help="folder for the figure (default: results)")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument(
        "--sensor-gain",
        type=_positive_float,
        default=None,
        help="turning: override Ke (counts/N) to explore the calibration",
    )
    t = sub.add_parser("train", help="train an SB3 policy (PPO, SAC, TD3) on an env")
    t.add_argument("--env", required=True, help="env id, e.g. machining_envs/Turning-v0")
    t.add_argument("--algo", default="ppo", choices=["ppo", "sac", "td3"])
    t.add_argument("--out", required=True, help="run folder (must be new unless --resume)")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--timesteps", type=int, default=None, help="override n_timesteps of the config")
    t.add_argument(
        "--config", default=None, help="YAML file (default agents/rl/configs/<algo>.yml)"
    )
    t.add_argument("--resume", action="store_true", help="continue from the run's last checkpoint")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.add_argument(
        "--vec",
        choices=["native", "subproc", "dummy"],
        default=None,
        help="how the envs run: the native batched vector env (default where the id has one), "
        "SB3's SubprocVecEnv or DummyVecEnv (default otherwise)",
    )

    e = sub.add_parser("evaluate", help="the harness on a saved policy")
    e.add_argument(
        "--model", required=True, help="a saved model .zip (VecNormalize stats beside it)"
    )
    e.add_argument("--env", required=True)
    e.add_argument("--scenarios", nargs="+", default=["test"])
    e.add_argument("--episodes", type=int, default=20)
    e.add_argument("--seed", type=int, default=1000)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "benchmark":
        from agents.bench.benchmark import run_benchmark

        run_benchmark(args.out, quick=args.quick, seed=args.seed)
        return 0
    if args.command == "reproduce":
        kwargs = {"seed": args.seed}
        if args.sensor_gain is not None:
            if args.process != "turning":
                raise SystemExit("--sensor-gain applies to 'reproduce turning' only")
            kwargs["sensor_gain"] = args.sensor_gain
        results = process(args.process).reproduce(args.out, **kwargs)
        return 0 if all(r["match"] for r in results) else 1
    if args.command == "train":
        from agents.rl import ConfigError, train

        try:
            train(
                args.env,
                args.algo,
                args.out,
                seed=args.seed,
                config_path=args.config,
                n_timesteps=args.timesteps,
                resume=args.resume,
                progress_bar=not args.no_progress,
                vec=args.vec,
            )
        except (ConfigError, FileExistsError, FileNotFoundError) as exc:
            print(f"machining-bench train: {exc}", file=sys.stderr)
            return 2
        return 0
    if args.command == "evaluate":
        from agents.rl import evaluate_policy_file

        ev, s, score = evaluate_policy_file(
            args.model, args.env, args.scenarios, args.episodes, args.seed
        )
        spec = benchmark_spec(args.env)
        print(ev.to_markdown(spec.table_metrics if spec else ev.metric_names()))
        print(
            f"\nprimary score ({score.label}): {s['score'] * score.scale:.4g} (episodes that "
            f"count: {s['valid']:.0%}); {score.secondary_label} {s['secondary']:.4g}"
        )
        return 0
    return 2  # pragma: no cover - argparse rejects other commands


if __name__ == "__main__":
    sys.exit(main())
