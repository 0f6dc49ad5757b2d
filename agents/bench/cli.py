"""machining-bench: benchmark controllers, reproduce the papers, train and evaluate policies.

machining-bench benchmark [--quick] [--out results] [--env ID ...]
machining-bench tune [--env ID] [--trials 30] [--episodes 16]
machining-bench reproduce {turning,milling,drilling,contouring} [--out results]
machining-bench train --env ID --out runs/x [--algo ppo] [--resume]
machining-bench sweep --env ID --out sweeps/x [--search N] [--seeds 0 1 2 3 4]
machining-bench evaluate --model runs/x/best_model.zip --env ID
machining-bench export --onnx --model runs/x/best_model.zip
machining-bench export --zoo --model runs/x/best_model.zip
machining-bench convert-stats FILE_vecnormalize.pkl
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from agents.bench.declarations import PROCESSES, benchmark_spec, process
from machining_envs.core.checks import is_seed

__all__ = ["main", "build_parser"]


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return v


def _seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if not is_seed(v):
        raise argparse.ArgumentTypeError(f"must be in [0, 2**32), got {text}")
    return v


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text}")
    return v


class _Formatter(argparse.HelpFormatter):
    """Shows each option's default where it has one its help does not already state."""

    def _get_help_string(self, action):
        text = action.help or ""
        if action.default not in (None, False, argparse.SUPPRESS) and "default" not in text:
            text += " (default: %(default)s)"
        return text


class _TopFormatter(_Formatter, argparse.RawDescriptionHelpFormatter):
    """The top-level help keeps the usage lines of the description as they are."""


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("machining_envs")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        import machining_envs

        return machining_envs.__version__


