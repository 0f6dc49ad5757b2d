"""The spindle-power sensor option (machining_envs.core.sensors) of Turning-v0 and EndMilling-v0."""

import math

import gymnasium as gym
import numpy as np
import pytest

import machining_envs  # noqa: F401
from machining_envs.core.sensors import PowerSensor, PowerSensorLanes, resolve_power_sensor

TURNING = "machining_envs/Turning-v0"
MILLING = "machining_envs/EndMilling-v0"


def _actions(n, seed=0, top=-0.4):
    """A feed that ramps up to ``top`` and moves: what a controller might command (below
    the limit of the validation cuts: turning's linear map, milling's log map to 0)."""
    rng = np.random.default_rng(seed)
    a = np.clip(np.linspace(-1.0, top, n) + 0.05 * rng.standard_normal(n), -1.0, 1.0)
    return a.astype(np.float32)


@pytest.mark.parametrize(
    "bad",
    [
        {"idle_W": -1.0},
        {"time_constant_s": 11.0},
        {"quantum_W": float("nan")},
        {"power_scale_W": 0.0},
        {"limit_W": -5.0},
    ],
)
def test_settings_are_checked_by_name(bad):
    name = next(iter(bad))
    with pytest.raises(ValueError, match=name):
        PowerSensor(**bad)


def test_resolve_and_unknown_keys():
    assert resolve_power_sensor(None) is None
    assert resolve_power_sensor(False) is None
    assert resolve_power_sensor(True) == PowerSensor()
    assert resolve_power_sensor({"quantum_W": 1.0}).quantum_W == 1.0
    with pytest.raises(TypeError, match="unknown settings"):
        resolve_power_sensor({"gain": 1.0})
    with pytest.raises(ValueError, match="sample_time_s"):
        PowerSensorLanes(PowerSensor(sample_time_s=0.15), 1, 0.1)


def test_filter_is_exact_for_a_ramp():
    """The lag integrated for a linear drive power: the closed form of a ramp's response."""
    s = PowerSensor(idle_W=0.0, idle_W_per_rpm=0.0, time_constant_s=0.2, quantum_W=0.0)
    lanes = PowerSensorLanes(s, 1, 0.1)
    obs = np.zeros((1, 7))
    zero = np.zeros(1)
    lanes.start([0], obs, zero, zero, zero)
    rate = 100.0  # W/s
    for k in range(1, 31):
        lanes.step(obs, np.array([rate * 0.1 * k]), zero, zero)
        t = 0.1 * k
        tau = s.time_constant_s
        exact = rate * (t - tau * (1.0 - math.exp(-t / tau)))
        assert lanes.reading[0, 0] == pytest.approx(exact, rel=1e-12, abs=1e-9)
    # the lag once settled: rate x tau, the stated error bound
    assert rate * 3.0 - lanes.reading[0, 0] == pytest.approx(rate * 0.2, rel=1e-3)
    assert rate * 3.0 - lanes.reading[0, 0] <= s.error_bound_W(rate)


def test_off_by_default_changes_nothing():
    a = _actions(20)
    for env_id in (TURNING, MILLING):
        plain = gym.make(env_id, scenario="validation")
        off = gym.make(env_id, scenario="validation", power_sensor=None)
        o1, i1 = plain.reset(seed=2)
        o2, i2 = off.reset(seed=2)
        assert "spindle_power_measured_W" not in i1 and "spindle_power_measured_W" not in i2
        for x in a:
            o1, _, end, cut, _ = plain.step(x[None])
            o2, *_ = off.step(x[None])
            np.testing.assert_array_equal(o1, o2)
            if end or cut:
                break


