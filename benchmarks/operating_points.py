"""Learned rows against the best tuned classical agent at operating points outside every split.

Each point takes the workpieces of ``--episodes`` ``validation`` draws from seed
``--seed0`` on (past the 100 the policies were chosen on) and changes one thing the splits
hold in a range: a fixed spindle speed, a harder material (force or torque coefficient
x 1.25) or deeper cuts (every depth scaled so the deepest is 3.5 mm, or 4 mm for end
milling, whose ``train`` reaches 3.5 mm). The benchmark's learned row (every training seed)
and the best tuned classical agent run the same cuts; printed per point: the share of cuts
each keeps, and the paired difference (reference - learned, positive: the learned row is
better) with its 95 % interval at each allowance and the verdict. ``test`` and ``ood`` are
never run, and nothing here chooses a policy.

    python benchmarks/operating_points.py --env machining_envs/EndMilling-v0 --episodes 30
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import gymnasium as gym
import numpy as np

from agents.bench.declarations import BENCHMARKS
from agents.bench.tune import agent_env_kwargs, best_tuned, tuned_factory
from agents.eval import evaluate
from agents.eval.stats import allowance_cells, allowance_sweep
from agents.rl.callbacks import evaluation_setup
from agents.rl.policy import load_policy, policy_env_kwargs, pretrained_seeds
from machining_envs.core.workpieces import DepthProfile

#: Where the learned rows are checked: (label, field, value) with field one of the
#: scenario's, "coefficient" (x value) or "deepest" (depths scaled so the deepest is value).
POINTS = {
    "machining_envs/Turning-v0": (
        ("spindle 300 rpm", "spindle_rpm", 300.0),
        ("spindle 600 rpm", "spindle_rpm", 600.0),
        ("Kf x 1.25", "coefficient", 1.25),
        ("deepest 3.5 mm", "deepest", 3.5),
    ),
    "machining_envs/EndMilling-v0": (
        ("spindle 0.75x", "spindle_scale", 0.75),
        ("spindle 1.5x", "spindle_scale", 1.5),
        ("Ks x 1.25", "coefficient", 1.25),
        ("deepest 4 mm", "deepest", 4.0),
    ),
}
_COEFFICIENT = {
    "machining_envs/Turning-v0": "force_coefficient_scale",
    "machining_envs/EndMilling-v0": "torque_coefficient_scale",
}


def _deepest(profile: DepthProfile, depth: float) -> DepthProfile:
    k = depth / max(*profile.start_depths_mm, *profile.end_depths_mm)
    return DepthProfile(
        profile.edges_mm,
        tuple(d * k for d in profile.start_depths_mm),
        tuple(d * k for d in profile.end_depths_mm),
        name=f"{profile.name}, deepest {depth:g} mm",
    )


def moved(env_id: str, scenario, field: str, value: float):
    """``scenario`` with ``field`` moved to the operating point ``value``."""
    if field == "deepest":
        return dataclasses.replace(scenario, profile=_deepest(scenario.profile, value))
    if field == "coefficient":
        key = _COEFFICIENT[env_id]
        return dataclasses.replace(scenario, **{key: min(getattr(scenario, key) * value, 2.0)})
    return dataclasses.replace(scenario, **{field: value})


def base_scenarios(env_id: str, n: int, seed0: int) -> list:
    """The scenarios of ``n`` ``validation`` draws from seed ``seed0`` on."""
    env = gym.make(env_id, scenario="validation")
    try:
        out = []
        for s in range(seed0, seed0 + n):
            env.reset(seed=s)
            out.append(env.unwrapped.scenario)
        return out
    finally:
        env.close()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--env", choices=sorted(POINTS), default="machining_envs/EndMilling-v0")
    ap.add_argument("--episodes", type=int, default=30, help="cuts per operating point")
    ap.add_argument("--seed0", type=int, default=5500, help="first validation draw")
    ap.add_argument(
        "--points", nargs="*", default=None, help="labels of the points to run, _ for spaces"
    )
    a = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    spec = next(s for s in BENCHMARKS if s.env_id == a.env)
    (learned,) = spec.learned
    best = best_tuned(a.env, among=[c.__name__ for c in spec.tuned])
    reference = next(c for c in spec.tuned if c.__name__ == best)
    _, score, failed = evaluation_setup(a.env, {})
    bases = base_scenarios(a.env, a.episodes, a.seed0)
    print(f"{a.env}: {learned} against {reference.__name__} (tuned), {a.episodes} cuts a point")
    for label, field, value in POINTS[a.env]:
        if a.points and label.replace(" ", "_") not in a.points:
            continue
        t0 = time.perf_counter()
        # each cut named by its draw, so that rows pair by cut
        cuts = [
            dataclasses.replace(moved(a.env, sc, field, value), name=str(a.seed0 + i))
            for i, sc in enumerate(bases)
        ]

        def run(factory, env_kwargs, cuts=cuts):
            rows = evaluate(
                factory, a.env, cuts, n_episodes=1, seed=a.seed0, env_kwargs=env_kwargs
            ).rows
            for row in rows:
                row["seed"] = int(row["scenario"])
            return rows

        ref_rows = run(tuned_factory(reference, a.env), agent_env_kwargs(reference))
        rows, worst = [], 1.0
        for seed, model in pretrained_seeds(learned):
            r = run(lambda env, m=model: load_policy(m, env=env), policy_env_kwargs(model))
            for row in r:
                row["policy_seed"] = seed
            worst = min(worst, float(np.mean([score.counts(x) for x in r])))
            rows += r
        diffs, verdict = allowance_sweep(ref_rows, rows, score, failed)
        cells = allowance_cells(diffs)
        ref_counts = float(np.mean([score.counts(x) for x in ref_rows]))
        counts = float(np.mean([score.counts(x) for x in rows]))
        print(
            f"{label}: reference keeps {ref_counts:.0%}, learned {counts:.0%} (worst seed "
            f"{worst:.0%}); {cells}; {verdict} ({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
