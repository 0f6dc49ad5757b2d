"""One evaluation harness for every agent on every env: same scenarios, seeds and metrics."""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

import machining_envs  # noqa: F401  (registers the env ids)
from machining_envs.core.checks import is_integer
from machining_envs.core.metrics import regulation_metrics
from machining_envs.core.score import REGULATION_SCORE, Task
from machining_envs.core.splits import split_seeds

__all__ = [
    "rollout",
    "rollout_batch",
    "evaluate",
    "evaluate_validation",
    "Evaluation",
    "agent_name",
    "task_of",
]

#: Most lanes of one batch of :func:`evaluate` (an evaluation of more episodes runs in
#: several batches): a batch runs until its longest episode ends, and a lane holds 8-16 kB.
MAX_BATCH_LANES = 1024

#: The task of an env that declares none (an env of another library): the regulation
#: metrics and the machining-time score.
DEFAULT_TASK = Task(regulation_metrics, REGULATION_SCORE)


def task_of(env) -> Task:
    """The task an env (or env class) is judged by: its class's ``task`` (episode metrics
    and primary score), found through any wrappers; ``DEFAULT_TASK`` for an env that
    declares none.

    Ids registered from other projects with our env classes find their task this way.
    """
    base = env if isinstance(env, type) else getattr(env, "unwrapped", env)
    task = getattr(base, "task", None)
    return task if isinstance(task, Task) else DEFAULT_TASK


def agent_name(agent) -> str:
    """The agent's ``name`` attribute, else its class name (SB3 models: ``PPO`` etc.)."""
    return str(getattr(agent, "name", type(agent).__name__))


def rollout(
    agent, env: gym.Env, scenario=None, seed: int | None = None, keys=None
) -> dict[str, np.ndarray]:
    """Run one episode and return its ``info`` trajectory (plus ``reward``) as arrays.

    Entry 0 is the reset's info (reward 0). ``machining_time_s`` is NaN until the cut ends.
    ``keys`` (a set of info keys), where given, keeps only those keys of the info.
    """
    options = {"scenario": scenario} if scenario is not None else None
    obs, info = env.reset(seed=seed, options=options)
    rows = [info]
    rewards = [0.0]
    state = None
    start = np.ones(1, dtype=bool)
    done = False
    while not done:
        action, state = agent.predict(obs, state=state, episode_start=start, deterministic=True)
        start = np.zeros(1, dtype=bool)
        obs, reward, terminated, truncated, info = env.step(action)
        rows.append(info)
        rewards.append(float(reward))
        done = terminated or truncated
    numbers = [k for k, v in rows[-1].items() if isinstance(v, (bool, int, float, np.number))]
    if keys is not None:
        numbers = [k for k in numbers if k in keys]
    traj = {k: np.array([r.get(k, math.nan) for r in rows]) for k in numbers}
    traj["reward"] = np.array(rewards)
    traj["scenario"] = rows[0].get("scenario")
    episode_log = getattr(agent, "episode_log", None)
    if episode_log is not None:  # what the agent logged of the episode (e.g. AFC's flags)
        traj["agent_log"] = episode_log(state)[0]
    return traj


