"""machining-bench: benchmark controllers, reproduce the papers, train and evaluate policies.

machining-bench benchmark [--quick] [--out results] [--env ID ...]
machining-bench synthesize [--out machining_envs/contouring/hinf_designs.json]
machining-bench tune [--env ID] [--trials 30] [--episodes 16] [--machine my_cnc.yml]
machining-bench reproduce {turning,milling,drilling,contouring} [--out results]
machining-bench train --env ID --out runs/x [--algo ppo] [--resume] [--machine my_cnc.yml]
machining-bench sweep --env ID --out sweeps/x [--search N] [--seeds 0 1 2 3 4]
machining-bench evaluate --model runs/x/best_model.zip --env ID
machining-bench export --onnx --model runs/x/best_model.zip
machining-bench export --zoo --model runs/x/best_model.zip
machining-bench convert-stats FILE_vecnormalize.pkl
machining-bench warmup [--env ID ...]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import shlex
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from machining_envs.core.checks import is_seed

__all__ = ["main", "build_parser", "COMMANDS", "EXTRAS", "missing_extras", "warm_up"]

#: The modules each extra of the package brings that the commands import (the extra is
#: missing where any of them is).
EXTRAS: dict[str, tuple[str, ...]] = {
    "rl": ("torch", "stable_baselines3", "yaml", "tqdm", "rich"),
    "bench": ("rliable", "pandas", "optuna", "casadi", "tqdm"),
    "onnx": ("onnx", "onnxscript", "onnxruntime"),
    "ray": ("ray", "optuna"),
}
ALGO_CHOICES = ["ppo", "sac", "td3"]
#: The processes ``reproduce`` takes: ``agents.bench.declarations.PROCESSES``' names (a
#: test holds them equal). Named here so that ``--help``, ``--version`` and the checks of a
#: command run before the agents and their compiled envs load.
PROCESS_NAMES = ("turning", "milling", "drilling", "contouring")


class UsageError(ValueError):
    """A command line that cannot run: one line on stderr, exit status 2."""


# ---- argument types --------------------------------------------------------------------------
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


def _int_at_least(lo: int):
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if v < lo:
            raise argparse.ArgumentTypeError(f"must be >= {lo}, got {text}")
        return v

    parse.__name__ = f"integer >= {lo}"
    return parse


_positive_int = _int_at_least(1)


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


# ---- checks made before any work ---------------------------------------------------------------
def missing_extras(extras) -> list[tuple[str, str]]:
    """``(extra, module)`` for each extra of ``extras`` one of whose modules cannot be
    imported (found without importing it)."""
    out = []
    for extra in extras:
        missing = next((m for m in EXTRAS[extra] if not _importable(m)), None)
        if missing is not None:
            out.append((extra, missing))
    return out


def _importable(module: str) -> bool:
    """Whether ``module`` can be imported (found, not imported)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def _extras_line(extras, missing: list[tuple[str, str]]) -> str:
    names = ", ".join(f"{m} ({e})" for e, m in missing)
    which = "the " + " and ".join(e for e, _ in missing) + " extra" + ("s" * (len(missing) > 1))
    return (
        f"needs {which}, not installed: {names}; pip install 'machining-envs[{','.join(extras)}]'"
    )


def _writable_folder(path: Path, flag: str) -> None:
    """Refuse ``path`` as a folder to write in: a file, a path under a file, or one whose
    first existing folder refuses a file (a probe made and removed there); nothing is
    created."""
    if path.exists() and not path.is_dir():
        raise UsageError(f"{flag} {path} is a file, not a folder")
    _writable_above(path, flag)


def _writable_file(path: Path, flag: str) -> None:
    """Refuse ``path`` as a file to write: a folder, or a path nothing can be written at."""
    if path.is_dir():
        raise UsageError(f"{flag} {path} is a folder, not a file")
    _writable_above(path.parent, flag)


def _writable_above(path: Path, flag: str) -> None:
    existing = next(p for p in (path, *path.parents) if p.exists())
    if not existing.is_dir():
        raise UsageError(f"{flag} {path} is under {existing}, a file")
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        raise UsageError(f"{flag} {path}: cannot write in {existing} ({exc.strerror})") from None


