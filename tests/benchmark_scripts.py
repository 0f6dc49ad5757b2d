"""Run a script of ``benchmarks/`` as a user would, for the scripts' smoke tests."""

import importlib.util
import subprocess
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def run_benchmark(command: str) -> str:
    """What ``python benchmarks/<command>`` prints (``command``: the script's name and its
    arguments, split at spaces); it must exit with 0."""
    name, *args = command.split()
    return subprocess.run(
        [sys.executable, str(BENCHMARKS / name), *args], capture_output=True, text=True, check=True
    ).stdout


def run_benchmark_json(command: str, out: Path) -> tuple[str, object]:
    """What ``python benchmarks/<command> --out <out>`` prints, and the JSON it writes to
    ``out``."""
    import json

    printed = run_benchmark(f"{command} --out {out}")
    return printed, json.loads(out.read_text())


def load_benchmark(name: str):
    """The script ``benchmarks/<name>.py`` imported as a module, for tests of its parts."""
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