def rollout_batch(
    agent, venv, scenario, seeds: Sequence[int], keys=None
) -> list[dict[str, np.ndarray]]:
    """One episode in each lane of a native vector env (``num_envs == len(seeds)``), the
    agent acting on the whole batch; returns one trajectory per lane, exactly as
    :func:`rollout` returns it for the same seed, scenario and ``keys``.

    Lane ``i`` is reset with seed ``seeds[i]`` on ``scenario`` (one for every lane; or a
    list of one per lane; None, or a None entry: the env's default); a lane that finishes
    is reset by the vector env and its later steps are ignored until every lane has
    finished.
    """
    n = venv.num_envs
    if len(seeds) != n:
        raise ValueError(f"seeds must hold one seed per lane ({n}), got {len(seeds)}")
    mode = venv.metadata.get("autoreset_mode")
    if mode != gym.vector.AutoresetMode.SAME_STEP:  # a lane's last info is its final_info
        raise ValueError(f"rollout_batch needs a same-step autoreset vector env, got {mode!r}")
    if isinstance(scenario, (list, tuple)):
        if len(scenario) != n:
            raise ValueError(f"scenario must hold one scenario per lane ({n}), got {len(scenario)}")
        if any(sc is None for sc in scenario):  # the env's default for those lanes
            default = venv.unwrapped.default_scenario
            scenario = [
                (default[i] if isinstance(default, list) else default) if sc is None else sc
                for i, sc in enumerate(scenario)
            ]
    options = {"scenario": scenario} if scenario is not None else None
    obs, info = venv.reset(seed=[int(s) for s in seeds], options=options)
    infos, rewards = [info], [np.zeros(n)]
    length = np.zeros(n, dtype=np.int64)
    done = np.zeros(n, dtype=bool)
    state, start = None, np.ones(n, dtype=bool)
    episode_log = getattr(agent, "episode_log", None)
    logs: list = [None] * n
    while not done.all():
        action, state = agent.predict(obs, state=state, episode_start=start, deterministic=True)
        obs, reward, terminated, truncated, info = venv.step(action)
        ended = np.logical_or(terminated, truncated)
        infos.append(info)
        rewards.append(np.asarray(reward, dtype=np.float64))
        length[ended & ~done] = len(infos) - 1
        if episode_log is not None:  # the agent's log of each lane's episode, as it ends
            for i in np.flatnonzero(ended & ~done).tolist():
                logs[i] = episode_log(np.asarray(state)[i : i + 1])[0]
        done |= ended
        start = ended
    trajs = _lane_trajectories(infos, rewards, length, keys)
    if episode_log is not None:
        for traj, log in zip(trajs, logs, strict=True):
            traj["agent_log"] = log
    return trajs


def _rows(items: list, dtype) -> np.ndarray:
    """The arrays ``items`` (a vector env's info values, one per step) end to end, as
    ``dtype``: one copy (``np.array`` of a list of arrays takes half as long again); values
    that are not all arrays of one dimension go through ``np.array``."""
    try:
        return np.concatenate(items, dtype=dtype)
    except (ValueError, TypeError):
        return np.array(items, dtype=dtype)


