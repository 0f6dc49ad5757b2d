"""Import time of ``machining_envs`` and ``agents`` against ``gymnasium`` (which they need
anyway), each in a fresh interpreter, median of several runs; and what ``gym.make`` and the
first agent class then cost.

    python benchmarks/import_time.py [--runs 7]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys

CASES = {
    "import gymnasium": "import gymnasium",
    "import machining_envs": "import machining_envs",
    "import agents": "import agents",
    "+ from agents import VariableGainPI": "from agents import VariableGainPI",
    "+ gym.make(Turning-v0)": "import gymnasium as g, machining_envs; "
    "g.make('machining_envs/Turning-v0')",
}


def seconds(code: str) -> float:
    """Wall time of ``code`` in a fresh interpreter, less the bare interpreter's start."""
    timer = f"import time; t = time.perf_counter(); {code}; print(time.perf_counter() - t)"
    out = subprocess.run([sys.executable, "-c", timer], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=7)
    args = ap.parse_args(argv)
    times = {name: [] for name in CASES}
    for _ in range(args.runs):
        for name, code in CASES.items():
            times[name].append(seconds(code))
    med = {name: statistics.median(t) for name, t in times.items()}
    peer = med["import gymnasium"]
    print(f"median of {args.runs} fresh interpreters (python {sys.version.split()[0]})")
    for name, t in med.items():
        print(f"{name:28s} {t:7.3f} s  {t / peer:5.2f}x import gymnasium")


if __name__ == "__main__":
    main()