def _new_folder(path: Path, flag: str, resume: bool = False) -> None:
    """A folder a run fills: new or empty (unless resumed) and writable."""
    _writable_folder(path, flag)
    if not resume and path.is_dir() and any(path.iterdir()):
        raise UsageError(f"{flag} {path} is not empty: choose another --out or pass --resume")


def _env_id(env_id: str, flag: str = "--env") -> None:
    import gymnasium as gym

    import machining_envs  # noqa: F401 - registers the ids

    if env_id not in gym.registry:
        ours = [i for i in gym.registry if i.startswith("machining_envs/")]
        raise UsageError(f"{flag}: unknown env id {env_id!r}; this package's: {ours}")


def _model_file(path: str) -> Path:
    model = Path(path)
    if not model.is_file():
        raise UsageError(f"--model: no model at {model}")
    return model


def _run_config(model: Path) -> dict:
    """The run's ``config.json`` beside ``model`` (``{}`` without one)."""
    meta = model.parent / "config.json"
    if not meta.is_file():
        return {}
    try:
        data = json.loads(meta.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UsageError(f"{meta} is not a run's configuration (JSON): {exc}") from None
    if not isinstance(data, dict):
        raise UsageError(f"{meta} is not a run's configuration (a JSON object)")
    return data


def _trained_on(model: Path, env_id: str | None, force: bool) -> str | None:
    """The env to use: ``env_id``, refused where the run's ``config.json`` names another env
    (unless ``force``); the run's env where ``env_id`` is None."""
    trained_on = _run_config(model).get("env_id")
    if env_id is None:
        return trained_on
    _env_id(env_id)
    if trained_on is not None and trained_on != env_id and not force:
        raise UsageError(
            f"{model} was trained on {trained_on}, not {env_id} (--force to use it anyway)"
        )
    return env_id


def _model_algo(model: Path, algo: str | None) -> None:
    """Refuse a model whose algorithm cannot be told (no ``--algo``, no ``config.json``, no
    algorithm in the file name), and an ``--algo`` that is not the model's (its
    ``config.json``'s, else that of the policy class recorded in the zip)."""
    import re

    recorded = _run_config(model).get("algo")
    if algo is None:
        if recorded is None and re.search(r"(ppo|sac|td3)", model.name.lower()) is None:
            raise UsageError(
                f"cannot tell the algorithm of {model} (no config.json beside it): pass "
                f"--algo, one of {ALGO_CHOICES}"
            )
        return
    if recorded is None:
        from agents.rl.export import saved_algorithm

        recorded = saved_algorithm(model)
    if recorded is not None and recorded != algo:
        raise UsageError(f"--algo {algo}: {model} is a {recorded} model")


# ---- the subcommands ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Command:
    """One subcommand: its parser, the extras it needs, the checks of its arguments made
    before any work (``UsageError``), and the work."""

    name: str
    summary: str
    description: str
    arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace, str], int]
    extras: Callable[[argparse.Namespace], tuple[str, ...]] = lambda args: ()
    check: Callable[[argparse.Namespace], None] = lambda args: None


def _benchmark_arguments(b):
    b.add_argument(
        "--quick",
        action="store_true",
        help="8 test episodes per agent instead of 100, no ood (25 in the full run), the fast "
        "oracles on one episode, no robustness grid",
    )
    b.add_argument("--out", default="results", help="output folder (default: results)")
    b.add_argument("--env", nargs="+", default=None, help="only these env ids (default: all)")
    b.add_argument("--no-reproductions", action="store_true", help="skip the paper reproductions")
    b.add_argument("--seed", type=_seed, default=0, help="seed of the bootstrap intervals")
    b.add_argument(
        "--jobs",
        type=_positive_int,
        default=None,
        help="envs run at once, one process each (default: 1)",
    )


def _benchmark_check(args):
    from agents.bench.declarations import BENCHMARKS

    known = [spec.env_id for spec in BENCHMARKS]
    unknown = [e for e in args.env or () if e not in known]
    if unknown:
        raise UsageError(f"envs (--env) must be ids among {known}, got {unknown}")
    _writable_folder(Path(args.out), "--out")


def _benchmark(args, command):
    from agents.bench.benchmark import run_benchmark

    run_benchmark(
        args.out,
        quick=args.quick,
        seed=args.seed,
        envs=args.env,
        reproductions=not args.no_reproductions,
        jobs=args.jobs,
    )
    return 0


