"""Packaging: the wheel holds every file of the two packages, the core install (envs,
classical agents, harness) runs without the ``rl`` extra, nothing in the package metadata
pins an exact version, the license is an SPDX id."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

ROOT = Path(__file__).resolve().parents[1]
RL_ONLY = ("torch", "stable-baselines3", "tensorboard", "rich", "tqdm", "pyyaml")

#: Run in a fresh interpreter in which the rl extra's modules cannot be imported.
CORE_ONLY = """
import sys, importlib.abc
BLOCK = ("torch", "stable_baselines3", "yaml", "tqdm", "rich", "tensorboard")
class Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in BLOCK:
            raise ImportError(f"No module named {name!r}")
sys.meta_path.insert(0, Blocker())
import gymnasium as gym
env = gym.make("machining_envs:machining_envs/Turning-v0")
env.reset(seed=0)
env.step(env.action_space.sample())
venv = gym.make_vec("machining_envs/Turning-v0", num_envs=2)
venv.reset(seed=0)
from agents import VariableGainPI
from agents.eval import evaluate
ev = evaluate(VariableGainPI.from_env, "machining_envs/Turning-v0", ["paper_405"], n_episodes=2)
assert len(ev.rows) == 2
from agents.bench.benchmark import _installed
assert not _installed("stable_baselines3")
from agents.bench.cli import main
try:
    main(["--version"])
except SystemExit as exit_:
    assert exit_.code == 0
print("core ok")
"""


def _project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def test_core_dependencies_leave_training_to_the_rl_extra():
    core = " ".join(_project()["dependencies"]).lower()
    for name in RL_ONLY:
        assert name not in core, name
    rl = " ".join(_project()["optional-dependencies"]["rl"]).lower()
    for name in ("torch", "stable-baselines3"):
        assert name in rl


def test_no_exact_pins_in_the_metadata_and_an_spdx_license():
    project = _project()
    every = list(project["dependencies"])
    for extra in project["optional-dependencies"].values():
        every += extra
    assert not [d for d in every if "==" in d]
    assert project["license"] == "MIT"
    # The CPU build of torch is pinned only for `make`, through the constraints file.
    assert "torch==2.13.0" in (ROOT / "constraints.txt").read_text()
    assert "-c constraints.txt" in (ROOT / "Makefile").read_text()


def test_envs_agents_and_harness_run_without_the_rl_extra():
    out = subprocess.run(
        [sys.executable, "-c", CORE_ONLY], capture_output=True, text=True, cwd=ROOT
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert "core ok" in out.stdout


def test_importing_the_package_loads_no_physics():
    """``import machining_envs`` registers the ids and loads nothing heavy (numba, scipy,
    matplotlib, torch, the env modules): the rest comes with ``gym.make`` or the first
    use of an exported name. Its time is measured by ``benchmarks/import_time.py``."""
    code = """
import sys
import machining_envs, gymnasium as gym
heavy = [m for m in sys.modules if m.split(".")[0] in ("numba", "scipy", "matplotlib", "torch")
         or m.endswith((".env", ".feed_env", ".plant"))]
assert not heavy, heavy
assert gym.spec("machining_envs/Turning-v0").vector_entry_point
from machining_envs import TurningEnv, Path, DepthProfile
assert TurningEnv.__name__ == "TurningEnv" and "numba" in sys.modules
assert "TurningEnv" in dir(machining_envs)
try:
    machining_envs.Nope
except AttributeError as exc:
    assert "Nope" in str(exc)
else:
    raise AssertionError("no AttributeError")
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]


def test_importing_agents_loads_no_controller():
    """``import agents`` loads none of its controllers (nor numba, scipy, torch): each
    class comes on first use, and one process's class loads no other process's modules
    (the contouring servo's scipy.signal took a second)."""
    code = """
import sys
import agents
heavy = [m for m in sys.modules if m.split(".")[0] in ("numba", "scipy", "matplotlib", "torch")
         or m.startswith("agents.")]
assert not heavy, heavy
from agents import VariableGainPI, Agent
assert issubclass(VariableGainPI, Agent) and "VariableGainPI" in dir(agents)
assert "scipy.signal" not in sys.modules and "agents.contouring" not in sys.modules
assert sorted(agents.__all__) == sorted(
    ["Agent", "ConstantFeed", "FixedGainPI", "VariableGainPI", "FixedGainIntegral",
     "IntegralACC", "MillingConstantFeed", "ConstantOverride", "LookAheadFeed", "HInf2DOF",
     "PIPosition", "NoControl", "PD", "PeckDrilling", "SlidingMode", "AdaptiveFeedControl",
     "DelayAwarePI", "ContourAFC", "TorquePeck", "VoltagePeck", "VoltageTorquePeck"])
for name in agents.__all__:
    getattr(agents, name)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]


def _package_files(root: Path) -> set[str]:
    """Every file of the two packages under ``root`` (their paths from ``root``), without
    Python's and numba's caches."""
    return {
        p.relative_to(root).as_posix()
        for pkg in ("machining_envs", "agents")
        for p in (root / pkg).rglob("*")
        if p.is_file() and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".nbi", ".nbc")
    }


def test_the_wheel_holds_every_file_of_the_packages(tmp_path):
    """What ``pip install machining-envs`` gets: the wheel built from a copy of the sources
    holds every file of ``machining_envs`` and ``agents`` (the tuned settings, the configs,
    every pretrained seed), so the benchmark of an installed package is the README's."""
    src = tmp_path / "src"
    shutil.copytree(
        ROOT,
        src,
        ignore=shutil.ignore_patterns(
            ".git",
            ".venv",
            "results",
            "runs",
            "build",
            "dist",
            "*.egg-info",
            "__pycache__",
            "notebooks",
            "tests",
            "docs",
            "benchmarks",
        ),
    )
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            str(src),
            "--no-deps",
            "--no-build-isolation",
            "--quiet",
            "-w",
            str(tmp_path / "wheel"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    (wheel,) = (tmp_path / "wheel").glob("machining_envs-*.whl")
    with zipfile.ZipFile(wheel) as z:
        shipped = {n for n in z.namelist() if not n.split("/")[0].endswith(".dist-info")}
    expected = _package_files(src)
    assert "agents/bench/tuned.json" in expected  # the check sees the data files
    assert not expected - shipped, sorted(expected - shipped)[:20]
    assert not shipped - expected, sorted(shipped - expected)[:20]


@pytest.mark.slow
def test_the_wheel_installs_in_a_clean_venv_and_runs_the_quickstart():
    """``.ci/wheel`` (``make wheel``, a step of ``.ci/run``): ``python -m build`` makes the
    wheel, a clean venv installs it with its dependencies (a few minutes from a package
    cache), and the README's first example runs there, outside the source tree."""
    pytest.importorskip("build")
    out = subprocess.run(
        [str(ROOT / ".ci" / "wheel")],
        capture_output=True,
        text=True,
        timeout=1800,
        env={**os.environ, "PYTHON": sys.executable},
    )
    assert out.returncode == 0, (out.stdout[-2000:], out.stderr[-2000:])
    assert "wheel ok: machining_envs-" in out.stdout
    assert "cut in" in out.stdout  # the example's own output
