"""The one-line notice while numba compiles the package's kernels (``core.notice``)."""

import subprocess
import sys

COMPILES = """
import numba
import machining_envs.core.compiled.kernels  # installs the listener, as every env's import does

def compiled(module):
    scope = {"__name__": module}
    exec("def f(x):\\n    return x + 1\\n", scope)
    return numba.njit(scope["f"])

compiled("somebody_else")(1)                # another package's: nothing
compiled("machining_envs.turning.one")(1)   # the line
compiled("machining_envs.turning.two")(1)   # no second line
compiled("machining_envs.milling.one")(1)
"""

FIRST_STEP = """
import gymnasium as gym
import machining_envs
env = gym.make("machining_envs/Turning-v0")
env.reset(seed=0)
env.step(env.action_space.sample())
"""


def _stderr(code: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    return [line for line in out.stderr.splitlines() if line.startswith("machining_envs:")]


def test_one_line_when_the_package_first_compiles():
    lines = _stderr(COMPILES)
    assert len(lines) == 1, lines
    assert "compiling the numba kernels" in lines[0] and "machining-bench warmup" in lines[0]


def test_nothing_once_the_kernels_are_cached():
    _stderr(FIRST_STEP)  # compiles and caches them where a fresh checkout has none
    assert _stderr(FIRST_STEP) == []