def _synthesize_arguments(sy):
    sy.add_argument("--out", default=None, help="file to write (default: the package's)")


def _synthesize_check(args):
    if args.out is not None:
        _writable_file(Path(args.out), "--out")


def _synthesize(args, command):
    from agents.bench.tune import stored_design_rhos
    from machining_envs.contouring.servo import HINF_DESIGNS_FILE, synthesize_stored_designs

    rhos = stored_design_rhos()
    target = args.out or HINF_DESIGNS_FILE
    print(f"synthesising H-infinity designs at rho {rhos}; writing {target}")
    print(f"wrote {synthesize_stored_designs(rhos, target)}")
    return 0


def _tune_arguments(tu):
    tu.add_argument("--env", default=None, help="only this env id (default: all)")
    tu.add_argument("--trials", type=_positive_int, default=30, help="trials per agent")
    tu.add_argument("--episodes", type=_positive_int, default=16, help="train episodes per trial")
    tu.add_argument(
        "--out",
        default=None,
        help="file to write (default: agents/bench/tuned.json; with --machine, "
        "tuned_<machine name>.json here)",
    )
    tu.add_argument(
        "--allowance",
        type=float,
        default=0.02,
        choices=(0.005, 0.01, 0.02),
        help="share of steps over the limit an episode may have and count, in the "
        "objective (default: the protocol's 0.02; the verdict's strictest: 0.005)",
    )
    tu.add_argument(
        "--machine",
        default=None,
        metavar="YAML",
        help="tune for this machine (docs/shopfloor.md): every env made with its "
        "actuation, spindle power and power sensor",
    )


def _machine(args):
    """The machine ``--machine`` names (None without it); a bad file is a usage error."""
    if getattr(args, "machine", None) is None:
        return None
    from machining_envs.core.machine import load_machine

    try:
        return load_machine(args.machine)
    except (ValueError, FileNotFoundError) as exc:
        raise UsageError(f"--machine: {exc}") from None


def _tune_out(args) -> Path:
    from agents.bench.tune import TUNED_FILE

    if args.out is not None:
        return Path(args.out)
    machine = _machine(args)
    return TUNED_FILE if machine is None else Path(f"tuned_{machine.name}.json")


def _tune_check(args):
    from agents.bench.declarations import BENCHMARKS, benchmark_spec

    if args.env is not None and benchmark_spec(args.env) is None:
        raise UsageError(f"--env must be one of {[b.env_id for b in BENCHMARKS]}, got {args.env!r}")
    out = _tune_out(args)
    _writable_file(out, "--out")
    if out.is_file():  # its other envs' entries are kept: it must be a tuned-settings file
        try:
            data = json.loads(out.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise UsageError(f"--out {out} exists and is not JSON ({exc})") from None
        if not isinstance(data, dict) or not isinstance(data.get("envs", {}), dict):
            raise UsageError(
                f"--out {out} exists and is not a tuned-settings file (a JSON object with "
                "'envs'); choose a new file"
            )


def _tune(args, command):
    from agents.bench.declarations import BENCHMARKS
    from agents.bench.tune import TuningBudget, tune_all

    budget = TuningBudget(args.trials, args.episodes, allowance=args.allowance)
    tune_all(
        BENCHMARKS,
        budget,
        _tune_out(args),
        only=args.env,
        machine=_machine(args),
        machine_file=args.machine,
    )
    return 0


def _reproduce_arguments(r):
    r.add_argument("process", choices=PROCESS_NAMES, help="which paper")
    r.add_argument("--out", default="results", help="folder for the figure (default: results)")
    r.add_argument("--seed", type=_seed, default=0)
    r.add_argument(
        "--sensor-gain",
        type=_positive_float,
        default=None,
        help="turning: override Ke (counts/N) to explore the calibration",
    )


def _reproduce_check(args):
    if args.sensor_gain is not None and args.process != "turning":
        raise UsageError("--sensor-gain applies to 'reproduce turning' only")
    _writable_folder(Path(args.out), "--out")


def _reproduce(args, command):
    kwargs = {"seed": args.seed}
    if args.sensor_gain is not None:
        kwargs["sensor_gain"] = args.sensor_gain
    from agents.bench.declarations import process

    results = process(args.process).reproduce(args.out, **kwargs)
    return 0 if all(r["match"] for r in results) else 1


def _training_arguments(p: argparse.ArgumentParser, out_help: str) -> None:
    """The arguments ``train`` and ``sweep`` share."""
    p.add_argument("--env", required=True, help="env id, e.g. machining_envs/Turning-v0")
    p.add_argument("--algo", default="ppo", choices=ALGO_CHOICES)
    p.add_argument("--out", required=True, help=out_help)
    p.add_argument(
        "--timesteps", type=_positive_int, default=None, help="override n_timesteps of the config"
    )
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


def _training_check(args):
    _env_id(args.env)
    if args.config is not None and not Path(args.config).is_file():
        raise UsageError(f"--config: no file at {args.config}")
    _new_folder(Path(args.out), "--out", args.resume)


def _train_arguments(t):
    _training_arguments(t, "run folder (must be new unless --resume)")
    t.add_argument("--seed", type=_seed, default=0)
    t.add_argument("--resume", action="store_true", help="continue from the run's last checkpoint")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.add_argument(
        "--machine",
        default=None,
        metavar="YAML",
        help="train for this machine (docs/shopfloor.md): its env options join the "
        "config's env_kwargs",
    )


def _train(args, command):
    from agents.rl import train

    overrides, machine = None, _machine(args)
    if machine is not None:  # the machine's env options over the config's
        from agents.rl.config import load_config

        cfg = load_config(args.env, args.algo, args.config)
        overrides = {"env_kwargs": {**cfg.env_kwargs, **machine.env_kwargs(args.env)}}
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
        overrides=overrides,
        command=command,
    )
    return 0


