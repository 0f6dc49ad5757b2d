"""The compile-time script runs, and what it shows holds: a process that finds the kernels
cached on disk does not compile them again."""

import re

from tests.benchmark_scripts import run_benchmark


def test_compile_time_script_finds_the_kernels_cached_the_second_time():
    """Contouring-v0 (the env that compiles fastest): its first steps from an empty numba
    cache take seconds; from the cache that run left, a fraction of that (a kernel that
    cannot be cached, or whose cache is not found, would compile again each time)."""
    out = run_benchmark("compile_time.py --env machining_envs/Contouring-v0")
    line = next(row for row in out.splitlines() if row.startswith("machining_envs/Contouring-v0"))
    single, vector, cold, cached, ratio = (float(x) for x in re.findall(r"\d+\.\d+", line))
    assert abs(single + vector - cold) <= 0.11, line
    assert cold > 1.0 and cached < cold / 3, line