def _training_arguments(p: argparse.ArgumentParser, out_help: str) -> None:
    """The arguments ``train`` and ``sweep`` share."""
    p.add_argument("--env", required=True, help="env id, e.g. machining_envs/Turning-v0")
    p.add_argument("--algo", default="ppo", choices=["ppo", "sac", "td3"])
    p.add_argument("--out", required=True, help=out_help)
    p.add_argument("--timesteps", type=int, default=None, help="override n_timesteps of the config")
    p.add_argument(
        "--config", default=None, help="YAML file (default agents/rl/configs/<algo>.yml)"
    )
    p.add_argument(
        "--vec",
        choices=["native", "subproc", "dummy"],
        default=None,
        help="how the envs run: the native batched vector env (default where the id has one), "
        "SB3's SubprocVecEnv or DummyVecEnv (default otherwise)",
    )


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="machining-bench", description=__doc__, formatter_class=_TopFormatter
    )
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, summary: str, description: str):
        return sub.add_parser(
            name, help=summary, description=description, formatter_class=_Formatter
        )

    b = command(
        "benchmark",
        "every agent on every env; table, CSV, report, plots",
        "Run every agent (physical bound, MPC oracle, the papers' classical controllers, the "
        "tuned ones and the shipped policies) on every env's fixed test and ood episodes; "
        "print the score tables and write CSV, report and plots.",
    )
    b.add_argument(
        "--quick", action="store_true",
        help="8 test episodes per agent instead of 100, no ood (25 in the full run), the fast "
        "oracles on one episode, no robustness grid",
    )  # fmt: skip
    b.add_argument("--out", default="results", help="output folder (default: results)")
    b.add_argument("--env", nargs="+", default=None, help="only these env ids (default: all)")
    b.add_argument("--no-reproductions", action="store_true", help="skip the paper reproductions")
    b.add_argument("--seed", type=_seed, default=0, help="seed of the bootstrap intervals")
    b.add_argument("--jobs", type=_positive_int, default=None,
                   help="envs run at once, one process each (default: 1)")  # fmt: skip

    sy = command(
        "synthesize",
        "re-synthesise the stored H-infinity designs; says where it writes",
        "Synthesise the H-infinity 2-DOF designs the benchmark runs (both axes at the paper's "
        "rho, the tuned rho and the residual policies' base rho) on this machine and write "
        "them, matrices and gamma, to the package's agents/hinf_designs.json (or --out). "
        "HInf2DOF loads them from there, so every machine runs the same controller.",
    )
    sy.add_argument("--out", default=None, help="file to write (default: the package's)")

    tu = command(
        "tune",
        "tune the classical agents on the train split (Optuna); writes tuned.json",
        "Tune every classical agent's free parameters (TUNABLE) on fixed train episodes with "
        "Optuna's TPE sampler, check the result on validation episodes, and write "
        "agents/bench/tuned.json (or --out). The same budget for every agent.",
    )
    tu.add_argument("--env", default=None, help="only this env id (default: all)")
    tu.add_argument("--trials", type=int, default=30, help="trials per agent")
    tu.add_argument("--episodes", type=int, default=16, help="train episodes per trial")
    tu.add_argument("--out", default=None, help="file to write (default: agents/bench/tuned.json)")

    r = command(
        "reproduce",
        "run a paper's experiments; paper vs ours",
        "Run the experiments of one source paper on the simulated plant and print the "
        "paper's numbers beside ours, row by row (exit 1 if a row does not match).",
    )
    r.add_argument("process", choices=[p.name for p in PROCESSES], help="which paper")
    r.add_argument("--out", default="results", help="folder for the figure (default: results)")
    r.add_argument("--seed", type=_seed, default=0)
    r.add_argument(
        "--sensor-gain",
        type=_positive_float,
        default=None,
        help="turning: override Ke (counts/N) to explore the calibration",
    )
    t = command(
        "train",
        "train an SB3 policy (PPO, SAC, TD3) on an env",
        "Train a Stable-Baselines3 policy with the hyperparameters of "
        "agents/rl/configs/<algo>.yml (or --config); the run folder keeps the model, its "
        "normalisation statistics, checkpoints and its evaluations on the validation split.",
    )
    _training_arguments(t, "run folder (must be new unless --resume)")
    t.add_argument("--seed", type=_seed, default=0)
    t.add_argument("--resume", action="store_true", help="continue from the run's last checkpoint")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")

    w = command(
        "sweep",
        "hyperparameter search or multi-seed training as Ray Tune trials",
        "Run training trials on Ray Tune: with --search N, N trials whose hyperparameters "
        "Optuna's sampler draws (agents.rl.sweep.SEARCH_SPACES) to minimise the best "
        "validation score; without it, one trial per --seeds value with the config as it "
        "is. Ray starts on this machine unless --address names a cluster. The results "
        "folder keeps every trial's run, results.csv, curves.csv (learning curves) and the "
        "best model in best/. Needs the rl and ray extras.",
    )
    _training_arguments(w, "results folder (must be new unless --resume)")
    w.add_argument("--search", type=int, default=0, metavar="N",
                   help="trials of the hyperparameter search (0: train --seeds as configured)")  # fmt: skip
    w.add_argument("--seeds", type=int, nargs="+", default=[0],
                   help="training seeds, one trial each (a search uses one)")  # fmt: skip
    w.add_argument("--workers", type=int, default=2,
                   help="trials at once (CPUs of the local Ray instance)")  # fmt: skip
    w.add_argument("--address", default=None,
                   help="a running Ray cluster ('auto', 'ray://host:10001'); default: start "
                   "Ray on this machine")  # fmt: skip
    w.add_argument("--resume", action="store_true", help="continue an interrupted sweep")

    e = command(
        "evaluate",
        "the harness on a saved policy",
        "Run a saved SB3 model on an env's episodes and print the env's metrics and primary "
        "score. The model's run folder (config.json beside it) gives its algorithm and the "
        "env it was trained on; for a model trained elsewhere give --algo (and --stats).",
    )
    e.add_argument("--model", required=True, help="a saved model .zip")
    e.add_argument("--env", required=True, help="env id, e.g. machining_envs/Turning-v0")
    e.add_argument("--scenarios", nargs="+", default=["validation"], help="scenario names")
    e.add_argument("--episodes", type=int, default=20, help="episodes per scenario")
    e.add_argument("--seed", type=_seed, default=5000, help="first episode seed (validation's)")
    e.add_argument("--algo", choices=["ppo", "sac", "td3"], default=None,
                   help="the model's algorithm (default: from config.json or the file name)")  # fmt: skip
    e.add_argument("--stats", default=None,
                   help="VecNormalize statistics (.json; default: *_vecnormalize.json beside "
                   "the model)")  # fmt: skip
    e.add_argument("--force", action="store_true",
                   help="evaluate on --env although config.json names another env")  # fmt: skip

    x = command(
        "export",
        "write a learned policy as ONNX (checked against SB3) or as an rl-zoo3 folder",
        "--onnx: write a saved SB3 model with its normalisation (and its action increment) "
        "folded in as one ONNX graph, raw observation -> env action; check that onnxruntime "
        "reproduces SB3's actions to 1e-5 on real episodes and print the per-decision "
        "latency against the env's control period. Needs the onnx extra. --zoo: write the "
        "policy of a run (its config.json beside the model) in rl-zoo3's layout, for "
        "`python -m rl_zoo3.enjoy` (default: <run>/zoo).",
    )
    form = x.add_mutually_exclusive_group(required=True)
    form.add_argument("--onnx", action="store_true", help="write ONNX")
    form.add_argument("--zoo", action="store_true", help="write an rl-zoo3 folder")
    x.add_argument("--model", required=True, help="a saved model .zip")
    x.add_argument("--env", default=None, help="env id (default: from config.json)")
    x.add_argument("--out", default=None,
                   help="the .onnx file or the rl-zoo3 folder (default: beside the model)")  # fmt: skip
    x.add_argument("--algo", choices=["ppo", "sac", "td3"], default=None,
                   help="the model's algorithm (default: from config.json or the file name)")  # fmt: skip
    x.add_argument("--stats", default=None,
                   help="VecNormalize statistics (.json; default: beside the model)")  # fmt: skip

    c = command(
        "convert-stats",
        "turn a pickled VecNormalize into the JSON statistics the library reads",
        "Read FILE_vecnormalize.pkl (written by SB3's VecNormalize.save) and write its "
        "statistics as FILE_vecnormalize.json beside it. Reading a pickle runs any code it "
        "names: convert only files you trust.",
    )
    c.add_argument("files", nargs="+", help="pickled VecNormalize files")
    return p


