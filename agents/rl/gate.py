"""The seed gate: a trained policy ships only if it holds on ``validation``, edges included.

Every training seed that ships must pass the same gate, whatever the env or algorithm:

- **Episodes.** ``n_validation`` fixed ``validation`` episodes (the split's first reset seeds,
  as every evaluation uses them), plus, for each *edge* the env declares in
  :data:`EDGES`, ``per_edge`` of the same validation draws with that one scenario field
  moved to the low or high end of the **train** range (a spindle at the slowest and the
  fastest speed the policy trained on, the process coefficient at its largest, the deepest
  cut). The edges are read from the env's own ``train`` factory, so a wider training range
  moves them with it. ``test`` and ``ood`` are never touched.
- **Rule.** The policy *passes* if at least :data:`GATE_SHARE` (90 %) of those workpieces
  count under the env's primary score (``PrimaryScore.counts``: finished, nothing broken,
  the constrained signal over its limit on less than the allowance of the steps, and never
  past the overload ceiling where the env reports ``overloaded``), and **no** episode
  overloads (:func:`gate_verdict`).
- **A failing seed** is not shipped and not tuned further: it is replaced by the next
  unused training seed, trained with the same config, and gated the same way; at most as
  many replacements as seeds were asked for. Every failure is recorded (:func:`gated_seeds`,
  ``gate.json``). Seeds are never chosen by a test score.

``python -m agents.rl.gate ENV_ID PATH...`` gates saved policies (a run folder, a
``best_model.zip``, a sweep's results folder or a shipped policy's folder with its
``seed_<k>`` subfolders) and writes the verdicts as JSON; ``machining-bench sweep --gate``
trains seeds under the gate (:func:`gated_sweep`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "GATE_SHARE",
    "EDGES",
    "Edge",
    "GateResult",
    "gate_verdict",
    "train_range",
    "gate_scenarios",
    "gate_agent",
    "gate_policy",
    "next_seeds",
    "gated_seeds",
]

#: The share of the gate's workpieces that must count.
GATE_SHARE = 0.9


@dataclass(frozen=True)
class Edge:
    """One scenario field moved to one end of its ``train`` range."""

    field: str
    """The scenario field (``depth``: the workpiece's profile scaled to the deepest cut)."""
    end: str
    """``"low"`` or ``"high"``."""

    @property
    def label(self) -> str:
        return f"{self.field}={self.end}"


def _edges(*pairs: tuple[str, str]) -> tuple[Edge, ...]:
    return tuple(Edge(f, e) for f, e in pairs)


#: Which scenario fields the gate moves to which end of the ``train`` range, per env id.
#: Both ends of the spindle speed (the policy's dynamics change either way), the high end
#: of the process coefficients and the depth (more load at the same feed); the low ends of
#: those only unload the tool. Envs not named here (the contouring ids, whose scenarios are
#: paths, not process ranges) are gated on ``validation`` episodes alone.
EDGES: dict[str, tuple[Edge, ...]] = {
    "machining_envs/Turning-v0": _edges(
        ("spindle_rpm", "low"),
        ("spindle_rpm", "high"),
        ("force_coefficient_scale", "high"),
        ("depth", "high"),
    ),
    "machining_envs/EndMilling-v0": _edges(
        ("spindle_scale", "low"),
        ("spindle_scale", "high"),
        ("torque_coefficient_scale", "high"),
        ("depth", "high"),
    ),
    "machining_envs/MicroDrilling-v0": _edges(
        ("aspect_ratio", "high"),
        ("cutting_scale", "high"),
        ("chip_scale", "high"),
    ),
}

# MicroDrilling-v0's train ranges, by field (its factory keeps them in a closure).
_DRILLING_FIELDS = (
    "aspect_ratio",
    "cutting_scale",
    "chip_scale",
    "fluctuation_scale",
    "noise_scale",
)


def _canonical(env_id: str) -> str:
    import gymnasium as gym

    import machining_envs  # noqa: F401  (registers the ids)

    return gym.spec(env_id).id


def train_range(env_id: str, name: str) -> tuple[float, float]:
    """The ``train`` split's range of scenario field ``name`` of ``env_id`` (``depth``: of
    the depth of cut, mm), read from the env's scenarios module."""
    env_id = _canonical(env_id)
    if env_id == "machining_envs/MicroDrilling-v0":
        from machining_envs.drilling import scenarios

        if name not in _DRILLING_FIELDS:
            raise ValueError(f"field must be one of {list(_DRILLING_FIELDS)}, got {name!r}")
        lo, hi = scenarios._TRAINING_RANGES[_DRILLING_FIELDS.index(name)]
        return float(lo), float(hi)
    if env_id == "machining_envs/Turning-v0":
        from machining_envs.turning.scenarios import TURNING_SCENARIOS as table
    elif env_id == "machining_envs/EndMilling-v0":
        from machining_envs.milling.scenarios import MILLING_SCENARIOS as table
    else:
        raise ValueError(f"env_id must be one of {sorted(EDGES)}, got {env_id!r}")
    factory = table["train"]
    if name == "depth":
        return tuple(float(v) for v in factory.depth)
    lo, hi = (getattr(s, name, None) for s in factory.extremes)
    if lo is None:
        raise ValueError(f"{env_id} scenarios have no field {name!r}")
    return float(lo), float(hi)


def _at_edge(scenario, env_id: str, edge: Edge):
    """``scenario`` with ``edge.field`` at that end of the train range."""
    lo, hi = train_range(env_id, edge.field)
    value = lo if edge.end == "low" else hi
    if edge.field == "depth":  # the profile's shape kept, its deepest point at the edge
        p = scenario.profile
        k = value / p.max_depth_mm
        profile = dataclasses.replace(
            p,
            start_depths_mm=tuple(d * k for d in p.start_depths_mm),
            end_depths_mm=tuple(d * k for d in p.end_depths_mm),
            name=f"{p.name} (deepest {value:g} mm)",
        )
        return dataclasses.replace(scenario, profile=profile, name=f"{scenario.name} {edge.label}")
    return dataclasses.replace(
        scenario, **{edge.field: value, "name": f"{scenario.name} {edge.label}"}
    )


def gate_scenarios(env_id: str, n_validation: int = 20, per_edge: int = 5):
    """The gate's episodes: ``(label, scenarios, seed)`` groups to evaluate with
    ``n_episodes=1`` per scenario object (or, for ``"validation"``, ``n_validation``
    episodes of the split from its first reset seed)."""
    import gymnasium as gym

    from machining_envs.core.splits import split_seeds

    seeds = split_seeds("validation", n_validation)
    groups = [("validation", ["validation"], seeds[0], n_validation)]
    edges = EDGES.get(_canonical(env_id), ())
    if not edges:
        return groups
    env = gym.make(env_id)
    try:
        drawn = []
        for s in seeds[:per_edge]:
            env.reset(seed=int(s), options={"scenario": "validation"})
            drawn.append(env.unwrapped.scenario)
    finally:
        env.close()
    for edge in edges:
        groups.append((edge.label, [_at_edge(sc, env_id, edge) for sc in drawn], seeds[0], 1))
    return groups


@dataclass
class GateResult:
    """One policy's gate verdict."""

    passed: bool
    n: int
    counting: int
    overloaded: int
    share: float = GATE_SHARE
    by_group: dict = field(default_factory=dict)
    """label -> ``{"n", "counting", "overloaded"}``."""

    @property
    def counting_share(self) -> float:
        return self.counting / self.n if self.n else 0.0

    def as_dict(self) -> dict:
        return {**dataclasses.asdict(self), "counting_share": self.counting_share}


def gate_verdict(
    rows: Sequence[dict],
    score,
    share: float = GATE_SHARE,
    labels: Sequence[str] | None = None,
    allowance: float | None = None,
) -> GateResult:
    """The gate's rule on episode rows: passes if at least ``share`` of them count under
    ``score`` (a ``PrimaryScore``; at its ``allowance`` of steps over the limit, default
    the benchmark's 2 %) and none is ``overloaded``. ``labels`` (one per row) groups the
    counts in ``by_group``."""
    if not rows:
        raise ValueError("rows must hold at least one episode")
    if not (isinstance(share, (int, float)) and 0.0 < share <= 1.0):
        raise ValueError(f"share must be a number in (0, 1], got {share!r}")
    if labels is not None and len(labels) != len(rows):
        raise ValueError(f"labels must give one label per row ({len(rows)}), got {len(labels)}")
    kw = {} if allowance is None else {"allowance": float(allowance)}
    counts = [bool(score.counts(r, **kw)) for r in rows]
    # The ceiling binds where the score has a share over the limit (Contouring-v0 scores
    # the error itself, with neither).
    ceiling = getattr(score, "over_key", None) is not None
    over = [ceiling and float(r.get("overloaded", 0.0) or 0.0) != 0.0 for r in rows]
    by_group: dict = {}
    for i, lab in enumerate(labels or ["all"] * len(rows)):
        g = by_group.setdefault(lab, {"n": 0, "counting": 0, "overloaded": 0})
        g["n"] += 1
        g["counting"] += counts[i]
        g["overloaded"] += over[i]
    n, c, o = len(rows), sum(counts), sum(over)
    # The share is compared in whole episodes, so 18 of 20 passes 90 % exactly.
    passed = c >= math.ceil(share * n - 1e-9) and o == 0
    return GateResult(bool(passed), n, c, o, float(share), by_group)


def gate_agent(
    agent,
    env_id: str,
    env_kwargs: dict | None = None,
    n_validation: int = 20,
    per_edge: int = 5,
    share: float = GATE_SHARE,
) -> GateResult:
    """The gate's episodes and rule on any agent (or factory ``env -> agent``) on
    ``gym.make(env_id, **env_kwargs)``: a classical agent meets the same bar as a policy."""
    from agents.eval import evaluate
    from agents.rl.callbacks import evaluation_setup

    env_kwargs = dict(env_kwargs or {})
    metrics_fn, score, _ = evaluation_setup(env_id, env_kwargs)
    rows, labels = [], []
    for label, scenarios, seed, n_episodes in gate_scenarios(env_id, n_validation, per_edge):
        ev = evaluate(
            agent,
            env_id,
            scenarios,
            n_episodes=n_episodes,
            seed=int(seed),
            env_kwargs=env_kwargs,
            metrics_fn=metrics_fn,
        )
        rows += ev.rows
        labels += [label] * len(ev.rows)
    return gate_verdict(rows, score, share, labels)


def gate_policy(
    model_path,
    env_id: str,
    n_validation: int = 20,
    per_edge: int = 5,
    share: float = GATE_SHARE,
    algo: str | None = None,
) -> GateResult:
    """Gate one saved policy (``best_model.zip`` with its statistics and ``config.json``
    beside it, as ``agents.rl.load_policy`` reads it), on the env as it was trained
    (``control="feed"`` for the pecking policy)."""
    import torch

    from agents.rl.policy import load_policy, policy_env_kwargs

    # One thread: torch's default pool spins against a loaded machine (25x the CPU time
    # of one thread for the milling policy's batched inference on 2 busy cores).
    torch.set_num_threads(1)
    env_kwargs = policy_env_kwargs(model_path)
    agent = load_policy(model_path, algo=algo)
    return gate_agent(agent, env_id, env_kwargs, n_validation, per_edge, share)


def next_seeds(tried: Iterable[int], k: int) -> list[int]:
    """The ``k`` replacement seeds for failed ones: the smallest seeds above every seed tried
    (a fixed rule: no seed is picked by a score)."""
    tried = list(tried)
    start = max(tried) + 1 if tried else 0
    return list(range(start, start + k))


def gated_seeds(
    seeds: Sequence[int],
    train_many: Callable[[list[int]], dict],
    gate: Callable[[object], GateResult],
    max_replacements: int | None = None,
) -> dict:
    """Train ``seeds``, gate each, and replace the failures by :func:`next_seeds` in rounds
    until as many seeds pass as were asked for or ``max_replacements`` (default
    ``len(seeds)``) extra seeds have been trained.

    ``train_many(seeds) -> {seed: model}`` trains a round (a sweep runs it in parallel);
    ``gate(model) -> GateResult``. Returns ``{"asked", "passed", "failed", "replacements",
    "verdicts": {seed: GateResult.as_dict()}, "complete"}``: ``complete`` is False when the
    replacements ran out before ``len(seeds)`` seeds passed (report it; do not ship a
    failing seed in its place)."""
    seeds = [int(s) for s in seeds]
    if not seeds or len(set(seeds)) != len(seeds) or min(seeds) < 0:
        raise ValueError(f"seeds must be distinct integers >= 0, got {seeds!r}")
    budget = len(seeds) if max_replacements is None else int(max_replacements)
    if budget < 0:
        raise ValueError(f"max_replacements must be >= 0, got {max_replacements!r}")
    passed, failed, verdicts, tried = [], [], {}, []
    todo = list(seeds)
    while todo:
        models = train_many(todo)
        tried += todo
        for s in todo:
            v = gate(models[s])
            verdicts[s] = v.as_dict()
            (passed if v.passed else failed).append(s)
        missing = len(seeds) - len(passed)
        extra = len(tried) - len(seeds)
        todo = next_seeds(tried, min(missing, budget - extra)) if missing > 0 else []
    return {
        "asked": seeds,
        "passed": passed,
        "failed": failed,
        "replacements": [s for s in tried if s not in seeds],
        "verdicts": verdicts,
        "complete": len(passed) >= len(seeds),
    }


def gated_sweep(
    settings,
    out,
    n_validation: int = 20,
    per_edge: int = 5,
    max_replacements: int | None = None,
    verbose: bool = True,
    command: str | None = None,
    progress: bool = True,
) -> dict:
    """Multi-seed training under the gate: ``agents.rl.sweep.sweep`` of ``settings.seeds``
    into ``out/round_0``, every trial gated, the failures replaced by the next seeds in
    ``out/round_1``, ... (:func:`gated_seeds`). Writes and returns ``out/gate.json``:
    the seeds asked for, passed, failed and added, each verdict, and the model path of
    every seed that passed (the ones to ship). ``command`` and ``progress``: the sweeps'."""
    from agents.rl.policy import read_run_config
    from agents.rl.sweep import sweep

    if settings.n_search:
        raise ValueError("gated_sweep trains seeds: give n_search=0 (a search picks no seed)")
    out = Path(out)
    paths: dict[int, str] = {}
    rounds: list[Path] = []

    def train_many(seeds):
        folder = out / f"round_{len(rounds)}"
        rounds.append(folder)
        sweep(
            dataclasses.replace(settings, seeds=list(seeds)),
            folder,
            verbose=verbose,
            command=command,
            progress=progress,
        )
        models = {}
        for trial in sorted((folder / "trials").iterdir()):
            meta = trial / "config.json"
            if meta.is_file() and (trial / "best_model.zip").is_file():
                models[int(read_run_config(meta)["seed"])] = trial / "best_model.zip"
        paths.update({s: str(m) for s, m in models.items()})
        return models

    def gate(model):
        v = gate_policy(model, settings.env_id, n_validation, per_edge)
        if verbose:
            print(
                f"gate {model}: {'PASS' if v.passed else 'FAIL'} {v.counting}/{v.n} count, "
                f"{v.overloaded} overloaded",
                flush=True,
            )
        return v

    result = gated_seeds(settings.seeds, train_many, gate, max_replacements)
    result["models"] = {s: paths[s] for s in result["passed"]}
    result["rule"] = (
        f">= {GATE_SHARE:.0%} of {n_validation} validation + {per_edge} per train-range edge "
        "episodes count, none overloads; a failing seed is replaced by the next unused seed"
    )
    out.mkdir(parents=True, exist_ok=True)
    (out / "gate.json").write_text(json.dumps(result, indent=2, default=str))
    return result


def _models(path: Path) -> list[tuple[str, Path]]:
    """The policies under ``path``: ``(name, best_model.zip)``."""
    if path.is_file():
        return [(path.parent.name, path)]
    found = []
    if (path / "best_model.zip").is_file():
        found.append((path.name, path / "best_model.zip"))
    for sub in ("seed_*", "trials/*"):
        found += [
            (f"{path.name}/{p.parent.name}", p) for p in sorted(path.glob(f"{sub}/best_model.zip"))
        ]
    if not found:
        raise FileNotFoundError(f"no best_model.zip in {path} or its seed_*/trials/* folders")
    return found


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m agents.rl.gate", description=__doc__.split("\n")[0]
    )
    ap.add_argument("env_id")
    ap.add_argument("paths", nargs="+", type=Path, help="policies to gate")
    ap.add_argument("--n-validation", type=int, default=20)
    ap.add_argument("--per-edge", type=int, default=5)
    ap.add_argument("--out", type=Path, default=None, help="write the verdicts here (JSON)")
    a = ap.parse_args(argv)
    out, failed = {}, 0
    for path in a.paths:
        for name, model in _models(path):
            v = gate_policy(model, a.env_id, a.n_validation, a.per_edge)
            out[name] = v.as_dict()
            failed += not v.passed
            groups = ", ".join(f"{k} {g['counting']}/{g['n']}" for k, g in v.by_group.items())
            print(
                f"{name}: {'PASS' if v.passed else 'FAIL'} {v.counting}/{v.n} count "
                f"({v.counting_share:.0%}), {v.overloaded} overloaded; {groups}",
                flush=True,
            )
    if a.out is not None:
        a.out.write_text(json.dumps(out, indent=2))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