@pytest.mark.parametrize("env_id", [TURNING, MILLING])
def test_recovers_cutting_power_within_the_filter_error(env_id):
    """The cutting power recovered from the reading (minus the idle losses at the observed
    spindle speed) stays within the stated filter's error of the true cutting power."""
    sensor = PowerSensor()
    env = gym.make(env_id, scenario="validation", power_sensor=sensor)
    obs, info = env.reset(seed=5)
    scale = sensor.power_scale_W
    rpm = [info["spindle_rpm"]]
    reading = [obs[0] * scale]
    cut = [0.0]
    for x in _actions(80, top=-0.4 if env_id == TURNING else 0.0):
        obs, _, terminated, truncated, info = env.step(x[None])
        rpm.append(info["spindle_rpm"])
        reading.append(obs[0] * scale)
        torque_power = (
            info["torque_Nmm"] * info["spindle_rpm"] * math.pi / 30e3
            if "torque_Nmm" in info
            else None
        )
        cut.append(info["cutting_power_W"] if env_id == TURNING else torque_power)
        assert obs[0] * scale == pytest.approx(info["spindle_power_measured_W"], rel=1e-6)
        if terminated or truncated:
            break
    rpm, reading, cut = map(np.asarray, (rpm, reading, cut))
    drive = cut + sensor.idle_power_W(rpm)
    rate = np.max(np.abs(np.diff(drive))) / 0.1  # W/s, the drive power's fastest change
    recovered = reading - sensor.idle_power_W(rpm)
    bound = sensor.error_bound_W(rate)
    err = np.abs(recovered - cut)
    assert err.max() <= bound + 1e-6 * scale  # float32 observation
    assert cut.max() > 10 * sensor.quantum_W  # the cut did load the spindle
    # the lag is a real error: the reading is not the power itself
    assert err.max() > sensor.quantum_W / 2


@pytest.mark.parametrize("env_id", [TURNING, MILLING])
def test_vector_lane_equals_single_env(env_id):
    kw = {"scenario": "validation", "power_sensor": {"sample_time_s": 0.2, "quantum_W": 2.0}}
    n = 3
    venv = gym.make_vec(env_id, num_envs=n, **kw)
    ov, iv = venv.reset(seed=10)
    actions = np.stack([_actions(40, seed=i) for i in range(n)], axis=1)
    traj_v = [ov.copy()]
    info_v = [iv["spindle_power_measured_W"].copy()]
    for a in actions:
        ov, _, _, _, iv = venv.step(a[:, None])
        traj_v.append(ov.copy())
        info_v.append(iv["spindle_power_measured_W"].copy())
    for lane in range(n):
        env = gym.make(env_id, **kw)
        o, i = env.reset(seed=10 + lane)
        np.testing.assert_array_equal(o, traj_v[0][lane])
        for t, a in enumerate(actions, start=1):
            o, _, term, trunc, i = env.step(a[lane : lane + 1])
            if term or trunc:
                break
            np.testing.assert_array_equal(o, traj_v[t][lane])
            assert i["spindle_power_measured_W"] == info_v[t][lane]


def test_reading_is_held_and_quantised():
    env = gym.make(
        TURNING, scenario="validation", power_sensor={"sample_time_s": 0.3, "quantum_W": 20.0}
    )
    obs, info = env.reset(seed=1)
    readings = [info["spindle_power_measured_W"]]
    for x in _actions(30):
        obs, *_, info = env.step(x[None])
        readings.append(info["spindle_power_measured_W"])
        assert np.isfinite(obs).all()
    r = np.asarray(readings)
    np.testing.assert_allclose(r / 20.0, np.round(r / 20.0), atol=1e-9)
    changes = np.flatnonzero(np.diff(r) != 0) + 1
    assert changes.size > 0 and np.all(changes % 3 == 0)  # read every third period only


def test_limit_as_a_power():
    env = gym.make(TURNING, scenario="validation", power_sensor={"limit_W": 1800.0})
    obs, info = env.reset(seed=0)
    assert info["power_limit_W"] == 1800.0
    assert obs[1] == pytest.approx(1.8)
    env = gym.make(TURNING, scenario="validation", power_sensor=True)
    obs, info = env.reset(seed=0)
    v = info["spindle_rpm"] * math.pi / 30 * env.unwrapped._core.diameter[0] * 5e-4
    expected = info["force_limit_N"] * v + PowerSensor().idle_power_W(info["spindle_rpm"])
    assert info["power_limit_W"] == pytest.approx(float(expected))
