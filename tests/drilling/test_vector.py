"""MicroDrilling-v0's batched physics and native vector env beyond the conventions every
vector env keeps (``tests/envs/test_vector.py``): every way an episode ends, in both control
modes, lane for lane the single env; the plant is a lane of the batch; the compiled kernels
reproduce numpy's arithmetic; the noise is drawn in the documented blocks."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from machining_envs import DrillingScenario
from machining_envs.drilling.plant import (
    _P,
    DrillingLanes,
    DrillingParams,
    DrillingPlant,
    _engagement,
    _sum,
)
from tests.helpers import DRILLING

SHORT = DrillingScenario("short", 0.5, aspect_ratio=1.0)  # 0.5 mm deep: about 160 steps


def _same(a, b) -> bool:
    if isinstance(a, float) and np.isnan(a):
        return isinstance(b, (float, np.floating)) and np.isnan(b)
    if isinstance(a, np.ndarray):  # control="voltage_feed"'s command pair
        return np.array_equal(a, b)
    return a == b


def _compare_lanes(kwargs: dict, actions, n_steps: int, n: int = 4, seed: int = 21) -> dict:
    """Step the vector env and ``n`` single envs with the same actions; every lane must be
    its single env bit for bit (observations, rewards, flags, every info value, across
    autoresets). Returns how the single envs' episodes ended."""
    venv = gym.make_vec(DRILLING, num_envs=n, autoreset_mode="SAME_STEP", **kwargs)
    singles = [gym.make(DRILLING, **kwargs) for _ in range(n)]
    obs, info = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        o, inf = env.reset(seed=seed + i)
        np.testing.assert_array_equal(obs[i], o)
        assert all(info["_" + k][i] and _same(info[k][i], v) for k, v in inf.items())
    rng = np.random.default_rng(1)
    ends = {"finished": 0, "breakage": 0, "truncated": 0}
    clipped = out_of_hole = 0
    for step in range(n_steps):
        a = actions(rng, n)
        obs, reward, terminated, truncated, info = venv.step(a)
        for i, env in enumerate(singles):
            o, r, te, tr, inf = env.step(a[i])
            assert (r, te, tr) == (reward[i], terminated[i], truncated[i]), (step, i)
            clipped += inf["action_clipped"]
            out_of_hole += inf["position_mm"] < 0.0 < inf["depth_mm"]
            if te or tr:
                ends["finished"] += inf["finished"]
                ends["breakage"] += inf["breakage"]
                ends["truncated"] += tr
                np.testing.assert_array_equal(info["final_obs"][i], o)
                final = info["final_info"]
                for k, v in inf.items():
                    assert final["_" + k][i] and _same(final[k][i], v), (step, i, k)
                o, inf = env.reset()
            np.testing.assert_array_equal(obs[i], o, err_msg=f"step {step}, lane {i}")
            for k, v in inf.items():
                assert info["_" + k][i] and _same(info[k][i], v), (step, i, k)
    ends["clipped"] = clipped
    ends["out_of_hole"] = out_of_hole
    return ends


def test_lanes_finish_holes_like_the_single_env_with_clipped_actions_and_progress_reward():
    ends = _compare_lanes(
        {"scenario": SHORT, "reward": {"progress": 0.5}},
        lambda rng, n: rng.uniform(-1.3, 1.3, (n, 1)).astype(np.float32),
        n_steps=700,
    )
    assert ends["finished"] >= 10 and ends["clipped"] > 100


def test_lanes_break_drills_like_the_single_env_on_a_starved_spindle():
    ends = _compare_lanes(
        {"scenario": "train"},
        lambda rng, n: rng.uniform(-1.0, -0.5, (n, 1)).astype(np.float32),
        n_steps=500,
    )
    assert ends["breakage"] >= 10


def test_lanes_of_the_feed_control_retract_break_and_run_out_of_time_like_the_single_env():
    """``control="feed"`` (the peck-drilling machine): feeds around the nominal one, fast
    plunges and retracts that clear the chips."""

    def feeds(rng, n):
        a = rng.normal(0.32 / 3.0, 0.1, (n, 1))
        jump = rng.random((n, 1)) < 0.05
        return np.where(jump, rng.uniform(-1.2, 1.2, (n, 1)), a).astype(np.float32)

    ends = _compare_lanes(
        {"control": "feed", "scenario": "ood", "max_episode_time_s": 1.0}, feeds, n_steps=800
    )
    assert ends["truncated"] >= 5 and ends["breakage"] >= 5 and ends["out_of_hole"] > 10


def test_lanes_of_the_voltage_and_feed_control_peck_and_clip_like_the_single_env():
    """``control="voltage_feed"``: voltages over the whole range beside feeds around a fast
    one, with retracts out of the hole; both components clipped at times."""

    def pairs(rng, n):
        volts = rng.uniform(-1.3, 1.3, (n, 1))
        feeds = rng.normal(0.6 / 3.0, 0.1, (n, 1))
        jump = rng.random((n, 1)) < 0.05
        feeds = np.where(jump, rng.uniform(-1.2, 1.2, (n, 1)), feeds)
        return np.hstack([volts, feeds]).astype(np.float32)

    ends = _compare_lanes(
        {"control": "voltage_feed", "scenario": "ood", "max_episode_time_s": 1.0},
        pairs,
        n_steps=800,
    )
    assert ends["truncated"] >= 3 and ends["out_of_hole"] >= 3 and ends["clipped"] > 100
    assert ends["breakage"] + ends["finished"] >= 3


