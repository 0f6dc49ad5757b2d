"""Loop margins of any turning controller, learned or classical, read as a control engineer
reads a design.

At an operating point (a constant-depth cut at one spindle speed, no sensor noise) the agent
runs closed loop until it settles. Around that steady state it is linearised numerically
(central differences of ``predict``) as a discrete system from the measured force to the
action: its own state (a classical agent's integrator and estimates) plus the observation's
memory (the three past forces and the previous action, which the env feeds back), so a
memoryless SB3 policy and a stateful controller are read the same way. The plant is the
paper's model at that point: the servo and cutting lag of eq. (11), discretised as eq. (14),
times the tangent process gain ``dF/dU = p F / U`` (eq. 8's feed exponent ``p`` times the
secant gain ``Kp`` of eq. 11). Closing ``L(z) = -C(z) P(z)`` gives python-control's gain and
phase margins and the sensitivity peak ``Ms = max |1 / (1 + L)|``, and the delay margin
``phase margin / crossover frequency``: the extra loop delay, in seconds, that would take
the phase margin to zero. On a machine whose control delays the command by ``d`` periods
(``loop_margins(..., delay_steps=d)``) the plant carries ``z^-d`` and the agent settles
with that delay.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from agents.base import check_positive
from machining_envs.core.checks import is_integer
from machining_envs.turning import TurningEnv
from machining_envs.turning.scenarios import DepthProfile, TurningScenario

__all__ = [
    "OperatingPoint",
    "Margins",
    "settle",
    "controller_ss",
    "plant_tf",
    "loop_margins",
    "delay_margin",
]

_I = TurningEnv.OBS_INDEX
_HISTORY = 3  # past measured forces in the observation


@dataclass(frozen=True)
class OperatingPoint:
    """A steady cut: spindle speed, depth and force limit (no noise, nominal truth)."""

    spindle_rpm: float
    depth_mm: float
    force_limit_N: float = 1000.0
    settle_steps: int = 300

    def __post_init__(self) -> None:
        steps = self.settle_steps
        if not (is_integer(steps) and steps >= 1):
            raise ValueError(f"settle_steps must be an integer >= 1, got {steps!r}")
        check_positive("depth_mm", self.depth_mm, 1e3)
        self.scenario()  # the scenario's own checks: speed, depth and limit in its ranges

    def scenario(self) -> TurningScenario:
        profile = DepthProfile.steps((self.depth_mm,), 2000.0, name=f"{self.depth_mm} mm")
        return TurningScenario(
            f"{self.spindle_rpm:.0f} rpm, {self.depth_mm:g} mm",
            profile,
            self.spindle_rpm,
            self.force_limit_N,
            noise_scale=0.0,
        )


@dataclass(frozen=True)
class Margins:
    gain_margin_db: float
    phase_margin_deg: float
    sensitivity_peak: float
    force_N: float
    """The steady force the agent holds at the point."""
    delay_margin_s: float = math.nan
    """The extra loop delay the loop tolerates, s (phase margin / crossover frequency;
    inf without a gain crossover)."""


def settle(
    agent, point: OperatingPoint, env_id: str = "machining_envs/Turning-v0", delay_steps: int = 0
):
    """Run ``agent`` at ``point`` until it settles; ``(env, obs, state, action)`` at the end.
    ``ValueError`` if the episode ends first or the force has not settled (within 0.1 %).
    ``delay_steps``: control periods the CNC delays the command by (0: none)."""
    act = {"delay_steps": delay_steps} if delay_steps else None
    env = gym.make(env_id, max_episode_time_s=1e4, actuation=act).unwrapped
    obs, _ = env.reset(seed=0, options={"scenario": point.scenario()})
    state, forces = None, []
    for _ in range(point.settle_steps):
        action, state = agent.predict(obs, state)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            raise ValueError(f"{getattr(agent, 'name', agent)}: the cut ended before settling")
        forces.append(info["force_N"])
    tail = np.asarray(forces[-20:])
    if np.ptp(tail) > 1e-3 * max(abs(tail.mean()), 1.0):
        raise ValueError(
            f"{getattr(agent, 'name', agent)} has not settled at {point.scenario().name} "
            f"(force {tail.min():.1f}-{tail.max():.1f} N over the last 20 steps)"
        )
    return env, obs, state, agent.predict(obs, state)[0]


def controller_ss(agent, obs0: np.ndarray, state0, action0, dt: float, eps: float = 1e-2):
    """The agent linearised at ``(obs0, state0)`` as a ``control.StateSpace`` from the measured
    force (observation units) to the action. The state is the agent's own state followed by the
    observation's memory ``[y_{k-1}, y_{k-2}, y_{k-3}, u_{k-1}]``, held at its steady values.
    ``eps``: the relative step of the central differences; every agent returns float32
    actions, so the step must be far above float32's resolution (1e-2 of the value: exact
    for the linear laws, second-order accurate for the rest)."""
    import control

    x0 = np.zeros(0) if state0 is None else np.asarray(state0, dtype=np.float64).reshape(-1)
    nx = x0.size
    y0 = float(obs0[_I["measured"]])
    u0 = float(np.asarray(action0).reshape(-1)[0])
    z0 = np.concatenate([x0, [y0] * _HISTORY, [u0]])

    def step(z: np.ndarray, y: float) -> tuple[np.ndarray, float]:
        obs = np.array(obs0, dtype=np.float64)
        obs[_I["measured"]] = y
        obs[_I["history"] : _I["history"] + _HISTORY] = z[nx : nx + _HISTORY]
        obs[_I["prev_action"]] = z[-1]
        st = None if state0 is None else z[:nx].reshape(np.shape(state0))
        a, st_new = agent.predict(obs, st)
        u = float(np.asarray(a, dtype=np.float64).reshape(-1)[0])
        x_new = np.zeros(0) if st_new is None else np.asarray(st_new, np.float64).reshape(-1)
        return np.concatenate([x_new, [y], z[nx : nx + _HISTORY - 1], [u]]), u

    def central(j: int) -> tuple[np.ndarray, float]:
        """d(next state, action) / d(variable j); j = n is the input. The step grows until
        the float32 action moves by far more than its resolution (or 10^4-fold)."""
        value = y0 if j == n else z0[j]
        h = eps * max(1.0, abs(value))
        for _ in range(5):
            zp, zm, yp, ym = z0.copy(), z0.copy(), y0, y0
            if j == n:
                yp, ym = y0 + h, y0 - h
            else:
                zp[j] += h
                zm[j] -= h
            (fp, up), (fm, um) = step(zp, yp), step(zm, ym)
            if abs(up - um) >= 1e-4:
                break
            h *= 10.0
        return (fp - fm) / (2 * h), (up - um) / (2 * h)

    n = z0.size
    A, B = np.zeros((n, n)), np.zeros((n, 1))
    C, D = np.zeros((1, n)), np.zeros((1, 1))
    for j in range(n):
        A[:, j], C[0, j] = central(j)
    B[:, 0], D[0, 0] = central(n)
    return control.ss(A, B, C, D, dt)


def plant_tf(env, point: OperatingPoint, action0):
    """The plant from the action to the measured force (observation units) at the steady
    command ``action0``: eq. (14) times the tangent process gain (see the module doc)."""
    import control

    p = env.params
    u0 = (float(np.asarray(action0).reshape(-1)[0]) + 1.0) * p.command_max / 2.0
    feed = p.servo_gain * p.gear_ratio * (60.0 / point.spindle_rpm) * u0
    secant = p.process_gain(point.spindle_rpm, point.depth_mm, feed)  # force counts / count
    tangent_N = p.feed_exponent * secant / p.sensor_gain  # N per command count
    gain = tangent_N * (p.command_max / 2.0) / p.force_scale_N  # obs units per action unit
    num, den = p.discrete_open_loop(point.spindle_rpm)
    return control.tf(gain * np.asarray(num), np.asarray(den), p.sample_time_s)


def loop_margins(agent, point: OperatingPoint, delay_steps: int = 0) -> Margins:
    """Gain, phase and delay margins and sensitivity peak of ``agent`` at ``point``, on a
    machine that delays the command by ``delay_steps`` control periods."""
    import control

    if not (is_integer(delay_steps) and 0 <= delay_steps <= 50):
        raise ValueError(f"delay_steps must be an integer in [0, 50], got {delay_steps!r}")
    env, obs, state, action = settle(agent, point, delay_steps=delay_steps)
    ts = env.params.sample_time_s
    ctrl = controller_ss(agent, obs, state, action, ts)
    plant = plant_tf(env, point, action)
    if delay_steps:
        plant = plant * control.tf([1.0], [1.0] + [0.0] * delay_steps, ts)
    loop = -ctrl * plant
    return margins_of(loop, float(obs[_I["measured"]]) * env.params.force_scale_N, control)


def margins_of(loop, force_N: float = math.nan, control=None) -> Margins:
    """Margins of a discrete open loop ``L`` (negative feedback)."""
    if control is None:
        import control
    import warnings

    with warnings.catch_warnings():  # python-control warns where a margin is infinite
        warnings.simplefilter("ignore")
        gm, pm, sm, _, wgc, _ = control.stability_margins(loop)
    gm_db = 20.0 * math.log10(gm) if gm and math.isfinite(gm) and gm > 0 else math.inf
    dm = delay_margin(pm, wgc)
    return Margins(gm_db, float(pm), 1.0 / sm if sm > 0 else math.inf, force_N, dm)


def delay_margin(phase_margin_deg: float, crossover_rad_s: float) -> float:
    """The delay margin, s, from python-control's phase margin and gain-crossover
    frequency (``stability_margins``): inf where the loop gain never crosses 1, 0 for a
    loop already unstable at its crossover (negative phase margin)."""
    pm, w = float(phase_margin_deg), float(crossover_rad_s)
    if not (math.isfinite(pm) and math.isfinite(w) and w > 0):
        return math.inf
    return max(0.0, math.radians(pm) / w)
