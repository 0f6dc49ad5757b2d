"""The benchmark's oracle in a process of its own gives the numbers it gives in place."""

import pytest

pytest.importorskip("casadi")


def test_the_oracle_apart_gives_the_same_rows_and_trajectory():
    from agents.bench.run import _start_apart, oracle_episodes
    from machining_envs.core.splits import split_seeds

    seed = split_seeds("test", 1)[0]
    args = ("machining_envs/Turning-v0", 1, seed, seed, {"t_s", "force_N"})
    here = oracle_episodes(*args)
    pool, future = _start_apart(oracle_episodes, *args)
    try:
        apart = future.result(timeout=600)
    finally:
        pool.shutdown()
    assert here.rows == apart.rows
    assert len(here.trajectories) == len(apart.trajectories) == 1
    for key in ("t_s", "force_N"):
        assert (here.trajectories[0][key] == apart.trajectories[0][key]).all()