def test_the_plant_is_a_lane_of_the_batch():
    """``DrillingPlant`` (one hole) and lane ``k`` of a ``DrillingLanes`` holding other drills
    and holes in its other lanes give the same numbers to the last bit."""
    p = DrillingParams()
    holes = [
        (p.replace(shear_stress_MPa=2500.0, chip_friction=0.4), 0.5, 3.0),
        (p.replace(chip_fluctuation=0.5, torque_noise_Nmm=0.03), 0.8, 6.0),
        (p, 0.6, 1.0),
    ]
    lanes = DrillingLanes(p, len(holes))
    plants = []
    for k, (q, d, depth) in enumerate(holes):
        lanes.start(k, q, d, depth)
        plants.append(DrillingPlant(q, d, depth))
    rng = np.random.default_rng(0)
    for _ in range(400):
        inputs = np.column_stack(
            [rng.uniform(-1.0, 11.0, 3), rng.uniform(-0.5, 1.0, 3), rng.standard_normal((3, 5))]
        )
        lanes.step(inputs)
        for k, plant in enumerate(plants):
            s = plant.step(inputs[k, 0], inputs[k, 1], tuple(inputs[k, 2:]))
            row = lanes.out[k]
            assert (s.torque_Nmm, s.measured_torque_Nmm, s.speed_hz) == tuple(row[[0, 3, 6]])
            assert (s.depth_mm, s.packed_mm, s.chip_ratio) == tuple(row[[12, 13, 14]])
            np.testing.assert_array_equal(plant._lanes.state[0], lanes.state[k])


def test_a_lane_must_share_the_batchs_valve_spindle_and_timing():
    lanes = DrillingLanes(DrillingParams(), 2)
    lanes.start(1, DrillingParams(shear_stress_MPa=2000.0, speed_noise_hz=1.0), 0.6, 5.0)
    with pytest.raises(ValueError, match="valve_damping"):
        lanes.start(0, DrillingParams(valve_damping=0.5), 0.6, 5.0)
    with pytest.raises(ValueError, match="substeps"):
        lanes.start(0, DrillingParams(substeps=4), 0.6, 5.0)
    with pytest.raises(ValueError, match="target_depth_mm"):
        lanes.start(0, DrillingParams(), 0.6, 0.0)
    with pytest.raises(ValueError, match="diameter_mm"):
        lanes.start(0, DrillingParams(), 1.5, 5.0)
    with pytest.raises(ValueError, match=r"shape \(2, 7\)"):
        lanes.step(np.zeros((3, 7)))


@pytest.mark.parametrize("n", [1, 5, 8, 23, 24, 64, 65, 128])
def test_compiled_sums_are_numpys(n):
    """The cutting model sums its elements in compiled code exactly as ``ndarray.sum``."""
    rng = np.random.default_rng(n)
    for _ in range(200):
        x = rng.standard_normal(n) * 10.0 ** rng.uniform(-3.0, 3.0, n)
        assert _sum(x) == x.sum()


def test_engagement_lookup_is_numpys_interp():
    """The kernel's engagement tables read exactly as ``np.interp`` reads them, at random
    depths, at the table's points and next to them, outside the tables and at NaN."""
    rng = np.random.default_rng(0)
    for web in (0.05, 0.15, 0.4):
        p = DrillingParams(web_ratio=web)
        for d in (0.3, 0.55, 1.0):
            c = p.coefficients(d)
            lanes = DrillingLanes(p, 1)
            lanes.start(0, p, d, 5.0)
            xp = c.engage_depth_mm
            full = lanes.par[0, _P.FULL]
            xs = np.concatenate(
                [rng.uniform(-0.01, 1.01 * xp[-1], 300), xp, np.nextafter(xp, 0.0), [0.0]]
            )
            for x in xs.tolist():
                got = _engagement(lanes.eng, 0, full, x)
                if x >= full:
                    want = (1.0, 1.0)
                elif x <= 0.0:
                    want = (0.0, 0.0)
                else:
                    want = (np.interp(x, xp, c.engage_torque), np.interp(x, xp, c.engage_thrust))
                assert got == want, x
            assert all(np.isnan(_engagement(lanes.eng, 0, full, float("nan"))))


def test_noise_is_drawn_from_np_random_five_normals_a_step():
    """The plant's normals come from ``np_random``, five a step, as the steps need them
    (after the scenario, ``core.compiled.normals``): after 300 steps of a named hole (whose reset
    draws nothing) the generator stands where 1500 normals from the seed leave it, and an
    unseeded reset goes on from there."""
    env = gym.make(DRILLING, scenario="paper_0.8")
    env.reset(seed=3)
    for _ in range(300):
        _, _, terminated, truncated, _ = env.step(np.array([0.0], dtype=np.float32))
        assert not (terminated or truncated)
    want = np.random.default_rng(3)
    want.standard_normal(300 * 5)
    mine = env.unwrapped.np_random
    assert mine.bit_generator.state == want.bit_generator.state
    env.reset()
    assert env.unwrapped._core.rngs.generators[0] is mine
    env.step(np.array([0.0], dtype=np.float32))
    want.standard_normal(5)
    assert mine.bit_generator.state == want.bit_generator.state


def test_vector_env_takes_the_single_envs_keywords():
    venv = gym.make_vec(DRILLING, num_envs=2, control="feed", torque_noise_Nmm=0.02)
    assert type(venv).__name__ == "MicroDrillingVectorEnv"
    assert venv.control == "feed" and venv.params.torque_noise_Nmm == 0.02
    _, info = venv.reset(seed=0, options={"scenario": SHORT})
    assert list(info["scenario"]) == ["short", "short"]
    with pytest.raises(TypeError, match="torque_noise"):
        gym.make_vec(DRILLING, num_envs=2, torque_noise_nmm=0.02)
    with pytest.raises(ValueError, match="control"):
        gym.make_vec(DRILLING, num_envs=2, control="pressure")