def _sweep_arguments(w):
    _training_arguments(w, "results folder (must be new unless --resume)")
    w.add_argument(
        "--search",
        type=_int_at_least(0),
        default=0,
        metavar="N",
        help="trials of the hyperparameter search (0: train --seeds as configured)",
    )
    w.add_argument(
        "--seeds",
        type=_seed,
        nargs="+",
        default=[0],
        help="training seeds, one trial each (a search uses one)",
    )
    w.add_argument(
        "--workers",
        type=_positive_int,
        default=2,
        help="trials at once (CPUs of the local Ray instance)",
    )
    w.add_argument(
        "--address",
        default=None,
        help="a running Ray cluster ('auto', 'ray://host:10001'); default: start "
        "Ray on this machine",
    )
    w.add_argument("--resume", action="store_true", help="continue an interrupted sweep")
    w.add_argument("--no-progress", action="store_true", help="no progress bar")
    w.add_argument(
        "--gate",
        action="store_true",
        help="train the --seeds under the seed gate (agents.rl.gate): a seed that fails is "
        "replaced by the next unused one, each round a sweep in --out/round_<k>; "
        "--out/gate.json records the verdicts",
    )


def _sweep_settings(args):
    from agents.rl.sweep import SweepSettings

    return SweepSettings(
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


def _sweep_check(args):
    from agents.rl.sweep import check_address

    if args.gate and (args.search or args.resume):
        raise UsageError("--gate trains --seeds afresh: it takes neither --search nor --resume")
    _training_check(args)
    try:
        _sweep_settings(args).check()
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.address is not None:
        try:
            check_address(args.address)
        except ValueError as exc:
            raise UsageError(str(exc)) from None


def _sweep(args, command):
    from agents.rl.sweep import sweep

    if args.gate:
        from agents.rl.gate import gated_sweep

        result = gated_sweep(
            _sweep_settings(args), args.out, command=command, progress=not args.no_progress
        )
        print(
            f"passed {result['passed']}, failed {result['failed']}, "
            f"replacements {result['replacements']}; {Path(args.out) / 'gate.json'}"
        )
        return 0 if result["complete"] else 1
    sweep(
        _sweep_settings(args),
        args.out,
        resume=args.resume,
        command=command,
        progress=not args.no_progress,
    )
    return 0


def _saved_model_arguments(p, force_help: str):
    """The arguments of a command that loads a saved model (``evaluate``, ``export``): the
    model, its algorithm and VecNormalize statistics where its run folder does not say, and
    ``--force`` (``force_help``) to use it on another env than it was trained on."""
    p.add_argument("--model", required=True, help="a saved model .zip")
    p.add_argument(
        "--algo",
        choices=ALGO_CHOICES,
        default=None,
        help="the model's algorithm (default: from config.json or the file name)",
    )
    p.add_argument(
        "--stats",
        default=None,
        help="VecNormalize statistics (.json; default: *_vecnormalize.json beside the model)",
    )
    p.add_argument("--force", action="store_true", help=force_help)


def _evaluate_arguments(e):
    _saved_model_arguments(e, "evaluate on --env although config.json names another env")
    e.add_argument("--env", required=True, help="env id, e.g. machining_envs/Turning-v0")
    e.add_argument("--scenarios", nargs="+", default=["validation"], help="scenario names")
    e.add_argument("--episodes", type=_positive_int, default=20, help="episodes per scenario")
    e.add_argument("--seed", type=_seed, default=5000, help="first episode seed (validation's)")


def _evaluate_check(args):
    model = _model_file(args.model)
    _trained_on(model, args.env, args.force)
    _model_algo(model, args.algo)
    if args.stats is not None and not Path(args.stats).is_file():
        raise UsageError(f"--stats: no statistics file at {args.stats}")


def _evaluate(args, command):
    from agents.rl import evaluate_policy_file

    ev, s, score = evaluate_policy_file(
        Path(args.model),
        args.env,
        args.scenarios,
        args.episodes,
        args.seed,
        algo=args.algo,
        stats=args.stats,
        progress=True,
        force=args.force,
    )
    from agents.bench.declarations import benchmark_spec

    spec = benchmark_spec(args.env)
    print(ev.to_markdown(spec.table_metrics if spec else ev.metric_names()))
    print(
        f"\nprimary score ({score.label}): {s['score'] * score.scale:.4g} (episodes that "
        f"count: {s['valid']:.0%}); {score.secondary_label} {s['secondary']:.4g}"
    )
    return 0


def _export_arguments(x):
    form = x.add_mutually_exclusive_group(required=True)
    form.add_argument("--onnx", action="store_true", help="write ONNX")
    form.add_argument("--zoo", action="store_true", help="write an rl-zoo3 folder")
    _saved_model_arguments(x, "--onnx: check on --env although config.json names another env")
    x.add_argument("--env", default=None, help="env id (default: from config.json)")
    x.add_argument(
        "--out",
        default=None,
        help="the .onnx file or the rl-zoo3 folder (default: beside the model)",
    )


def _export_check(args):
    model = _model_file(args.model)
    if args.zoo:
        from agents.rl.zoo import check_zoo_export

        if args.env is not None or args.algo is not None or args.stats is not None:
            raise UsageError(
                "--zoo takes the env, algorithm and statistics of the run's "
                "config.json: drop --env, --algo and --stats"
            )
        try:
            check_zoo_export(model, args.out)
        except (FileNotFoundError, FileExistsError, ValueError) as exc:
            raise UsageError(str(exc)) from None
        out = Path(args.out) if args.out is not None else model.parent / "zoo"
        _writable_folder(out, "--out")
        return
    _model_algo(model, args.algo)
    env_id = _trained_on(model, args.env, args.force)
    if env_id is None:
        raise UsageError(f"no config.json beside {model}: give the env id (--env)")
    if args.stats is not None and not Path(args.stats).is_file():
        raise UsageError(f"--stats: no statistics file at {args.stats}")
    out = Path(args.out) if args.out is not None else model.with_suffix(".onnx")
    _writable_file(out, "--out")


def _export(args, command):
    if args.zoo:
        from agents.rl.zoo import write_zoo_folder

        exp = write_zoo_folder(args.model, args.out)
        algo, env_id = exp.parent.name, _run_config(Path(args.model))["env_id"]
        print(
            f"wrote {exp}; run it with:\n  python -m rl_zoo3.enjoy --algo {algo} --env {env_id} "
            f"-f {exp.parent.parent} --gym-packages machining_envs --exp-id 1 --load-best "
            "--no-render"
        )
        return 0
    from agents.rl.export import export_onnx

    env_id = _trained_on(Path(args.model), args.env, args.force)
    result = export_onnx(args.model, env_id, args.out, algo=args.algo, stats=args.stats)
    print(result.summary())
    return 0


def _convert_arguments(c):
    c.add_argument("files", nargs="+", help="pickled VecNormalize files")


def _convert_check(args):
    for name in args.files:
        if not Path(name).is_file():
            raise UsageError(f"no file at {name}")
        _writable_file(Path(name).with_suffix(".json"), "the statistics file")


def _convert(args, command):
    from agents.rl.stats import convert_pickle

    for name in args.files:
        try:
            print(f"{name} -> {convert_pickle(name)}")
        except Exception as exc:  # noqa: BLE001 - any unreadable file: one line
            raise UsageError(f"{name}: {exc}") from None
    return 0


def _warmup_arguments(w):
    w.add_argument("--env", nargs="+", default=None, help="only these env ids (default: all)")


def _warmup_check(args):
    for env_id in args.env or ():
        _env_id(env_id)


def warm_up(env_ids=None, progress: bool = True) -> None:
    """Make each env of ``env_ids`` (default: every id), single and vector (16 lanes on two
    threads), and take a step, so that numba compiles and caches their kernels now."""
    import gymnasium as gym

    import machining_envs

    ids = list(env_ids or machining_envs.ENV_IDS)
    bar = None
    if progress and _importable("tqdm"):
        from tqdm import tqdm

        bar = tqdm(total=len(ids), unit="env", desc="compiling")
    for env_id in ids:
        if bar is not None:
            bar.set_postfix_str(env_id.split("/")[-1])
        env = gym.make(env_id)
        env.reset(seed=0)
        env.step(env.action_space.sample())
        env.close()
        if gym.spec(env_id).vector_entry_point is not None:
            venv = gym.make_vec(env_id, num_envs=16, num_threads=2)
            venv.reset(seed=0)
            venv.step(venv.action_space.sample())
            venv.close()
        if bar is not None:
            bar.update()
        else:
            print(f"compiled {env_id}", file=sys.stderr)
    if bar is not None:
        bar.close()


def _warmup(args, command):
    warm_up(args.env)
    return 0


def _rl(args):
    return ("rl",)


COMMANDS: dict[str, Command] = {
    c.name: c
    for c in (
        Command(
            "benchmark",
            "every agent on every env; table, CSV, report, plots",
            "Run every agent (physical bound, MPC oracle, the papers' classical controllers, "
            "the tuned ones and the shipped policies) on every env's fixed test and ood "
            "episodes; print the score tables and write CSV, report and plots. Needs the "
            "bench extra (and the rl extra for the shipped policies' rows).",
            _benchmark_arguments,
            _benchmark,
            lambda a: ("bench",),
            _benchmark_check,
        ),
        Command(
            "synthesize",
            "re-synthesise the stored H-infinity designs; says where it writes",
            "Synthesise the H-infinity 2-DOF designs the benchmark runs (both axes at the "
            "paper's rho, the tuned rho and the residual policies' base rho) on this machine "
            "and write them, matrices and gamma, to the package's "
            "machining_envs/contouring/hinf_designs.json (or --out). The envs' servo and "
            "HInf2DOF load them from there, so every machine runs the same controllers. "
            "Needs the rl extra (the residual policies' base rho).",
            _synthesize_arguments,
            _synthesize,
            _rl,
            _synthesize_check,
        ),
        Command(
            "tune",
            "tune the classical agents on the train split (Optuna); writes tuned.json",
            "Tune every classical agent's free parameters (TUNABLE) on fixed train episodes "
            "with Optuna's TPE sampler, check the result on validation episodes, and write "
            "agents/bench/tuned.json (or --out). The same budget for every agent. Needs the "
            "bench extra.",
            _tune_arguments,
            _tune,
            lambda a: ("bench",),
            _tune_check,
        ),
        Command(
            "reproduce",
            "run a paper's experiments; paper vs ours",
            "Run the experiments of one source paper on the simulated plant and print the "
            "paper's numbers beside ours, row by row (exit 1 if a row does not match).",
            _reproduce_arguments,
            _reproduce,
            check=_reproduce_check,
        ),
        Command(
            "train",
            "train an SB3 policy (PPO, SAC, TD3) on an env",
            "Train a Stable-Baselines3 policy with the hyperparameters of "
            "agents/rl/configs/<algo>.yml (or --config); the run folder keeps the model, its "
            "normalisation statistics, checkpoints and its evaluations on the validation "
            "split. Needs the rl extra.",
            _train_arguments,
            _train,
            _rl,
            _training_check,
        ),
        Command(
            "sweep",
            "hyperparameter search or multi-seed training as Ray Tune trials",
            "Run training trials on Ray Tune: with --search N, N trials whose hyperparameters "
            "Optuna's sampler draws (agents.rl.sweep.SEARCH_SPACES) to minimise the best "
            "validation score; without it, one trial per --seeds value with the config as it "
            "is (with --gate, under the seed gate: failing seeds replaced by the next ones). "
            "Ray starts on this machine unless --address names a cluster. The results "
            "folder keeps every trial's run, results.csv, curves.csv (learning curves) and "
            "the best model in best/. Needs the rl and ray extras.",
            _sweep_arguments,
            _sweep,
            lambda a: ("rl", "ray"),
            _sweep_check,
        ),
        Command(
            "evaluate",
            "the harness on a saved policy",
            "Run a saved SB3 model on an env's episodes and print the env's metrics and "
            "primary score. The model's run folder (config.json beside it) gives its "
            "algorithm and the env it was trained on; for a model trained elsewhere give "
            "--algo (and --stats). Needs the rl extra.",
            _evaluate_arguments,
            _evaluate,
            _rl,
            _evaluate_check,
        ),
        Command(
            "export",
            "write a learned policy as ONNX (checked against SB3) or as an rl-zoo3 folder",
            "--onnx: write a saved SB3 model with its normalisation (and its action "
            "increment) folded in as one ONNX graph, raw observation -> env action; check "
            "that onnxruntime reproduces SB3's actions to 1e-5 on real episodes of the env "
            "and print the per-decision latency against the env's control period. Needs the "
            "rl and onnx extras. --zoo: write the policy of a run (its config.json beside "
            "the model) in rl-zoo3's layout, for `python -m rl_zoo3.enjoy` (default: "
            "<run>/zoo). Needs the rl extra.",
            _export_arguments,
            _export,
            lambda a: ("rl", "onnx") if a.onnx else ("rl",),
            _export_check,
        ),
        Command(
            "convert-stats",
            "turn a pickled VecNormalize into the JSON statistics the library reads",
            "Read FILE_vecnormalize.pkl (written by SB3's VecNormalize.save) and write its "
            "statistics as FILE_vecnormalize.json beside it. Reading a pickle runs any code "
            "it names: convert only files you trust. Needs the rl extra.",
            _convert_arguments,
            _convert,
            _rl,
            _convert_check,
        ),
        Command(
            "warmup",
            "compile every env's kernels ahead (numba; cached on disk)",
            "Make every env (or --env's), single and vector, and take a step, so that numba "
            "compiles its kernels now, with a progress bar, instead of at the first use "
            "(about 30 s an env; the cache in the package's __pycache__ serves every later "
            "process).",
            _warmup_arguments,
            _warmup,
            check=_warmup_check,
        ),
    )
}

#: What a command may fail with as a user's error (one line, exit 2) once it runs.
USER_ERRORS = (
    ValueError,
    FileExistsError,
    FileNotFoundError,
    NotADirectoryError,
    IsADirectoryError,
    PermissionError,
    ImportError,
    RuntimeError,
)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="machining-bench", description=__doc__, formatter_class=_TopFormatter
    )
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for c in COMMANDS.values():
        c.arguments(
            sub.add_parser(
                c.name, help=c.summary, description=c.description, formatter_class=_Formatter
            )
        )
    return p


def _fail(command: str, exc: BaseException | str) -> int:
    """One line on stderr, exit status 2 (a user error, not a crash)."""
    text = " ".join(str(exc).split())
    print(f"machining-bench {command}: {text}", file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # The command line a run records (config.json, sweep.json): this one, however called.
    line = shlex.join(["machining-bench", *(sys.argv[1:] if argv is None else argv)])
    cmd = COMMANDS[args.command]
    extras = cmd.extras(args)
    missing = missing_extras(extras)
    if missing:
        return _fail(cmd.name, _extras_line(extras, missing))
    try:
        cmd.check(args)
    except UsageError as exc:
        return _fail(cmd.name, exc)
    try:
        return cmd.run(args, line)
    except USER_ERRORS as exc:
        return _fail(cmd.name, exc)


if __name__ == "__main__":
    sys.exit(main())
