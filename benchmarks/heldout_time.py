"""Wall time of the held-out benchmark of every paper classical agent: 100 ``test`` episodes per
env and agent, run batched on the native vector envs (each agent's episodes as the lanes
of one vector env), as the benchmark runs them.

    python benchmarks/heldout_time.py [--episodes 100]
"""

from __future__ import annotations

import argparse
import time

from agents.bench.declarations import BENCHMARKS
from agents.eval import evaluate
from machining_envs.core.splits import split_seeds


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--episodes", type=int, default=100)
    args = ap.parse_args(argv)
    total = 0.0
    print(f"{'env':34s} {'agents':>6s} {'episodes':>8s} {'time (s)':>9s}")
    for spec in BENCHMARKS:
        agents = list(spec.paper_agents)
        t0 = time.perf_counter()
        for factory in agents:
            ev = evaluate(
                factory,
                spec.env_id,
                ["test"],
                n_episodes=args.episodes,
                seed=split_seeds("test", args.episodes)[0],
            )
            assert len(ev.rows) == args.episodes
        dt = time.perf_counter() - t0
        total += dt
        print(f"{spec.env_id:34s} {len(agents):6d} {len(agents) * args.episodes:8d} {dt:9.1f}")
    print(f"{'all':34s} {'':6s} {'':8s} {total:9.1f}")


if __name__ == "__main__":
    main()
