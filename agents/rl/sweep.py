"""Hyperparameter searches and multi-seed training as Ray Tune trials (``machining-bench sweep``).

Every trial is one ``machining-bench train`` run (SB3 on the id's native vector env) with
the shipped config entry, some of its keys replaced, in its own run folder; it reports each
``validation`` evaluation to Ray Tune. Two kinds of sweep:

- **search** (``n_search`` trials): Optuna's TPE sampler, through Ray Tune's ``OptunaSearch``,
  draws the hyperparameters of ``SEARCH_SPACES[algo]`` and minimises the best validation
  score of the run (the env's primary score on ``validation`` episodes; ``test`` is never
  touched). One training seed per trial.
- **seeds** (no search): one trial per seed, the config as it is: multi-seed training.

Ray starts on demand on this machine (``workers`` CPUs, one trial per CPU) unless
``address`` names a running cluster (``"auto"`` or ``"ray://host:10001"``), where every node
needs this package installed. The results folder holds:

``sweep.json``
    The sweep's settings and command line.
``tune/``
    Ray Tune's experiment state: ``resume=True`` continues an interrupted sweep (unfinished
    trials restart from their run's last checkpoint).
``trials/<trial>/``
    Each trial's run folder (``config.json``, ``eval.csv``, ``best_model.zip``, ...).
``results.csv``, ``curves.csv``
    One row per trial (its hyperparameters, best validation score, wall time), and every
    evaluation of every trial (the learning curves).
``best/``
    The best trial's best model, statistics and config: ``machining-bench evaluate`` and
    ``agents.rl.load_policy`` read it like any run folder.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from agents.rl.algos import ALGOS

__all__ = ["SEARCH_SPACES", "SweepSettings", "check_address", "sweep"]

#: The hyperparameters a search draws, per algorithm: key -> ("log", lo, hi) for a
#: log-uniform float, ("uniform", lo, hi), or ("choice", [values]). Ranges around SB3's and
#: rl-zoo3's defaults for continuous control; PPO's batch sizes stay below its smallest
#: rollout (n_steps 256 x 1 env).
SEARCH_SPACES: dict[str, dict[str, tuple]] = {
    "ppo": {
        "learning_rate": ("log", 3e-5, 3e-3),
        "gamma": ("choice", [0.95, 0.98, 0.99, 0.995]),
        "gae_lambda": ("choice", [0.9, 0.95, 0.98]),
        "ent_coef": ("log", 1e-6, 1e-2),
        "clip_range": ("choice", [0.1, 0.2, 0.3]),
        "n_steps": ("choice", [256, 512, 1024, 2048]),
        "batch_size": ("choice", [64, 128, 256]),
    },
    "sac": {
        "learning_rate": ("log", 3e-5, 3e-3),
        "gamma": ("choice", [0.95, 0.98, 0.99, 0.995]),
        "tau": ("choice", [0.005, 0.01, 0.02]),
        "batch_size": ("choice", [64, 128, 256]),
    },
    "td3": {
        "learning_rate": ("log", 3e-5, 3e-3),
        "gamma": ("choice", [0.95, 0.98, 0.99, 0.995]),
        "tau": ("choice", [0.005, 0.01, 0.02]),
        "batch_size": ("choice", [64, 128, 256]),
    },
}


@dataclass
class SweepSettings:
    """What a sweep runs (recorded in ``sweep.json``)."""

    env_id: str
    algo: str = "ppo"
    n_search: int = 0
    seeds: list[int] = field(default_factory=lambda: [0])
    n_timesteps: int | None = None
    config_path: str | None = None
    workers: int = 2
    address: str | None = None
    vec: str | None = None

    def check(self) -> None:
        if self.algo not in ALGOS:
            raise ValueError(f"algo must be one of {list(ALGOS)}, got {self.algo!r}")
        if not isinstance(self.n_search, int) or self.n_search < 0:
            raise ValueError(f"n_search must be an integer >= 0, got {self.n_search!r}")
        if not self.seeds or any(not isinstance(s, int) or s < 0 for s in self.seeds):
            raise ValueError(f"seeds must be integers >= 0, got {self.seeds!r}")
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds must differ, got {self.seeds!r}")
        if self.n_search and len(self.seeds) != 1:
            raise ValueError(
                f"a search trains one seed per trial: give one seed, got {self.seeds!r}"
            )
        if not isinstance(self.workers, int) or self.workers < 1:
            raise ValueError(f"workers must be an integer >= 1, got {self.workers!r}")
        if self.n_timesteps is not None and self.n_timesteps < 1:
            raise ValueError(f"n_timesteps must be >= 1, got {self.n_timesteps!r}")


def check_address(address: str, timeout_s: float = 5.0) -> None:
    """``ValueError`` unless a Ray cluster may be listening at ``address`` (``"auto"``: one
    this machine knows of; ``"[ray://]host:port"``: something accepts a TCP connection
    there within ``timeout_s``), so that a sweep fails at once instead of waiting for Ray's
    own connection timeout."""
    import socket

    if address == "local":
        return
    if address == "auto":
        try:
            from ray._private.services import canonicalize_bootstrap_address
        except ImportError:  # pragma: no cover - a Ray without it: Ray's own check only
            return
        try:
            address = canonicalize_bootstrap_address("auto")
        except (ConnectionError, ValueError) as exc:
            raise ValueError(f"--address auto: no running Ray cluster here ({exc})") from None
        if address is None:
            raise ValueError("--address auto: no running Ray cluster on this machine")
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ValueError(f"--address must be 'auto' or [ray://]host:port, got {address!r}")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise ValueError(f"--address {address}: no Ray cluster answers there ({reason})") from None


def _tune_space(algo: str) -> dict:
    from ray import tune

    make = {
        "log": lambda lo, hi: tune.loguniform(lo, hi),
        "uniform": lambda lo, hi: tune.uniform(lo, hi),
        "choice": lambda values: tune.choice(values),
    }
    return {k: make[kind](*args) for k, (kind, *args) in SEARCH_SPACES[algo].items()}


def _trial(config: dict, settings: dict, root: str, command: str) -> None:
    """One Ray Tune trial: a training run in ``root/trials/<trial id>``, recording the
    sweep's ``command`` (the worker's own command line is Ray's)."""
    from ray import tune

    from agents.rl.train import train

    trial_dir = Path(root) / "trials" / tune.get_context().get_trial_id()
    hyper = {k: v for k, v in config.items() if k != "seed"}
    resume = (trial_dir / "config.json").is_file()  # a restored sweep continues the run
    train(
        settings["env_id"],
        settings["algo"],
        out_dir=trial_dir,
        seed=int(config["seed"]),
        config_path=settings["config_path"],
        n_timesteps=settings["n_timesteps"],
        resume=resume,
        progress_bar=False,
        verbose=False,
        vec=settings["vec"],
        overrides=hyper or None,
        on_evaluation=lambda row: tune.report(dict(row)),
        command=command,
    )


