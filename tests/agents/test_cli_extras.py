"""Every ``machining-bench`` command on the core install (``pip install -e .``, no extras):
it works, or it exits 2 with one line naming the extra it needs, before doing any work.

The extras' modules are hidden by an import blocker (a meta-path finder that a
``sitecustomize`` on ``PYTHONPATH`` installs), in a subprocess per command."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from agents.bench.cli import COMMANDS, EXTRAS

ROOT = Path(__file__).resolve().parents[2]
MODEL = "agents/rl/pretrained/turning_ppo/best_model.zip"
TURNING = "machining_envs/Turning-v0"
#: Every module an extra brings (the rl-zoo3 and dev extras' too).
HIDDEN = sorted({m for mods in EXTRAS.values() for m in mods} | {"rl_zoo3", "tensorboard"})

SITECUSTOMIZE = f"""
import importlib.abc, sys

HIDDEN = {HIDDEN!r}


class Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in HIDDEN:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)


sys.meta_path.insert(0, Blocker())
"""


@pytest.fixture(scope="module")
def core_only(tmp_path_factory):
    """The environment of a process in which no extra is installed."""
    site = tmp_path_factory.mktemp("core_only")
    (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
    path = os.pathsep.join([str(site), str(ROOT), os.environ.get("PYTHONPATH", "")])
    return {**os.environ, "PYTHONPATH": path, "MPLBACKEND": "Agg"}


def _run(env, *argv, timeout=600):
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-m", "agents.bench.cli", *argv],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=timeout,
    )
    return out, time.perf_counter() - t0


def test_the_blocker_hides_the_extras(core_only):
    code = "import importlib.util as u; print(u.find_spec('yaml'))"
    out = subprocess.run([sys.executable, "-c", "import yaml"], env=core_only, capture_output=True)
    assert out.returncode == 1 and b"No module named 'yaml'" in out.stderr
    assert subprocess.run([sys.executable, "-c", code], env=core_only).returncode == 1


#: Each command that needs an extra, with arguments that would run it, and the extras the
#: line must name. The out paths are checked not to exist afterwards.
NEEDS = {
    "benchmark": (["benchmark", "--quick", "--out", "{tmp}/bench"], "bench"),
    "tune": (["tune", "--trials", "1", "--episodes", "1", "--out", "{tmp}/t.json"], "bench"),
    "train": (["train", "--env", TURNING, "--out", "{tmp}/run", "--timesteps", "64"], "rl"),
    "sweep": (["sweep", "--env", TURNING, "--out", "{tmp}/sweep"], "rl,ray"),
    "evaluate": (["evaluate", "--model", MODEL, "--env", TURNING, "--episodes", "1"], "rl"),
    "export --onnx": (["export", "--onnx", "--model", MODEL, "--out", "{tmp}/p.onnx"], "rl,onnx"),
    "export --zoo": (["export", "--zoo", "--model", MODEL, "--out", "{tmp}/zoo"], "rl"),
    "convert-stats": (["convert-stats", "{tmp}/x_vecnormalize.pkl"], "rl"),
    "synthesize": (["synthesize", "--out", "{tmp}/designs.json"], "rl"),
}


@pytest.mark.parametrize("name", list(NEEDS))
def test_a_command_without_its_extra_says_which_in_one_line(name, core_only, tmp_path):
    argv, extras = NEEDS[name]
    (tmp_path / "x_vecnormalize.pkl").write_bytes(b"")
    out, seconds = _run(core_only, *[a.format(tmp=tmp_path) for a in argv])
    assert out.returncode == 2, (out.stdout[-500:], out.stderr[-2000:])
    assert out.stdout == ""
    line = out.stderr
    assert line.count("\n") == 1 and line.startswith(f"machining-bench {name.split()[0]}: needs ")
    assert f"pip install 'machining-envs[{extras}]'" in line
    for extra in extras.split(","):
        assert f"({extra})" in line
    assert seconds < 60  # before any work (the interpreter and the imports only)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x_vecnormalize.pkl"]


def test_every_command_is_covered():
    covered = {n.split()[0] for n in NEEDS} | {"reproduce", "warmup"}
    assert covered == set(COMMANDS)


def test_reproduce_runs_without_extras(core_only, tmp_path):
    """It runs to its end (exit 1 says that a row does not show the paper's behaviour)."""
    out, _ = _run(core_only, "reproduce", "drilling", "--out", str(tmp_path))
    assert out.returncode in (0, 1), out.stderr[-2000:]
    assert "checks show the paper's behaviour" in out.stdout
    assert (tmp_path / "reproduce_drilling.png").stat().st_size > 0


def test_warmup_runs_without_extras(core_only):
    out, _ = _run(core_only, "warmup", "--env", TURNING)
    assert out.returncode == 0, out.stderr[-2000:]
    assert f"compiled {TURNING}" in out.stderr  # no tqdm: a line an env instead of a bar


def test_help_and_the_checks_load_no_agent():
    """``--help``, ``--version`` and a command's checks run before the agents (and the
    envs' kernels, which some of them compile on import) load."""
    import subprocess

    code = """
import sys
from agents.bench.cli import PROCESS_NAMES, build_parser, main
build_parser()
assert main(["train", "--env", "machining_envs/Turning-v0", "--out", "/sys/x"]) == 2
loaded = [m for m in sys.modules if m.startswith("agents.") and m != "agents.bench.cli"
          and m != "agents.bench" or m.startswith(("numba", "torch"))]
assert not loaded, loaded
from agents.bench.declarations import PROCESSES
assert PROCESS_NAMES == tuple(p.name for p in PROCESSES)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]


def test_version_and_help_run_without_extras(core_only):
    out, _ = _run(core_only, "--version")
    assert out.returncode == 0 and out.stdout.startswith("machining-bench ")
    for name in COMMANDS:
        out, _ = _run(core_only, name, "--help")
        assert out.returncode == 0 and "usage: machining-bench" in out.stdout, name
