"""The README's quickstart and its "In your own project" example run as written, and its
first lines are the two commands."""

import re
from pathlib import Path

import gymnasium as gym
import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_opens_with_the_two_commands():
    text = README.read_text()
    first_block = re.search(r"```bash\n(.*?)```", text, re.S).group(1)
    assert first_block.splitlines()[0].startswith("make demo")
    assert first_block.splitlines()[1].startswith("make test")


def test_quickstart_runs(capsys):
    text = README.read_text()
    quick = text.split("## Quickstart", 1)[1]
    code = re.search(r"```python\n(.*?)```", quick, re.S).group(1)
    exec(compile(code, "README quickstart", "exec"), {})
    out = capsys.readouterr().out
    assert "cut in" in out and "| adaptive PI K=0.5 | validation | 3 |" in out


def test_the_own_project_example_runs():
    """Every line of the example a user copies into a project of their own (it builds
    SB3 vectorised envs, so it needs the rl extra)."""
    pytest.importorskip("stable_baselines3")
    section = README.read_text().split("## In your own project", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    scope: dict = {}
    try:
        exec(compile(code, "README: In your own project", "exec"), scope)
    finally:  # the example's own id leaves the registry as it found it
        gym.registry.pop("mylab/MyLathe-v0", None)
    assert scope["vec"].num_envs == 1024 and scope["vec64"].num_envs == 64
    assert scope["obs"].shape == (1024, 7)  # as its comment says
    assert scope["fast_venv"].num_envs == 1024
    for name in ("env", "vec", "vec64", "venv", "sb3_venv", "fast_venv"):
        scope[name].close()


def test_ci_runs_the_readme_test_command():
    ci = (README.parent / ".ci" / "run").read_text()
    assert "make test" in ci
