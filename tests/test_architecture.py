"""The import contracts of ``pyproject.toml`` (import-linter) hold, and would catch a cycle."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(cwd)}
    return subprocess.run(
        [str(LINT), "--no-cache"], cwd=cwd, env=env, capture_output=True, text=True, timeout=120
    )


def test_import_contracts_hold():
    res = _lint(ROOT)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "0 broken" in res.stdout


def test_a_deliberate_cycle_breaks_the_contracts(tmp_path):
    """A copy of the packages where the shared core imports a process (and so the process,
    which imports the core, closes a cycle): the linter must fail and name the cycle."""
    for pkg in ("machining_envs", "agents"):
        shutil.copytree(ROOT / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("pretrained"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    lti = tmp_path / "machining_envs" / "core" / "lti.py"
    lti.write_text(lti.read_text() + "\nimport machining_envs.turning.env  # noqa: E402,F401\n")
    res = _lint(tmp_path)
    assert res.returncode != 0
    assert "No import cycles anywhere BROKEN" in res.stdout
    assert "machining_envs.core.lti -> machining_envs.turning.env" in res.stdout


def test_an_agent_importing_the_benchmark_breaks_the_layers(tmp_path):
    """Controllers sit below the tooling: a controller module importing the benchmark fails."""
    for pkg in ("machining_envs", "agents"):
        shutil.copytree(ROOT / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("pretrained"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    mod = tmp_path / "agents" / "turning.py"
    mod.write_text(mod.read_text() + "\nimport agents.bench.benchmark  # noqa: E402,F401\n")
    res = _lint(tmp_path)
    assert res.returncode != 0
    assert "agents: bench -> rl -> eval -> controllers -> base BROKEN" in res.stdout


def test_an_agent_importing_a_compiled_or_lanes_module_breaks_the_contracts(tmp_path):
    """Controllers read a process's model through its public ``plant``: a controller module
    importing the compiled wing, a process's engine (``lanes``) or a private module fails,
    each named."""
    for pkg in ("machining_envs", "agents"):
        shutil.copytree(ROOT / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("pretrained"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    mod = tmp_path / "agents" / "turning.py"
    mod.write_text(
        mod.read_text()
        + "\nimport machining_envs.core.compiled.kernels  # noqa: E402,F401"
        + "\nimport machining_envs.milling.lanes  # noqa: E402,F401"
        + "\nimport machining_envs.contouring._exact  # noqa: E402,F401\n"
    )
    res = _lint(tmp_path)
    assert res.returncode != 0
    name = "The agents read the envs' public faces: no compiled, lanes or private module BROKEN"
    assert name in res.stdout.replace("\n", " ").replace("  ", " ")
    for imported in (
        "machining_envs.core.compiled.kernels",
        "machining_envs.milling.lanes",
        "machining_envs.contouring._exact",
    ):
        assert f"agents.turning -> {imported}" in res.stdout


def test_the_compiled_wing_importing_a_process_breaks_the_contracts(tmp_path):
    """The numba runtime is below every process: a compiled module importing one fails."""
    for pkg in ("machining_envs", "agents"):
        shutil.copytree(ROOT / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("pretrained"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    mod = tmp_path / "machining_envs" / "core" / "compiled" / "normals.py"
    mod.write_text(mod.read_text() + "\nimport machining_envs.turning.plant  # noqa: E402,F401\n")
    res = _lint(tmp_path)
    assert res.returncode != 0
    assert "The compiled wing imports no process and nothing of the envs BROKEN" in res.stdout
    assert "machining_envs.core.compiled.normals -> machining_envs.turning.plant" in res.stdout
