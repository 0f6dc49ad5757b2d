"""drilling_metrics on hand-made trajectories, and on a recorded one."""

import math

import gymnasium as gym
import numpy as np
import pytest

from agents.drilling import NoControl
from agents.eval import evaluate, rollout
from machining_envs.drilling.metrics import drilling_mask, drilling_metrics


def _traj():
    # reset, 2 entry samples, 4 engaged cutting samples, a retract (out of the hole), 2 more.
    return {
        "t_s": np.arange(10) * 0.01,
        "cutting": np.array([0, 1, 1, 1, 1, 1, 1, 0, 1, 1], dtype=bool),
        "engagement": np.array([0, 0.3, 0.9, 1, 1, 1, 1, 0, 1, 1.0]),
        "torque_Nmm": np.array([0, 0.1, 0.3, 0.4, 0.5, 0.6, 0.5, 0.0, 0.4, 0.4]),
        "thrust_N": np.array([0, 1, 1, 2, 2, 2, 2, 0, 2, 2.0]),
        "torque_limit_Nmm": np.full(10, 0.44),
        # The env's cost: cutting with the torque above the limit.
        "cost": np.array([0, 0, 0, 0, 1, 1, 1, 0, 0, 0.0]),
        "spindle_hz": np.array([545, 540, 538, 550, 560, 570, 565, 545, 552, 551.0]),
        "peak_torque_Nmm": np.array([0, 0.1, 0.3, 0.45, 0.55, 0.65, 0.55, 0.0, 0.42, 0.41]),
        "breakage_torque_Nmm": np.full(10, 1.3),
        "position_mm": np.array([0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, -0.1, 0.61, 0.7]),
        "depth_mm": np.array([0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.6, 0.61, 0.7]),
        "finished": np.array([0] * 9 + [1], dtype=bool),
        "drilling_time_s": np.array([math.nan] * 9 + [0.085]),
        "breakage": np.zeros(10, dtype=bool),
        "diverged": np.zeros(10, dtype=bool),
    }


def test_metrics_by_hand():
    tr = _traj()
    assert drilling_mask(tr).tolist() == [False, False, True, True, True, True, False, True, True]
    m = drilling_metrics(tr)
    engaged = np.array([0.4, 0.5, 0.6, 0.5, 0.4, 0.4])
    assert m["torque_mean_Nmm"] == pytest.approx(engaged.mean())
    assert m["torque_std_Nmm"] == pytest.approx(engaged.std())
    assert m["torque_mean_rel"] == pytest.approx(engaged.mean() / 0.44)
    assert m["thrust_mean_N"] == 2.0 and m["thrust_std_N"] == 0.0
    assert m["time_over_limit"] == pytest.approx(3 / 6)  # 0.5, 0.6, 0.5 above 0.44
    assert m["spindle_min_hz"] == 550.0 and m["spindle_range_hz"] == 20.0
    assert m["peak_torque_Nmm"] == 0.65 and m["peak_torque_rel"] == pytest.approx(0.5)
    assert math.isnan(m["score_bound"])  # the hand-made record has none
    assert m["drilling_time_s"] == 0.085 and m["finished"] == 1.0
    assert m["n_retracts"] == 1.0 and m["breakage"] == 0.0 and m["n_steps"] == 9.0


def test_unfinished_episode_and_no_engaged_sample():
    tr = _traj()
    tr["finished"][:] = False
    tr["engagement"][:] = 0.5
    m = drilling_metrics(tr)
    assert m["drilling_time_s"] == pytest.approx(0.09) and m["finished"] == 0.0
    assert math.isnan(m["torque_mean_Nmm"]) and math.isnan(m["spindle_range_hz"])


def test_metrics_of_a_recorded_run_through_the_harness():
    env = gym.make("machining_envs/MicroDrilling-v0", scenario="paper_0.6")
    tr = rollout(NoControl.from_env(env), env, seed=0)
    m = drilling_metrics(tr)
    assert m["finished"] == 1.0 and m["drilling_time_s"] == pytest.approx(6.0 / 0.32)
    assert m["torque_mean_rel"] > 1.2  # chips raise the torque above the chip-free reference
    assert 0 < m["spindle_range_hz"] < 100.0  # the load slows the free spindle a little
    ev = evaluate(
        NoControl.from_env,
        "machining_envs/MicroDrilling-v0",
        ["paper_0.6"],
        metrics_fn=drilling_metrics,
    )
    assert ev.rows[0]["torque_mean_Nmm"] == m["torque_mean_Nmm"]