def _init_ray(settings: SweepSettings) -> bool:
    """Connect to Ray (started here unless running already); True if this call started it."""
    import ray

    if ray.is_initialized():
        return False
    if settings.address:
        ray.init(address=settings.address, log_to_driver=False)
        return False
    ray.init(num_cpus=settings.workers, include_dashboard=False, log_to_driver=False)
    return True


def _progress(total: int):
    """A progress bar over the ``total`` trials (tqdm, on stderr) as a Ray Tune callback
    in the driver: a trial counts when it ends; the postfix is the best validation score
    reported so far."""
    from ray import tune
    from tqdm import tqdm

    class Progress(tune.Callback):
        """The bar is made at the first event and never pickled (Ray Tune saves its
        callbacks with the experiment's state)."""

        def __init__(self):
            self._bar = None
            self.best = math.inf

        def __getstate__(self):
            return {**self.__dict__, "_bar": None}

        @property
        def bar(self):
            if self._bar is None:
                self._bar = tqdm(total=total, unit="trial", desc="sweep")
            return self._bar

        def setup(self, **info):
            self.bar.refresh()

        def on_trial_result(self, iteration, trials, trial, result, **info):
            score = result.get("best", result.get("score"))
            if score is not None and score < self.best:
                self.best = float(score)
                self.bar.set_postfix(best=f"{self.best:.4g}")

        def on_trial_complete(self, iteration, trials, trial, **info):
            self.bar.update()

        def on_trial_error(self, iteration, trials, trial, **info):
            self.bar.update()

        def on_experiment_end(self, trials, **info):
            self.bar.close()

    return Progress()


