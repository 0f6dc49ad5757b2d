"""The Turning-v0 ceiling script: its two measures, and a tiny end-to-end run."""

import numpy as np
import pytest

from tests.benchmark_scripts import load_benchmark, run_benchmark


@pytest.fixture(scope="module")
def ceiling():
    return load_benchmark("turning_ceiling")


def test_steps_over_the_limit_are_placed_against_segment_changes(ceiling):
    traj = {"cost": [0, 1, 0, 0, 0, 0, 0, 1, 1], "segment": [0, 0, 0, 1, 1, 1, 1, 1, 1]}
    # the change is at step 3: step 1 is 2 away, steps 7 and 8 are 4 and 5 away
    assert ceiling.steps_near_segment_change(traj, 2) == (1, 3)
    assert ceiling.steps_near_segment_change(traj, 5) == (3, 3)
    assert ceiling.steps_near_segment_change({"cost": [1, 1], "segment": [0, 0]}, 9) == (0, 2)
    assert ceiling.steps_near_segment_change({"cost": [0, 0], "segment": [0, 1]}, 9) == (0, 0)


def test_the_after_the_fact_choice_takes_each_episodes_best_reference(ceiling):
    charged = {0.8: np.array([[10.0, 9.0], [200.0, 7.0]]), 0.9: np.array([[8.0, 9.5], [6.0, 7.0]])}
    gain = ceiling.hindsight_gain(charged, 0.8)
    assert gain.tolist() == [[2.0, 0.0], [194.0, 0.0]]
    assert (ceiling.hindsight_gain(charged, 0.9) >= 0).all()


def test_turning_ceiling_script_runs_on_validation():
    printed = run_benchmark("turning_ceiling.py --episodes 2 --refs 0.7 0.9")
    assert "(tuned)" in printed and "reference 0.700" in printed and "reference 0.900" in printed
    assert "steps over the limit lie within 1.5 s" in printed
    assert "after the fact, paired gain over the tuned AFC" in printed


def test_the_overload_brake_acts_only_on_a_sample_over_the_limit(ceiling):
    import gymnasium as gym

    import machining_envs  # noqa: F401 - registers the envs
    from agents import AdaptiveFeedControl

    env = gym.make("machining_envs/Turning-v0")
    obs, _ = env.reset(seed=0)
    afc = AdaptiveFeedControl.from_env(env, reference=0.8, fmax=2.9)
    brake = ceiling.OverloadBrake.from_env(env, reference=0.8, fmax=2.9, cut=0.5, hold=0.25)
    st0 = afc.initial_state(1, obs[None].astype(np.float64))
    cmap = afc.command_map
    for load, over in ((0.6, False), (1.3, True)):  # shares of the observed limit
        o = obs[None].astype(np.float64).copy()
        o[:, 0] = load * o[:, 1]
        o[:, 4:] = o[:, 0:1]
        sa, sb = st0.copy(), st0.copy()
        sa[:, ceiling._OVR] = sb[:, ceiling._OVR] = 1.5
        ua = cmap.action_to_command(afc._act(o, sa)[:, 0])
        ub = cmap.action_to_command(brake._act(o, sb)[:, 0])
        ovr_a, ovr_b = sa[0, ceiling._OVR], sb[0, ceiling._OVR]
        if over:
            assert ovr_b == pytest.approx(0.5 * ovr_a) and ub == pytest.approx(0.25 * ua)
        else:
            assert ovr_b == ovr_a and ub == pytest.approx(ua)
    env.close()


def test_turning_ceiling_script_measures_the_brake_and_refuses_bad_settings():
    printed = run_benchmark("turning_ceiling.py --episodes 2 --refs 0.9 --brake --brake-refs 0.85")
    assert "overload brake (cut 0.7, hold 0.6) at reference 0.850" in printed
    assert "against the tuned AFC 0.5%:" in printed
    with pytest.raises(SystemExit, match="--brake-cut must be in"):
        load_benchmark("turning_ceiling").main(["--brake-cut", "1.5"])