def _fail(command: str, exc: BaseException) -> int:
    """One line on stderr, exit status 2 (a user error, not a crash)."""
    print(f"machining-bench {command}: {exc}", file=sys.stderr)
    return 2


def _evaluate(args) -> int:
    import json
    from pathlib import Path

    import gymnasium as gym

    from agents.rl import evaluate_policy_file

    model = Path(args.model)
    if not model.is_file():
        raise FileNotFoundError(f"no model at {model}")
    if args.env not in gym.registry:
        raise ValueError(f"unknown env id {args.env!r}")
    meta = model.parent / "config.json"
    trained_on = json.loads(meta.read_text()).get("env_id") if meta.is_file() else None
    if trained_on is not None and trained_on != args.env and not args.force:
        raise ValueError(
            f"{model} was trained on {trained_on}, not {args.env} (--force to evaluate anyway)"
        )
    if args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    ev, s, score = evaluate_policy_file(
        model, args.env, args.scenarios, args.episodes, args.seed, algo=args.algo,
        stats=args.stats, progress=True,
    )  # fmt: skip
    spec = benchmark_spec(args.env)
    print(ev.to_markdown(spec.table_metrics if spec else ev.metric_names()))
    print(
        f"\nprimary score ({score.label}): {s['score'] * score.scale:.4g} (episodes that "
        f"count: {s['valid']:.0%}); {score.secondary_label} {s['secondary']:.4g}"
    )
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # The command line a run records (config.json, sweep.json): this one, however called.
    command = shlex.join(["machining-bench", *(sys.argv[1:] if argv is None else argv)])
    if args.command == "benchmark":
        from agents.bench.benchmark import check_env_ids, run_benchmark

        try:
            check_env_ids(args.env)
        except ValueError as exc:
            return _fail("benchmark", exc)
        try:
            run_benchmark(
                args.out, quick=args.quick, seed=args.seed, envs=args.env,
                reproductions=not args.no_reproductions, jobs=args.jobs,
            )  # fmt: skip
        except (FileExistsError, NotADirectoryError, PermissionError, ImportError) as exc:
            return _fail("benchmark", exc)
        return 0
    if args.command == "tune":
        from agents.bench.declarations import BENCHMARKS
        from agents.bench.tune import TUNED_FILE, TuningBudget, tune_all

        try:
            if args.env is not None and benchmark_spec(args.env) is None:
                raise ValueError(
                    f"--env must be one of {[b.env_id for b in BENCHMARKS]}, got {args.env!r}"
                )
            budget = TuningBudget(args.trials, args.episodes)
            tune_all(BENCHMARKS, budget, args.out or TUNED_FILE, only=args.env)
        except (ValueError, ImportError) as exc:
            return _fail("tune", exc)
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
                command=command,
            )
        except (ConfigError, FileExistsError, FileNotFoundError) as exc:
            return _fail("train", exc)
        return 0
    if args.command == "sweep":
        try:
            import ray.tune  # noqa: F401

            from agents.rl.sweep import SweepSettings, sweep
        except ImportError as exc:
            return _fail("sweep", f"{exc}: pip install 'machining-envs[rl,ray]'")
        from agents.rl import ConfigError

        settings = SweepSettings(
            args.env,
            args.algo,
            n_search=args.search,
            seeds=list(args.seeds),
            n_timesteps=args.timesteps,
            config_path=args.config,
            workers=args.workers,
            address=args.address,
            vec=args.vec,
        )
        try:
            sweep(settings, args.out, resume=args.resume, command=command)
        except (ConfigError, ValueError, FileExistsError, FileNotFoundError, RuntimeError) as exc:
            return _fail("sweep", exc)
        return 0
    if args.command == "evaluate":
        try:
            return _evaluate(args)
        except (FileNotFoundError, ValueError) as exc:
            return _fail("evaluate", exc)
    if args.command == "export" and args.zoo:
        try:
            from agents.rl.zoo import write_zoo_folder
        except ImportError as exc:
            return _fail("export", f"{exc}: pip install 'machining-envs[rl]'")
        try:
            exp = write_zoo_folder(args.model, args.out)
        except (FileNotFoundError, ValueError, KeyError) as exc:
            return _fail("export", exc)
        algo, env_id = (
            exp.parent.name,
            json.loads((Path(args.model).parent / "config.json").read_text())["env_id"],
        )
        print(f"wrote {exp}; run it with:\n  python -m rl_zoo3.enjoy --algo {algo} --env {env_id} "
              f"-f {exp.parent.parent} --gym-packages machining_envs --exp-id 1 --load-best")  # fmt: skip
        return 0
    if args.command == "export":
        try:
            from agents.rl.export import export_onnx
        except ImportError as exc:
            return _fail("export", f"{exc}: pip install 'machining-envs[rl,onnx]'")
        try:
            result = export_onnx(args.model, args.env, args.out, algo=args.algo, stats=args.stats)
        except (FileNotFoundError, ValueError) as exc:
            return _fail("export", exc)
        print(result.summary())
        return 0
    if args.command == "synthesize":
        from agents.bench.tune import stored_design_rhos
        from agents.contouring import hinf_designs_file, synthesize_stored_designs

        rhos = stored_design_rhos()
        target = args.out or hinf_designs_file()
        print(f"synthesising H-infinity designs at rho {rhos}; writing {target}")
        try:
            print(f"wrote {synthesize_stored_designs(rhos, target)}")
        except (OSError, RuntimeError, ImportError) as exc:
            return _fail("synthesize", exc)
        return 0
    if args.command == "convert-stats":
        from agents.rl.stats import convert_pickle

        for name in args.files:
            try:
                print(f"{name} -> {convert_pickle(name)}")
            except Exception as exc:  # noqa: BLE001 - any unreadable file: one line
                return _fail("convert-stats", f"{name}: {exc}")
        return 0
    return 2  # pragma: no cover - argparse rejects other commands


if __name__ == "__main__":
    sys.exit(main())