def sweep(
    settings: SweepSettings,
    out,
    resume: bool = False,
    verbose: bool = True,
    command: str | None = None,
    progress: bool = True,
) -> Path:
    """Run the sweep into the results folder ``out``; returns it (see the module doc).
    ``command`` is the command line that ``sweep.json`` and every trial's ``config.json``
    record (default: this process's). ``progress``: a progress bar over the trials (with
    ``verbose``). Ray is connected to (or started) before anything is written."""
    import ray
    from ray import tune

    from agents.rl.config import load_config

    settings.check()
    if settings.config_path is not None:  # trials run in their own working directories
        settings.config_path = str(Path(settings.config_path).resolve())
    load_config(settings.env_id, settings.algo, settings.config_path)  # refuse bad configs now
    out = Path(out).resolve()
    state = out / "tune"
    if resume:
        if not tune.Tuner.can_restore(str(state)):
            raise FileNotFoundError(f"--resume: no sweep to continue in {out}")
        recorded = json.loads((out / "sweep.json").read_text())["settings"]
        if {k: v for k, v in recorded.items() if k not in ("workers", "address")} != {
            k: v for k, v in asdict(settings).items() if k not in ("workers", "address")
        }:
            raise ValueError(
                f"--resume: the settings differ from the sweep in {out} ({out / 'sweep.json'})"
            )
    elif out.exists() and any(out.iterdir()):
        raise FileExistsError(f"{out} is not empty: choose another --out or pass --resume")
    if settings.address is not None:
        check_address(settings.address)
    started = _init_ray(settings)
    out.mkdir(parents=True, exist_ok=True)
    command = " ".join(sys.argv) if command is None else command
    if not resume:  # a resumed sweep keeps the record of the command that started it
        (out / "sweep.json").write_text(
            json.dumps({"settings": asdict(settings), "command": command}, indent=2)
        )
    else:
        command = json.loads((out / "sweep.json").read_text()).get("command", command)
    trainable = tune.with_resources(
        tune.with_parameters(_trial, settings=asdict(settings), root=str(out), command=command),
        {"cpu": 1},
    )
    total = settings.n_search or len(settings.seeds)
    callbacks = [_progress(total)] if verbose and progress else []
    t0 = time.perf_counter()
    if resume:
        tuner = tune.Tuner.restore(
            str(state), trainable, resume_unfinished=True, resume_errored=True
        )
    else:
        if settings.n_search:
            from ray.tune.search.optuna import OptunaSearch

            space = {**_tune_space(settings.algo), "seed": settings.seeds[0]}
            search_alg = OptunaSearch(seed=settings.seeds[0])
            n_samples = settings.n_search
        else:
            space = {"seed": tune.grid_search(list(settings.seeds))}
            search_alg, n_samples = None, 1
        tuner = tune.Tuner(
            trainable,
            param_space=space,
            tune_config=tune.TuneConfig(
                metric="best",
                mode="min",
                search_alg=search_alg,
                num_samples=n_samples,
                max_concurrent_trials=settings.workers,
            ),
            run_config=tune.RunConfig(
                name="tune", storage_path=str(out), verbose=0, callbacks=callbacks
            ),
        )
    grid = tuner.fit()
    wall = time.perf_counter() - t0
    errors = [r.error for r in grid if r.error is not None]
    if errors:
        raise RuntimeError(f"{len(errors)} of {len(grid)} trials failed; the first: {errors[0]}")
    rows = _write_results(out, settings)
    best = _copy_best(out, rows)
    if started:
        ray.shutdown()
    if verbose:
        _print_summary(rows, best, wall, settings)
    return out


def _write_results(out: Path, settings: SweepSettings) -> list[dict]:
    """``results.csv`` and ``curves.csv`` from the trials' run folders; rows best first."""
    keys = sorted(SEARCH_SPACES[settings.algo]) if settings.n_search else []
    rows, curves = [], []
    for trial in sorted((out / "trials").iterdir()):
        if not (trial / "config.json").is_file():
            continue
        meta = json.loads((trial / "config.json").read_text())
        hyper = meta.get("overrides", {})
        evals = []
        if (trial / "eval.csv").is_file():
            with open(trial / "eval.csv") as fh:
                evals = list(csv.DictReader(fh))
        for e in evals:
            curves.append(
                {
                    "trial": trial.name,
                    "seed": meta["seed"],
                    "timesteps": int(e["timesteps"]),
                    "wall_s": float(e["wall_s"]),
                    "score": float(e["score"]),
                    "valid": float(e["valid"]),
                }
            )
        scores = [float(e["score"]) for e in evals]
        i = min(range(len(scores)), key=scores.__getitem__) if scores else None
        rows.append(
            {
                "trial": trial.name,
                "seed": meta["seed"],
                **{k: hyper.get(k) for k in keys},
                "best_score": scores[i] if i is not None else math.inf,
                "best_valid": float(evals[i]["valid"]) if i is not None else 0.0,
                "best_at": int(evals[i]["timesteps"]) if i is not None else 0,
                "timesteps": int(evals[-1]["timesteps"]) if evals else 0,
                "wall_s": float(evals[-1]["wall_s"]) if evals else 0.0,
            }
        )
    rows.sort(key=lambda r: r["best_score"])
    for name, table in (("results.csv", rows), ("curves.csv", curves)):
        if table:
            with open(out / name, "w", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=list(table[0]))
                w.writeheader()
                w.writerows(table)
    return rows


def _copy_best(out: Path, rows: list[dict]) -> Path | None:
    if not rows or not math.isfinite(rows[0]["best_score"]):
        return None
    src = out / "trials" / rows[0]["trial"]
    dst = out / "best"
    if dst.exists():
        shutil.rmtree(dst)
    dst.mkdir()
    for name in ("best_model.zip", "best_vecnormalize.json", "config.json", "eval.csv"):
        if (src / name).is_file():
            shutil.copy2(src / name, dst / name)
    return dst


def _print_summary(rows: list[dict], best: Path | None, wall: float, settings) -> None:
    kind = f"search of {settings.n_search} trials" if settings.n_search else "seeds"
    print(
        f"sweep ({kind}) of {settings.algo} on {settings.env_id}: {len(rows)} trials in "
        f"{wall:.0f} s on {settings.workers} workers ({len(rows) / wall * 60:.2f} trials/min)"
    )
    for r in rows:
        extra = ", ".join(
            f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
            for k, v in r.items()
            if k in SEARCH_SPACES[settings.algo]
        )
        print(
            f"  {r['trial']}: seed {r['seed']}, best validation score {r['best_score']:.4g} "
            f"({r['best_valid']:.0%} count) at {r['best_at']} steps"
            + (f"; {extra}" if extra else "")
        )
    if best is not None:
        print(f"best model: {best / 'best_model.zip'}")