def _stack(dicts: list[dict], key: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(values, ok)`` arrays ``(len(dicts), n)`` of ``d[key]`` over ``dicts`` (NaN where a
    dict lacks it) and of its mask ``d["_" + key]`` (True where absent, False where the key is)."""
    mask_key = "_" + key
    if all(key in d for d in dicts):
        vals = _rows([d[key] for d in dicts], np.float64).reshape(len(dicts), n)
        if all(mask_key in d for d in dicts):
            ok = _rows([d[mask_key] for d in dicts], bool).reshape(len(dicts), n)
        else:
            ok = np.stack(
                [
                    np.broadcast_to(np.asarray(d.get(mask_key, True), dtype=bool), (n,))
                    for d in dicts
                ]
            )
        return vals, ok
    vals = np.full((len(dicts), n), np.nan)
    ok = np.zeros((len(dicts), n), dtype=bool)
    for t, d in enumerate(dicts):
        if key in d:
            vals[t] = d[key]
            ok[t] = d.get(mask_key, True)
    return vals, ok


def _lane_trajectories(
    infos: list[dict], rewards: list, length: np.ndarray, wanted=None
) -> list[dict]:
    """Per-lane trajectories (as :func:`rollout` gives them) from a vector env's infos:
    lane ``i``'s rows are the infos of steps ``0 .. length[i] - 1`` and the ``final_info``
    of step ``length[i]``; only the info keys in ``wanted``, where given."""
    n = len(length)
    # Only the steps where some lane ended hold a final_info: stack those alone (a batch of
    # long episodes has tens of thousands of steps and a few hundred such).
    fin_steps = [t for t, info in enumerate(infos) if "final_info" in info]
    finals = [infos[t]["final_info"] for t in fin_steps]
    fin_row = {t: r for r, t in enumerate(fin_steps)}
    keys = {k for k in set().union(*infos, *finals) if not k.startswith("_")}
    keys -= {"final_obs", "final_info"}
    if wanted is not None:  # stacking is most of a long batch's bookkeeping: only these
        keys &= set(wanted)
    columns = {}
    for key in keys:
        sample = next(np.asarray(d[key]) for d in (*infos, *finals) if key in d)  # the key's dtype
        if sample.dtype.kind not in "biuf" or sample.ndim != 1:
            continue  # rollout keeps numbers only (not the arrays of a signal's components)
        top, top_ok = _stack(infos, key, n)
        fin, fin_ok = _stack(finals, key, n)
        columns[key] = (top, top_ok, fin, fin_ok, sample.dtype)
    reward = np.array(rewards)
    scenario = infos[0].get("scenario")
    trajs = []
    for i in range(n):
        last = int(length[i])
        row = fin_row[last]  # the lane ended at step `last`: its final_info is there
        traj = {}
        for key, (top, top_ok, fin, fin_ok, dtype) in columns.items():
            if not fin_ok[row, i]:
                continue  # not in the lane's last row: rollout leaves such keys out
            col = np.where(top_ok[:last, i], top[:last, i], np.nan)
            col = np.append(col, fin[row, i])
            if dtype.kind in "biu" and not np.isnan(col).any():
                col = col.astype(dtype if dtype.kind == "b" else np.int64)
            traj[key] = col
        traj["reward"] = np.concatenate(([0.0], reward[1 : last + 1, i]))
        traj["scenario"] = None if scenario is None else scenario[i]
        trajs.append(traj)
    return trajs


@dataclass
class Evaluation:
    """Per-episode metrics (``rows``) and, when kept, the trajectories they came from."""

    rows: list[dict] = field(default_factory=list)
    trajectories: list[dict] = field(default_factory=list)

    @staticmethod
    def concat(evals: Iterable[Evaluation]) -> Evaluation:
        out = Evaluation()
        for ev in evals:
            out.rows.extend(ev.rows)
            out.trajectories.extend(ev.trajectories)
        return out

    def metric_names(self) -> list[str]:
        skip = {"agent", "scenario", "episode", "seed", "env_id"}
        return [k for k in self.rows[0] if k not in skip] if self.rows else []

    def _columns(self, metrics) -> list[str]:
        """``metrics`` as a list (one name alone is a list of one; none: every metric)."""
        if isinstance(metrics, str):
            return [metrics]
        return list(metrics or self.metric_names())

    def summary(
        self, metrics: Sequence[str] | None = None, by: Sequence[str] = ("agent", "scenario")
    ):
        """Mean, standard deviation and count of each metric per group. ``ValueError``
        names a metric or grouping key that some row lacks, with the metrics there are."""
        metrics = self._columns(metrics)
        by = [by] if isinstance(by, str) else list(by)
        for key in [*by, *metrics]:
            missing = sum(key not in r for r in self.rows)
            if missing:
                raise ValueError(
                    f"{key!r} is not a column of {missing} of the {len(self.rows)} rows; "
                    f"the metrics of the first row are {self.metric_names()}"
                )
        groups: dict[tuple, list[dict]] = {}
        for r in self.rows:
            groups.setdefault(tuple(r[k] for k in by), []).append(r)
        out = []
        for key, rs in groups.items():
            row = dict(zip(by, key, strict=True))
            row["n"] = len(rs)
            for m in metrics:
                v = np.array([r[m] for r in rs], dtype=np.float64)
                row[m] = float(np.mean(v))
                row[m + "_std"] = float(np.std(v))
            out.append(row)
        return out

    def to_markdown(
        self, metrics: Sequence[str] | None = None, by: Sequence[str] = ("agent", "scenario")
    ) -> str:
        """Markdown table of ``mean ± std`` per group (breakage and finished as counts)."""
        metrics = self._columns(metrics)
        by = [by] if isinstance(by, str) else list(by)
        summ = self.summary(metrics, by)
        head = [*by, "n", *metrics]
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for row in summ:
            cells = [str(row[k]) for k in by] + [str(row["n"])]
            for m in metrics:
                if m in ("breakage", "finished", "diverged"):
                    cells.append(f"{round(row[m] * row['n'])}/{row['n']}")
                else:
                    cells.append(f"{row[m]:.3g} ± {row[m + '_std']:.2g}")
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)

    def to_csv(self, path) -> None:
        """One line per episode; the columns are every metric any row has (rows from envs
        with different metrics leave the others' cells empty)."""
        if not self.rows:
            raise ValueError("no rows to write")
        fields = list(dict.fromkeys(k for row in self.rows for k in row))
        with open(path, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=fields, restval="")
            w.writeheader()
            w.writerows(self.rows)


def _scenario_label(sc) -> str:
    """A row's scenario: a name as it is, an object by its ``name``; an env (the scenario
    ``None`` ran its default) by its default scenario's label, else ``"default"``."""
    if isinstance(sc, gym.Env):
        default = getattr(sc.unwrapped, "default_scenario", None)
        return "default" if default is None else _scenario_label(default)
    return sc if isinstance(sc, str) else str(getattr(sc, "name", sc))


def _iterable(v) -> bool:
    try:
        iter(v)
    except TypeError:
        return False
    return True


def evaluate(
    agent,
    env_id: str,
    scenarios: Sequence,
    n_episodes: int = 1,
    seed: int = 0,
    env_kwargs: dict | None = None,
    keep_trajectories: bool = False,
    metrics_fn: Callable[[dict], dict] | None = None,
    batched: bool | None = None,
    progress: bool = False,
    keep_seeds: Iterable[int] | None = None,
    extra_keys: Iterable[str] = (),
) -> Evaluation:
    """Evaluate ``agent`` on ``env_id`` over ``scenarios`` x ``n_episodes``.

    Parameters
    ----------
    agent
        Anything with SB3's ``predict``, or a factory ``env -> agent`` (such as
        ``VariableGainPI.from_env``) called once with the evaluation env.
    env_id : str
        A registered id, e.g. ``"machining_envs/Turning-v0"``.
    scenarios : sequence
        Scenario names or objects, passed to ``reset(options={"scenario": ...})`` (one name
        or object alone is a list of one).
    n_episodes : int
        Episodes per scenario; episode ``i`` uses seed ``seed + i``, so every agent meets the
        same workpieces and noise.
    metrics_fn : callable, optional
        Trajectory -> metrics of one episode; by default the env's own (``task_of``).
        Where it declares the info keys it reads (an ``info_keys`` attribute, see
        ``machining_envs.core.metrics.reads_info``; the envs' own metrics do) and the
        trajectories are not kept, the episodes record only those keys.
    batched : bool, optional
        Run the episodes (``n_episodes`` of every scenario) as the lanes of the env's native
        vector env (``gym.make_vec``, each lane on its own scenario), the agent predicting
        for all of them at once, in batches of at most ``MAX_BATCH_LANES``; the rows are
        the same as episode by episode. By default batched where the id has a native vector
        env and more than one episode is asked for in all (a sweep over many scenarios of
        one episode each included).
    progress : bool
        Show a progress bar (tqdm, on stderr) over the episodes.
    keep_seeds : iterable of int, optional
        Keep the trajectories of the episodes with these seeds only (with the metrics'
        keys and ``extra_keys``), as a benchmark keeps the episodes it plots without
        running them again.
    extra_keys : iterable of str
        Info keys recorded beside the metrics' own (where those are declared).
    """
    if not (hasattr(agent, "predict") or callable(agent)):
        raise TypeError(
            f"agent must have SB3's predict or be a factory env -> agent, got {agent!r:.60}"
        )
    if not is_integer(n_episodes) or n_episodes < 1:
        raise ValueError(f"n_episodes must be an integer >= 1, got {n_episodes!r}")
    if not is_integer(seed) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    if env_kwargs is not None and not isinstance(env_kwargs, dict):
        raise TypeError(f"env_kwargs must be a dict or None, got {type(env_kwargs).__name__}")
    if batched is not None and not isinstance(batched, (bool, np.bool_)):
        raise TypeError(f"batched must be True, False or None, got {batched!r}")
    for flag, value in (("keep_trajectories", keep_trajectories), ("progress", progress)):
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{flag} must be True or False, got {value!r}")
    if metrics_fn is not None and not callable(metrics_fn):
        raise TypeError(f"metrics_fn must be a function trajectory -> metrics, got {metrics_fn!r}")
    if not isinstance(env_id, str) or env_id not in gym.registry:
        raise ValueError(f"env_id must be a registered env id, got {env_id!r}")
    has_vector = gym.spec(env_id).vector_entry_point is not None
    if scenarios is None:  # (not taken for the env's default: say so with [None])
        raise ValueError(
            "scenarios must be scenario names or objects (such as ['validation']), or [None] "
            "for the env's default scenario; got None"
        )
    # One scenario (a name or an object) is a list of one.
    scenarios = (
        [scenarios] if isinstance(scenarios, str) or not _iterable(scenarios) else list(scenarios)
    )
    if not scenarios:
        raise ValueError("scenarios must hold at least one scenario name or object, got none")
    if batched is None:
        batched = has_vector and n_episodes * len(scenarios) > 1
    elif batched and not has_vector:
        raise ValueError(f"batched=True: {env_id} has no native vector env")
    env = gym.make(env_id, **(env_kwargs or {}))
    venv = None
    try:
        if metrics_fn is None:
            metrics_fn = task_of(env).metrics
        # The keys the metrics read, where they say (None: every key); all when kept.
        keys = None if keep_trajectories else getattr(metrics_fn, "info_keys", None)
        if keys is not None:
            keys = frozenset(keys) | frozenset(extra_keys)
        kept = None if keep_seeds is None else {int(s) for s in keep_seeds}
        if not hasattr(agent, "predict") and callable(agent):
            agent = agent(env)
            if not hasattr(agent, "predict"):
                raise TypeError(f"the agent factory returned {agent!r:.60}, which has no predict")
        name = agent_name(agent)
        ev = Evaluation()
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=len(scenarios) * n_episodes, desc=name, unit="episode")
        seeds = [seed + i for i in range(n_episodes)]
        if batched:  # every (scenario, episode) a lane, in batches
            jobs = [(j, i) for j in range(len(scenarios)) for i in range(n_episodes)]
            done: list[list] = [[None] * n_episodes for _ in scenarios]
            for first in range(0, len(jobs), MAX_BATCH_LANES):
                batch = jobs[first : first + MAX_BATCH_LANES]
                if venv is None or venv.num_envs != len(batch):
                    if venv is not None:
                        venv.close()
                    venv = gym.make_vec(
                        env_id,
                        num_envs=len(batch),
                        autoreset_mode="SAME_STEP",
                        **(env_kwargs or {}),
                    )
                trajs = rollout_batch(
                    agent,
                    venv,
                    [scenarios[j] for j, _ in batch],
                    [seeds[i] for _, i in batch],
                    keys,
                )
                for (j, i), traj in zip(batch, trajs, strict=True):
                    done[j][i] = traj
                if bar is not None:
                    bar.update(len(batch))
        for j, sc in enumerate(scenarios):
            if batched:
                trajs = done[j]
            else:
                trajs = []
                for s in seeds:
                    trajs.append(rollout(agent, env, sc, s, keys))
                    if bar is not None:
                        bar.update(1)
            for i, traj in enumerate(trajs):
                row = {
                    "agent": name,
                    "scenario": _scenario_label(env if sc is None else sc),
                    "episode": i,
                    "seed": seed + i,
                }
                log = traj.pop("agent_log", None)
                row.update(metrics_fn(traj))
                if log:  # the agent's own log of the episode (AFC: teach-in, flags ...)
                    prefix = getattr(agent, "log_prefix", "agent_")
                    row.update({prefix + k: v for k, v in log.items()})
                ev.rows.append(row)
                if keep_trajectories or (kept is not None and seed + i in kept):
                    traj["agent"] = name
                    traj["seed"] = seed + i
                    ev.trajectories.append(traj)
        if bar is not None:
            bar.close()
        return ev
    finally:
        env.close()
        if venv is not None:
            venv.close()


def evaluate_validation(
    agent, env_id: str, n_episodes: int, first_episode: int = 0, **kwargs
) -> Evaluation:
    """:func:`evaluate` on ``n_episodes`` episodes of the ``validation`` split from its
    ``first_episode`` on (seeds from ``split_seeds("validation", ...)``), as training and
    tuning select on them; ``kwargs``: evaluate's other keywords."""
    seed = split_seeds("validation", first_episode + n_episodes)[first_episode]
    return evaluate(agent, env_id, ["validation"], n_episodes=n_episodes, seed=seed, **kwargs)
