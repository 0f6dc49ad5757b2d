"""Running one env's benchmark: every row's agent on the held-out episodes, once.

:func:`run_env` runs the paper agents, the tuned classical agents (the classes the spec's
``tuned`` names, at ``agents/bench/tuned.json``'s settings), each training seed of the
learned policies and the MPC oracle on the fixed episodes of the ``test`` split (and the
``ood`` and extra splits), paired by seed, and keeps, beside every episode's metrics row,
the recorded trajectory of one typical test episode of every agent (the plots draw those:
no episode is simulated twice). The statistics (``agents.bench.results``), the plots
(``agents.bench.plots``) and the report (``agents.bench.report``) read the :class:`EnvRun`
it returns.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import gymnasium as gym

from agents.bench.spec import BenchmarkSpec
from agents.bench.tune import agent_env_kwargs, machine_tuned_factory, tuned_factory
from agents.eval import Evaluation, evaluate
from machining_envs.core.splits import split_seeds

__all__ = [
    "EnvRun",
    "Job",
    "jobs_of",
    "run_env",
    "oracle_episodes",
    "representative_seed",
    "installed",
]


def installed(module: str) -> bool:
    """Whether ``module`` imports (an optional extra's package)."""
    try:
        __import__(module)
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class Job:
    """One row's agent: its ``kind`` (paper, tuned, learned, oracle), its factory
    ``env -> agent``, the training seed of a learned policy and the class of a tuned row
    (one of the spec's ``tuned``). A row tuned for the shop-floor machine (one of the
    spec's ``machine_tuned``) has ``machine_cls`` instead and runs on the ``splits`` named
    only (None: every split). ``env_kwargs`` go over the spec's: the machine's env options,
    a tuned class's ``ENV_KWARGS`` and a learned policy's run options
    (``agents.rl.policy.policy_env_kwargs``): ``PeckDrilling`` and the peck policy drill
    with ``control="feed"``, on the same episodes, scored by the same task."""

    kind: str
    factory: object
    policy_seed: int | None = None
    tuned_cls: type | None = None
    machine_cls: type | None = None
    splits: tuple[str, ...] | None = None
    env_kwargs: dict | None = None


class EnvRun:
    """The rows of one env: per agent, its kind, its episode rows per split, the class of a
    tuned row and the recorded trajectory of the typical episode ``plot_seed``."""

    def __init__(self, spec: BenchmarkSpec):
        self.spec = spec
        self.kind: dict[str, str] = {}
        self.rows: dict[str, dict[str, list]] = {}
        self.factory: dict[str, object] = {}
        self.tuned_cls: dict[str, type] = {}
        #: The rows tuned for the shop-floor machine: name -> class (of ``machine_tuned``).
        self.machine_cls: dict[str, type] = {}
        #: Agent name -> the ``gym.make`` keywords its rows ran with (the spec's, with the
        #: row's own over them: ``control="feed"`` for the peck cycles).
        self.env_kwargs: dict[str, dict] = {}
        #: Agent name -> the trajectory of test episode ``plot_seed`` (a learned row: its
        #: first training seed's).
        self.trajectories: dict[str, dict] = {}
        self.plot_seed: int | None = None
        #: Split -> the episodes each of its rows runs.
        self.n_episodes: dict[str, int] = {}
        env = gym.make(spec.env_id, **spec.env_kwargs)
        try:
            self.score = spec.task.score
            self.failed = self.score.failed_value(env)
        finally:
            env.close()

    def add(self, name, kind, split, rows, policy_seed=None):
        for r in rows:
            r["env_id"] = self.spec.env_id
            r["split"] = split
            r["kind"] = kind
            if policy_seed is not None:
                r["policy_seed"] = policy_seed
        self.kind.setdefault(name, kind)
        self.rows.setdefault(name, {}).setdefault(split, []).extend(rows)

    def env_kwargs_of(self, name: str) -> dict:
        """The ``gym.make`` keywords of ``name``'s env (see ``env_kwargs``)."""
        return dict(self.env_kwargs.get(name, self.spec.env_kwargs))

    def all_rows(self) -> list[dict]:
        return [r for by in self.rows.values() for rs in by.values() for r in rs]

    def names(self, split: str = "test") -> list[str]:
        return [n for n in self.rows if split in self.rows[n]]


def jobs_of(
    spec: BenchmarkSpec,
    tuned: dict,
    verbose: bool,
    one_seed: bool = False,
    machine_tuned: dict | None = None,
) -> list[Job]:
    """Every row the env's benchmark runs but the oracle (with ``one_seed``, each learned
    row's first training seed only). ``machine_tuned``: the settings tuned for the
    shop-floor machine (``agents/bench/tuned_shopfloor.json``), whose rows run on the
    ``shopfloor`` split where the spec has it."""
    out = [Job("paper", f) for f in spec.paper_agents]
    # (classes, their settings file, factory, what a missing entry prints, Job's fields)
    groups = [
        (
            spec.tuned,
            tuned,
            tuned_factory,
            "no tuned settings (run `machining-bench tune`)",
            lambda cls: {"tuned_cls": cls, "env_kwargs": agent_env_kwargs(cls) or None},
        )
    ]
    if "shopfloor" in spec.extra_splits and machine_tuned:
        kwargs = machine_tuned.get("env_kwargs", {}).get(spec.env_id, {})
        groups.append(
            (
                spec.machine_classes,
                machine_tuned,
                machine_tuned_factory,
                "no settings tuned for the shop-floor machine",
                lambda cls: {
                    "machine_cls": cls,
                    "splits": ("shopfloor",),
                    "env_kwargs": agent_env_kwargs(cls, kwargs),
                },
            )
        )
    for classes, data, make, missing, fields in groups:
        for cls in classes:
            f = make(cls, spec.env_id, data)
            if f is None:
                if verbose:
                    print(f"  {cls.__name__}: {missing}")
                continue
            out.append(Job("tuned", f, **fields(cls)))
    if spec.learned:
        if not installed("stable_baselines3"):
            if verbose:
                print(
                    "  learned rows skipped: they need the rl extra (pip install 'machining-envs[rl]')"
                )
        else:
            from agents.rl.policy import load_policy, policy_env_kwargs, pretrained_seeds

            for name in spec.learned:
                for seed, path in pretrained_seeds(name)[: 1 if one_seed else None]:

                    def make(env, path=path, name=name):
                        return load_policy(path, name=f"{name}", env=env)

                    # the env as the policy acts on it (a peck policy: control="feed")
                    kwargs = policy_env_kwargs(path) or None
                    out.append(Job("learned", make, seed, env_kwargs=kwargs))
    return out


class _Progress:
    """One progress bar per env (tqdm on stderr, where installed: the ``rl`` and ``bench``
    extras bring it), advanced once per agent and split and once per oracle episode; without
    tqdm, one printed line per agent. Silent when ``verbose`` is False."""

    def __init__(self, env_name: str, total: int, verbose: bool, t0: float):
        self.env_name, self.verbose, self.t0 = env_name, verbose, t0
        self.bar = None
        if verbose and installed("tqdm"):
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=env_name, unit="run", leave=True)

    def note(self, text: str) -> None:
        if not self.verbose:
            return
        if self.bar is not None:
            self.bar.write(text)
        else:
            print(text)

    def working_on(self, text: str) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(text)

    def done(self, text: str, n: int = 1) -> None:
        if self.bar is not None:
            self.bar.update(n)
        elif self.verbose:
            print(f"[{self.env_name}] {text} ({time.perf_counter() - self.t0:.0f} s)")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def representative_seed(spec: BenchmarkSpec, seeds: list[int]) -> int | None:
    """The test episode among ``seeds`` whose physical bound (``info["score_bound"]`` at
    reset, from the episode's truth) is the median: a typical workpiece, not a chosen one,
    known before any agent runs. None where the env gives no bound."""
    env = gym.make(spec.env_id, **spec.env_kwargs)
    try:
        vals = []
        for s in seeds:
            _, info = env.reset(seed=s, options={"scenario": "test"})
            b = float(info.get("score_bound", math.nan))
            if not math.isfinite(b):
                return None
            vals.append((b, s))
    finally:
        env.close()
    vals.sort()
    return int(vals[len(vals) // 2][1])


def _plot_keys(spec: BenchmarkSpec) -> set[str]:
    keys = {"t_s", spec.plot_main[0], spec.plot_lower[0]}
    if spec.plot_main[1] is not None:
        keys.add(spec.plot_main[1])
    if spec.plot_context is not None:
        keys.add(spec.plot_context[0])
    return keys


def run_env(
    spec: BenchmarkSpec,
    n_test,
    n_ood,
    n_oracle,
    tuned: dict,
    verbose: bool,
    t0,
    one_seed: bool = False,
    oracle_apart: bool = False,
    machine_tuned: dict | None = None,
    n_extra: dict | None = None,
) -> EnvRun:
    """Run every row of ``spec`` (see the module docstring): ``n_test`` test episodes,
    ``n_ood`` of ``ood`` and of each extra split (``n_extra``: split -> episodes, where
    not ``n_ood``; only where ``n_ood`` is not 0), and the oracle on the first
    ``min(n_oracle, spec.oracle_episodes)`` test episodes; the rows tuned for the
    shop-floor machine (``machine_tuned``) on the ``shopfloor`` split only. ``oracle_apart``:
    the oracle runs in a process of its own beside the other rows (the same episodes, the
    same numbers; it is the slowest row, so the env takes about the longer of the two
    instead of their sum)."""
    run = EnvRun(spec)
    env_name = spec.env_id.split("/")[-1]
    extra = [(x, (n_extra or {}).get(x, n_ood) if n_ood else 0) for x in spec.extra_splits]
    named = (("test", n_test), ("ood", n_ood), *extra)
    splits = [(split, n) for split, n in named if n > 0]
    run.n_episodes = dict(splits)
    jobs = [
        j
        for j in jobs_of(spec, tuned, verbose, one_seed, machine_tuned)
        if j.splits is None or any(s in j.splits for s, _ in splits)
    ]

    def job_splits(job):
        return [(s, n) for s, n in splits if job.splits is None or s in job.splits]

    oracle_skipped = None
    if spec.oracle is not None and n_oracle < spec.oracle_episodes and not spec.oracle_in_quick:
        oracle_skipped = f"  oracle skipped in --quick ({spec.oracle_seconds:g} s an episode)"
    elif spec.oracle is not None and not installed("casadi"):
        oracle_skipped = "  oracle skipped: it needs casadi (pip install 'machining-envs[bench]')"
    n_oracle_run = 0
    if spec.oracle is not None and oracle_skipped is None:
        n_oracle_run = min(spec.oracle_episodes, n_oracle)
    test_seeds = split_seeds("test", n_test)
    # The plotted episode: among the oracle's episodes where it runs, so that it is drawn too.
    run.plot_seed = representative_seed(spec, test_seeds[: n_oracle_run or None])
    plot_keys = _plot_keys(spec)
    n_runs = sum(len(job_splits(j)) for j in jobs)
    progress = _Progress(env_name, n_runs + n_oracle_run, verbose, t0)
    oracle_args = (spec.env_id, n_oracle_run, test_seeds[0], run.plot_seed, plot_keys)
    apart = None
    if oracle_apart and n_oracle_run > 0:
        apart = _start_apart(oracle_episodes, *oracle_args)
    try:
        for k, job in enumerate(jobs):
            tag = f" seed {job.policy_seed}" if job.policy_seed is not None else ""
            kwargs = {**spec.env_kwargs, **(job.env_kwargs or {})}
            for split, n in job_splits(job):
                progress.working_on(f"{job.kind}{tag} on {split}")
                keep = None
                if split == "test":  # the first agent keeps all, where no bound chose one
                    keep = test_seeds if run.plot_seed is None else [run.plot_seed]
                ev = evaluate(
                    job.factory,
                    spec.env_id,
                    [split],
                    n_episodes=n,
                    seed=split_seeds(split, n)[0],
                    env_kwargs=kwargs,
                    keep_seeds=keep,
                    extra_keys=plot_keys,
                )
                name = ev.rows[0]["agent"]
                if split == "test":
                    _keep_plotted(run, name, ev)
                run.factory.setdefault(name, job.factory)
                run.env_kwargs.setdefault(name, kwargs)
                if job.tuned_cls is not None:
                    run.tuned_cls[name] = job.tuned_cls
                if job.machine_cls is not None:
                    run.machine_cls[name] = job.machine_cls
                run.add(name, job.kind, split, ev.rows, job.policy_seed)
                progress.done(f"{k + 1}/{len(jobs)} {job.kind} {name}{tag} on {split}")
        if oracle_skipped is not None:
            progress.note(oracle_skipped)
        elif spec.oracle is not None:
            progress.working_on(f"oracle, {n_oracle_run} test episodes")
            if apart is None:
                ev = oracle_episodes(*oracle_args)
            else:
                pool, future = apart
                ev = future.result()
                pool.shutdown()
                apart = None
            name = ev.rows[0]["agent"]
            _keep_plotted(run, name, ev)
            run.factory.setdefault(name, spec.oracle)
            run.add(name, "oracle", "test", ev.rows)
            progress.done(f"oracle {name}, {n_oracle_run} test episodes", n_oracle_run)
    finally:
        progress.close()
        if apart is not None:  # an error in the other rows: do not wait for the oracle
            apart[0].shutdown(wait=False, cancel_futures=True)
    return run


def _spec(env_id: str) -> BenchmarkSpec:
    from agents.bench.declarations import BENCHMARKS

    return next(s for s in BENCHMARKS if s.env_id == env_id)


def oracle_episodes(env_id: str, n: int, seed: int, plot_seed, plot_keys) -> Evaluation:
    """The oracle of ``env_id``'s benchmark on ``n`` test episodes from ``seed``, one at a
    time, keeping the trajectory of ``plot_seed``."""
    spec = _spec(env_id)
    return evaluate(
        spec.oracle,
        spec.env_id,
        ["test"],
        n_episodes=n,
        seed=seed,
        env_kwargs=spec.env_kwargs,
        batched=False,
        keep_seeds=[plot_seed] if plot_seed is not None else [],
        extra_keys=plot_keys,
    )


def one_thread() -> None:
    """A worker process computes on one core: BLAS and torch each get one thread, so that
    ``jobs`` processes do not oversubscribe the machine."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    try:
        import torch
    except ImportError:
        return
    torch.set_num_threads(1)


def _start_apart(fn, *args):
    """``fn(*args)`` started in a new process (spawned, one thread): ``(pool, future)``."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    pool = ProcessPoolExecutor(
        1, mp_context=multiprocessing.get_context("spawn"), initializer=one_thread
    )
    return pool, pool.submit(fn, *args)


def _keep_plotted(run: EnvRun, name: str, ev) -> None:
    """Keep ``name``'s trajectory of the plotted episode (the first training seed's); where
    no bound chose the episode, the first agent's median-score episode chooses it."""
    if name in run.trajectories or not ev.trajectories:
        return
    if run.plot_seed is None:
        charged = sorted((run.score.charged(r, run.failed), r["seed"]) for r in ev.rows)
        run.plot_seed = int(charged[len(charged) // 2][1])
    for tr in ev.trajectories:
        if tr["seed"] == run.plot_seed:
            run.trajectories[name] = tr
