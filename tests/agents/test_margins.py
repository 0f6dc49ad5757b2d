"""Loop margins from a numerically linearised agent equal the analytic design's."""

import math

import control
import gymnasium as gym
import numpy as np
import pytest

from agents.eval.margins import (
    OperatingPoint,
    controller_ss,
    loop_margins,
    margins_of,
    plant_tf,
    settle,
)
from agents.turning import FixedGainPI
from machining_envs.turning import TurningEnv
from tests.helpers import TURNING

_I = TurningEnv.OBS_INDEX


def _close(a, b, rel):
    return (math.isinf(a) and math.isinf(b)) or a == pytest.approx(b, rel=rel)


@pytest.mark.parametrize("rpm, depth, kh", [(405.0, 2.0, 0.006), (245.0, 1.5, 0.02)])
def test_the_linearised_fixed_pi_has_the_analytic_designs_margins(rpm, depth, kh):
    point = OperatingPoint(rpm, depth)
    pi = FixedGainPI.from_env(gym.make(TURNING), kh=kh, kgh=1.9, setpoint=0.7)
    env, obs, state, action = settle(pi, point)
    plant = plant_tf(env, point, action)
    numeric = -controller_ss(pi, obs, state, action, 0.1) * plant
    # eq. (12)-(13) in observation and action units: U = U' + Kh (Kgh E - E'), E = Ke fs (r - y)
    p = env.params
    k = 2.0 / p.command_max * kh * p.sensor_gain * p.force_scale_N
    analytic = k * control.tf([1.9, -1.0], [1.0, -1.0], 0.1) * plant
    got, want = margins_of(numeric), margins_of(analytic)
    assert _close(got.gain_margin_db, want.gain_margin_db, 0.01)
    assert _close(got.phase_margin_deg, want.phase_margin_deg, 0.01)
    assert _close(got.sensitivity_peak, want.sensitivity_peak, 0.01)
    assert loop_margins(pi, point).force_N == pytest.approx(0.7 * 1000.0, rel=1e-3)


class _LinearPolicy:
    """A memoryless policy linear in the observation's force, its history and the previous
    action: u = c0 y + c1 y1 + c2 y2 + c3 y3 + d u_prev + bias."""

    c = np.array([-0.5, 0.2, 0.1, 0.05])
    d = 0.9

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        o = np.asarray(obs, dtype=np.float64)
        y = np.array([o[_I["measured"]], *o[_I["history"] : _I["history"] + 3]])
        u = self.c @ (y - 0.7) + self.d * o[_I["prev_action"]] - 0.074  # steady at -0.74
        return np.array([np.clip(u, -1.0, 1.0)], dtype=np.float32), state


def test_a_memoryless_policy_is_read_with_the_observations_memory():
    policy = _LinearPolicy()
    obs = np.array([0.7, 1.0, -0.74, 0.405, 0.7, 0.7, 0.7])
    ctrl = controller_ss(policy, obs, None, np.array([-0.74]), 0.1)
    # u_k = d u_{k-1} + sum_i c_i y_{k-i}  ->  C(z) = sum c_i z^-i / (1 - d z^-1)
    want = control.tf(list(policy.c), [1.0, -policy.d, 0.0, 0.0], 0.1)
    w = np.logspace(-2, np.log10(math.pi / 0.1) - 1e-3, 30)
    got_resp = control.frequency_response(ctrl, w)
    want_resp = control.frequency_response(want, w)
    np.testing.assert_allclose(
        np.asarray(got_resp.complex).ravel(), np.asarray(want_resp.complex).ravel(), rtol=1e-3
    )


def test_an_agent_that_does_not_settle_is_reported_not_linearised():
    class Oscillating:
        name = "bang-bang"

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            k = 0 if state is None else state
            return np.array([0.5 if k % 2 else -0.5], dtype=np.float32), k + 1

    with pytest.raises(ValueError, match="has not settled"):
        settle(Oscillating(), OperatingPoint(405.0, 2.0, settle_steps=60))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"settle_steps": 0}, "settle_steps must be an integer >= 1, got 0"),
        ({"settle_steps": 2.5}, "settle_steps must be an integer >= 1"),  # range(2.5)
        ({"depth_mm": -1.0}, r"depth_mm must be in \(0, 1000\]"),
        ({"spindle_rpm": float("nan")}, "spindle_rpm must be in"),
    ],
)
def test_a_bad_operating_point_is_refused_when_made_naming_the_field(kwargs, message):
    # settle_steps=0 failed deep in the linearisation ("zero-size array to reduction").
    with pytest.raises(ValueError, match=message):
        OperatingPoint(**{"spindle_rpm": 405.0, "depth_mm": 1.0, **kwargs})
