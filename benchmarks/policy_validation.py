"""Learned policies against the best tuned classical agent on ``validation``, with the gate.

For each policy folder (a shipped ``agents/rl/pretrained/<name>`` with ``seed_<k>/``
subfolders, or a folder of ``train`` run folders ``seed_<k>/``), every seed's policy runs
the same ``--episodes`` ``validation`` episodes (from ``--first-episode`` on) as the
reference (the best tuned classical agent of ``agents/bench/tuned.json`` by its validation
score, unless ``--reference``), and the seed gate (``agents.rl.gate``) runs on each seed unless ``--no-gate``. Printed and
written (``--out``, JSON): per seed the gate verdict, the counting share, the mean
charged time and the seed's own paired difference and verdict against the reference; per
policy (the seeds pooled, an episode's value the mean over its seeds, as
the benchmark pools them) the counting share, the mean time and the paired difference
against the reference (reference - policy, positive: the policy is better) with its 95 %
bootstrap interval at each allowance of ``machining_envs.core.score.ALLOWANCES`` and the
verdict. ``--tuned`` adds tuned classical agents (class names, run with their tuned
settings and their ``ENV_KWARGS``) as rows compared with the reference the same way.
``test`` and ``ood`` are never run.

    python benchmarks/policy_validation.py --env machining_envs/Turning-v0 \\
        agents/rl/pretrained/turning_ppo_residual runs/lag/lagafc --out val.json
    python benchmarks/policy_validation.py runs/pen runs/lag --baseline runs/pen
    python benchmarks/policy_validation.py --env machining_envs/MicroDrilling-v0 \
        --tuned VoltagePeck VoltageTorquePeck --reference NoControl --episodes 100
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from agents.bench.tune import TUNED_FILE, agent_env_kwargs, best_tuned, tuned_factory
from agents.eval.harness import evaluate_validation
from agents.eval.stats import allowance_cells, allowance_sweep, seed_count_shares
from agents.rl.callbacks import evaluation_setup
from agents.rl.gate import gate_policy
from agents.rl.policy import load_policy, policy_env_kwargs, pretrained_seeds
from machining_envs.core.score import ALLOWANCES
from machining_envs.core.splits import MAX_SPLIT_EPISODES


def _agent_class(name: str):
    import agents

    cls = getattr(agents, name, None)
    if cls is None:
        raise ValueError(f"--reference: no agent class {name!r} in agents")
    return cls


def _by_allowance(diffs: list[dict]) -> dict:
    """The paired differences of ``allowance_sweep`` keyed by their allowance, for the JSON."""
    return {str(al): d for al, d in zip(ALLOWANCES, diffs, strict=True)}


def seed_models(folder: Path) -> list[tuple[int, Path]]:
    """``(seed, best_model.zip)`` of every policy in ``folder``: its own ``best_model.zip``
    (a shipped folder's seed 0) and every ``seed_<k>/best_model.zip``."""
    return pretrained_seeds(folder.name, folder.parent)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--env", default="machining_envs/Turning-v0")
    ap.add_argument("folders", nargs="*", type=Path)
    ap.add_argument(
        "--tuned", nargs="*", default=[], help="tuned agent classes compared as rows too"
    )
    ap.add_argument("--episodes", type=int, default=50, help="validation episodes")
    ap.add_argument(
        "--first-episode",
        type=int,
        default=0,
        help="the first validation episode (default 0): check on episodes kept apart",
    )
    ap.add_argument("--reference", default=None, help="tuned agent class (default: the best)")
    ap.add_argument("--no-gate", action="store_true")
    ap.add_argument(
        "--baseline",
        type=Path,
        default=None,
        help="one of the folders: every other is also compared with it, paired",
    )
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    if not a.folders and not a.tuned:
        ap.error("give policy folders or --tuned agent classes")

    import torch

    torch.set_num_threads(1)
    metrics_fn, score, failed = evaluation_setup(a.env, {})
    if not 0 <= a.first_episode <= MAX_SPLIT_EPISODES - a.episodes:
        ap.error(
            f"--first-episode must be in [0, {MAX_SPLIT_EPISODES} - --episodes], "
            f"got {a.first_episode}"
        )

    def run(agent, env_kwargs):
        return evaluate_validation(
            agent,
            a.env,
            a.episodes,
            a.first_episode,
            env_kwargs=env_kwargs,
            metrics_fn=metrics_fn,
        ).rows

    ref_name = a.reference or best_tuned(a.env)
    t0 = time.perf_counter()
    ref_cls = _agent_class(ref_name)
    ref_rows = run(tuned_factory(ref_cls, a.env), agent_env_kwargs(ref_cls))
    ref_counts = float(np.mean([score.counts(r) for r in ref_rows]))
    ref_mean = float(np.mean([score.charged(r, failed) for r in ref_rows]))
    print(
        f"reference {ref_name}: counts {ref_counts:.0%}, mean {ref_mean:.2f} s "
        f"({time.perf_counter() - t0:.0f} s)",
        flush=True,
    )
    report_tuned = {}
    for name in a.tuned:
        t1 = time.perf_counter()
        cls = _agent_class(name)
        factory = tuned_factory(cls, a.env)
        if factory is None:
            raise SystemExit(f"--tuned: {TUNED_FILE} holds no {name} entry for {a.env}")
        rows = run(factory, agent_env_kwargs(cls))
        diffs, verdict = allowance_sweep(ref_rows, rows, score, failed)
        report_tuned[name] = {
            "counts": float(np.mean([score.counts(x) for x in rows])),
            "mean": float(np.mean([score.charged(x, failed) for x in rows])),
            "diffs": _by_allowance(diffs),
            "verdict": verdict,
            "wall_s": round(time.perf_counter() - t1, 1),
        }
        cells = allowance_cells(diffs)
        e = report_tuned[name]
        print(
            f"{name} (tuned): counts {e['counts']:.0%}, mean {e['mean']:.2f} s; "
            f"vs {ref_name} {cells}; {verdict} ({e['wall_s']} s)",
            flush=True,
        )
    pooled_rows = {}
    report = {
        "env": a.env,
        "episodes": a.episodes,
        "first_episode": a.first_episode,
        "reference": ref_name,
        "reference_counts": ref_counts,
        "reference_mean": ref_mean,
        "tuned": report_tuned,
        "policies": {},
    }
    for folder in a.folders:
        rows, seeds = [], {}
        for seed, model in seed_models(folder):
            t1 = time.perf_counter()
            # on the env as trained (control="feed" for the peck policy), checked at load
            r = run(lambda env, m=model: load_policy(m, env=env), policy_env_kwargs(model))
            for row in r:
                row["policy_seed"] = seed
            rows += r
            seed_diffs, seed_verdict = allowance_sweep(ref_rows, r, score, failed)
            entry = {
                "counts": float(np.mean([score.counts(x) for x in r])),
                "mean": float(np.mean([score.charged(x, failed) for x in r])),
                "diffs": _by_allowance(seed_diffs),
                "verdict": seed_verdict,
            }
            if not a.no_gate:
                g = gate_policy(model, a.env)
                entry["gate"] = {
                    "passed": g.passed,
                    "counting": g.counting,
                    "n": g.n,
                    "overloaded": g.overloaded,
                    "by_group": g.by_group,
                }
            entry["wall_s"] = round(time.perf_counter() - t1, 1)
            seeds[seed] = entry
            gate = entry.get("gate")
            gtxt = (
                ""
                if gate is None
                else (
                    f"; gate {'PASS' if gate['passed'] else 'FAIL'} {gate['counting']}/{gate['n']},"
                    f" {gate['overloaded']} overloaded"
                )
            )
            print(
                f"{folder} seed {seed}: counts {entry['counts']:.0%}, mean "
                f"{entry['mean']:.2f} s; alone {allowance_cells(seed_diffs)}; {seed_verdict}"
                f"{gtxt} ({entry['wall_s']} s)",
                flush=True,
            )
        diffs, verdict = allowance_sweep(ref_rows, rows, score, failed)
        pooled = {
            "counts": float(np.mean([score.counts(x) for x in rows])),
            "mean": float(np.mean([score.charged(x, failed) for x in rows])),
            "seed_counts_by_allowance": {
                str(al): seed_count_shares(rows, score, al) for al in ALLOWANCES
            },
            "diffs": _by_allowance(diffs),
            "verdict": verdict,
            "seeds": seeds,
        }
        report["policies"][str(folder)] = pooled
        pooled_rows[folder] = rows
        cells = allowance_cells(diffs)
        print(
            f"{folder}: counts {pooled['counts']:.0%}, mean {pooled['mean']:.2f} s; "
            f"vs {ref_name} {cells}; {verdict}",
            flush=True,
        )
    if a.baseline is not None:
        if a.baseline not in pooled_rows:
            raise SystemExit(f"--baseline {a.baseline} must be one of the folders")
        for folder, rows in pooled_rows.items():
            if folder == a.baseline:
                continue
            diffs, verdict = allowance_sweep(pooled_rows[a.baseline], rows, score, failed)
            report["policies"][str(folder)]["vs_baseline"] = {
                "baseline": str(a.baseline),
                "verdict": verdict,
                "diffs": _by_allowance(diffs),
            }
            cells = allowance_cells(diffs)
            print(f"{folder} vs {a.baseline}: {cells}; {verdict}", flush=True)
    if a.out is not None:
        a.out.write_text(json.dumps(report, indent=2, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
