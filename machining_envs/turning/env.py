"""``machining_envs/Turning-v0``: hold the cutting force at a reference by adjusting the feed."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from machining_envs.core.checks import PY_NUMBER_TYPES, check_range
from machining_envs.core.env import (
    ActionMap,
    EpisodeLog,
    check_action,
    check_episode_time,
    check_render_mode,
    check_reward_weights,
    check_scenario_spec,
    present_frame,
    ready_to_render,
    record_step,
    render_signals,
    resolve_params,
    resolve_reward,
    scenario_option,
)
from machining_envs.turning.metrics import TURNING_TASK
from machining_envs.turning.plant import SPINDLE_RPM_RANGE, TurningParams, TurningPlant
from machining_envs.turning.scenarios import TURNING_SCENARIOS, TurningScenario, turning_scenario

__all__ = ["TurningEnv", "TurningReward"]

_HISTORY = 3
_FORCE_OBS = (-1.0, 10.0)
#: The signals render() draws: name -> the info key each is read from.
_LOG_FIELDS = {
    "t": "t_s",
    "force": "force_N",
    "measured": "measured",
    "feed": "feed_mm_per_rev",
    "depth": "depth_mm",
}


@dataclass(frozen=True)
class TurningReward:
    r"""Weights of the turning reward (see :class:`TurningEnv`, section Rewards).

    .. math::

        r = -w_t \frac{|F - F_r|}{F_r} - w_o \max\!\left(0, \frac{F}{F_r} - \theta_o\right)
            + w_p \frac{\Delta x}{T_s V_{max}} - w_b [\text{breakage}]
    """

    tracking: float = 1.0
    """w_t, weight of the normalised force error."""
    overforce: float = 4.0
    """w_o, extra weight on force above ``overforce_threshold`` x reference."""
    overforce_threshold: float = 1.1
    """theta_o, the 1.1 x reference above which force counts as a constraint violation."""
    progress: float = 0.0
    """w_p, weight of the distance fed this step as a share of the most the servo can feed."""
    breakage: float = 50.0
    """w_b, one-off penalty when the tool breaks."""

    def __post_init__(self) -> None:
        check_reward_weights(self, allow_bool=True)


class TurningEnv(gym.Env):
    """Constant cutting-force regulation in turning by feed (Noh, Kim & Kim 1992).

    ## Description
    A lathe turns an SM45C bar with a carbide tool. The depth of cut changes along the bar
    (pre-machined steps, tapers); the controller must keep the main cutting force at the
    reference (1 kN in the paper) by commanding the feed servo, as fast as the force allows.
    The plant is ``machining_envs.turning.plant``: a second-order feed servo (eq. 1), a gear
    train (eq. 2), the feed per revolution as the exact moving integral of the feed velocity
    over the last spindle revolution (eq. 4), the force law ``F = Kf f^p a`` (eq. 8) and a
    dynamometer with a 10 Hz low-pass filter and noise (eq. 10), sampled every 0.1 s.
    Because ``Kp`` of eq. (11) grows with depth and falls with spindle speed, a fixed-gain
    controller tuned for one cut oscillates or crawls in another.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``, mapped affinely onto the servo command ``U`` in
    ``[0, command_max]`` DAC counts (``action_to_command`` / ``command_to_action``). A finite
    action outside the box is clipped and counted in ``info["n_action_clipped"]``; NaN or inf
    raises ``ValueError``.

    ## Observation Space
    ``Box(float32, (7,))``: only what the machine measures, normalised to order one.

    | index | observation | unit | range |
    |---|---|---|---|
    | 0 | measured force (filtered, noisy) / ``force_scale_N`` | - | [-1, 10] |
    | 1 | reference force / ``force_scale_N`` | - | [0, 10] |
    | 2 | previous action (the command now applied) | - | [-1, 1] |
    | 3 | spindle speed / 1000 rpm | - | [0, 3] |
    | 4-6 | measured force one, two, three samples ago / ``force_scale_N`` | - | [-1, 10] |

    The depth of cut, the feed and the true process constants are hidden (they are in
    ``info``).

    ## Rewards
    With ``F`` the cutting force at the sample instant, ``Fr`` the reference, ``dx`` the
    distance fed in the step and ``Vmax`` the servo's top feed velocity (weights in
    :class:`TurningReward`, configurable with ``reward=``):
    ``r = -1.0 |F - Fr|/Fr - 4.0 max(0, F/Fr - 1.1) + 0.0 dx/(Ts Vmax) - 50 [breakage]``.
    Holding the force at the reference is also the fastest safe cut, so the default reward
    needs no progress term. Benchmark metrics are computed from ``info``, not from rewards.

    ## Starting State
    Tool at the start of the workpiece, feed at rest, force zero; the scenario (workpiece,
    spindle speed, hidden Kf and p, noise) is drawn from ``self.np_random``.

    ## Episode End
    Terminated when the workpiece is cut to its end (``info["finished"]``), when the force
    passes ``breakage_force_N`` at any 2 ms sub-step (``info["breakage"]``), or when a state
    goes non-finite (``info["diverged"]``). Truncated at ``max_episode_time_s``.

    ## Arguments
    ``gym.make("machining_envs/Turning-v0", scenario="train", render_mode=None,
    params=None, spindle_rpm=None, reward=None, max_episode_time_s=200.0, **overrides)``:
    ``scenario`` is the default for resets without one (a name of ``TURNING_SCENARIOS`` or a
    ``TurningScenario``); ``params`` a ``TurningParams`` (nominal: what controllers are
    designed from); ``overrides`` change single fields of it (``sensor_gain=15``);
    ``spindle_rpm`` fixes the spindle speed of every scenario. Unknown keywords raise
    ``TypeError``; out-of-range values raise ``ValueError`` naming the parameter.

    Reset options: ``{"scenario": name_or_TurningScenario}``.

    ## info
    ``t_s``, ``command`` (U, counts), ``action_clipped``, ``n_action_clipped``,
    ``breakage``, ``diverged``, ``finished``, ``force_N`` (true force), ``force_ref_N``,
    ``measured`` (force the controller saw, N), ``measured_counts``, ``peak_force_N``,
    ``feed_mm_per_rev``, ``feed_velocity_mm_s``, ``depth_mm``, ``spindle_rpm``,
    ``position_mm``, ``segment`` (index of the workpiece segment being cut),
    ``workpiece_length_mm``, ``scenario``, and ``machining_time_s`` once the cut is finished.

    ## Version History
    * v0: first version.

    ## Example
    >>> import gymnasium as gym
    >>> import machining_envs
    >>> env = gym.make("machining_envs/Turning-v0", scenario="paper_405")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["depth_mm"], info["spindle_rpm"]
    ((7,), 1.0, 405.0)
    >>> obs, reward, terminated, truncated, info = env.step(np.array([0.0], dtype=np.float32))
    >>> round(info["command"]), info["t_s"]
    (2048, 0.1)
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}
    #: Episode metrics and primary score of this env (``machining_envs.core.score.Task``).
    task = TURNING_TASK
    #: Positions of the observation's fields, for controllers that read them by name.
    OBS_INDEX = {"measured": 0, "reference": 1, "prev_action": 2, "spindle": 3, "history": 4}

    def __init__(
        self,
        scenario: str | TurningScenario = "train",
        render_mode: str | None = None,
        params: TurningParams | None = None,
        spindle_rpm: float | None = None,
        reward: TurningReward | dict | None = None,
        max_episode_time_s: float = 200.0,
        **overrides,
    ):
        self.params = resolve_params(
            type(self).__name__, params, TurningParams, TurningParams.noh_kim_kim_1992, overrides
        )
        if spindle_rpm is not None:
            spindle_rpm = check_range(
                "spindle_rpm", spindle_rpm, *SPINDLE_RPM_RANGE, types=PY_NUMBER_TYPES
            )
        self.spindle_rpm_override = spindle_rpm
        self.reward_weights = resolve_reward(reward, TurningReward)
        self.max_episode_time_s = check_episode_time(max_episode_time_s)
        check_scenario_spec(scenario, TurningScenario, TURNING_SCENARIOS)
        self.default_scenario = scenario
        self.render_mode = check_render_mode(render_mode, self.metadata["render_modes"])

        self.command_map = ActionMap(0.0, self.params.command_max)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        f_lo, f_hi = _FORCE_OBS
        low = np.array([f_lo, 0.0, -1.0, 0.0] + [f_lo] * _HISTORY, dtype=np.float32)
        high = np.array(
            [f_hi, 10.0, 1.0, SPINDLE_RPM_RANGE[1] / 1000.0] + [f_hi] * _HISTORY, dtype=np.float32
        )
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.scenario: TurningScenario | None = None
        self.plant: TurningPlant | None = None

    # ---- the command map, for classical agents -----------------------------------------
    def action_to_command(self, action):
        """Servo command U (counts) for an action in [-1, 1]."""
        return self.command_map.action_to_command(action)

    def command_to_action(self, command):
        """Action in [-1, 1] for a servo command U (counts)."""
        return self.command_map.command_to_action(command)

    # ---- gymnasium API -------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        spec = scenario_option(options, self.default_scenario)
        sc = turning_scenario(spec, self.np_random)
        if self.spindle_rpm_override is not None:
            sc = dataclasses.replace(sc, spindle_rpm=self.spindle_rpm_override)
        self.scenario = sc
        self._truth = sc.true_params(self.params)
        self.plant = TurningPlant(self._truth, sc.spindle_rpm, sc.profile)
        self._fr = float(sc.force_ref_N)
        self._length = sc.profile.length_mm
        self._vmax = self._truth.max_feed_velocity_mm_s
        self._noise_counts = self._truth.sensor_gain * self._truth.noise_std_N
        self._meas = [0.0] * (_HISTORY + 1)  # newest first, N
        self._normals: list[float] = []
        self._fr_obs = min(self._fr / self.params.force_scale_N, 10.0)
        self._rpm_obs = sc.spindle_rpm / 1000.0
        self._prev_action = -1.0
        self._n_clipped = 0
        self._done = False
        self._log = EpisodeLog(_LOG_FIELDS)
        info = self._info(0.0, 0.0, 0.0, False, False, False)
        info.update(
            feed_mm_per_rev=0.0,
            feed_velocity_mm_s=0.0,
            position_mm=0.0,
            depth_mm=float(sc.profile.start_depths_mm[0]),
            peak_force_N=0.0,
            segment=0,
        )
        self._log.record(info)
        return self._obs(), info

    def step(self, action):
        if self.plant is None:
            raise RuntimeError("TurningEnv: call reset() before step()")
        a, clipped = check_action(action, "TurningEnv")
        self._n_clipped += clipped
        u = self.command_map.action_to_command(a)
        noise = (
            self._noise_counts * float(self.np_random.standard_normal())
            if self._noise_counts
            else 0.0
        )
        s = self.plant.step(u, noise)
        t = self.plant.t_s
        force, peak, counts = s.force_N, s.peak_force_N, s.measured_counts
        diverged = not (
            math.isfinite(force) and math.isfinite(counts) and math.isfinite(s.position_mm)
        )
        if diverged:  # never seen; kept so that no NaN can reach an observation or a reward
            force = peak = counts = 0.0
        measured_N = counts / self.params.sensor_gain
        meas = self._meas
        meas.pop()
        meas.insert(0, measured_N)
        self._prev_action = a
        breakage = peak > self._truth.breakage_force_N
        finished = s.finish_time_s is not None
        terminated = diverged or breakage or finished
        truncated = (not terminated) and t >= self.max_episode_time_s - 1e-9

        w = self.reward_weights
        e = force / self._fr
        reward = -w.tracking * abs(e - 1.0) - w.overforce * max(0.0, e - w.overforce_threshold)
        if w.progress:
            reward += w.progress * s.feed_velocity_mm_s / self._vmax
        if breakage or diverged:
            reward -= w.breakage

        sc = self.scenario
        info = {
            "t_s": t,
            "command": u,
            "action_clipped": clipped,
            "n_action_clipped": self._n_clipped,
            "breakage": breakage,
            "diverged": diverged,
            "finished": finished,
            "force_N": force,
            "force_ref_N": self._fr,
            "measured": measured_N,
            "measured_counts": counts,
            "peak_force_N": peak,
            "feed_mm_per_rev": s.feed_mm_per_rev if not diverged else 0.0,
            "feed_velocity_mm_s": s.feed_velocity_mm_s if not diverged else 0.0,
            "position_mm": s.position_mm if not diverged else 0.0,
            "depth_mm": s.depth_mm,
            "segment": s.segment,
            "spindle_rpm": sc.spindle_rpm,
            "workpiece_length_mm": self._length,
            "scenario": sc.name,
        }
        if finished:
            info["machining_time_s"] = s.finish_time_s
        record_step(self, self._log, info)
        return self._obs(), float(reward), terminated, truncated, info

    # ---- helpers -------------------------------------------------------------------------
    def _obs(self) -> np.ndarray:
        fs = self.params.force_scale_N
        lo, hi = _FORCE_OBS
        m = self._meas
        return np.array(
            (
                min(max(m[0] / fs, lo), hi),
                self._fr_obs,
                self._prev_action,
                self._rpm_obs,
                min(max(m[1] / fs, lo), hi),
                min(max(m[2] / fs, lo), hi),
                min(max(m[3] / fs, lo), hi),
            ),
            dtype=np.float32,
        )

    def _info(self, t, command, measured, clipped, breakage, diverged) -> dict:
        sc = self.scenario
        return {
            "t_s": float(t),
            "command": float(command),
            "action_clipped": bool(clipped),
            "n_action_clipped": self._n_clipped,
            "breakage": bool(breakage),
            "diverged": bool(diverged),
            "finished": False,
            "force_N": 0.0,
            "force_ref_N": float(self._fr),
            "measured": float(measured),
            "measured_counts": float(measured * self.params.sensor_gain),
            "spindle_rpm": float(sc.spindle_rpm),
            "workpiece_length_mm": sc.profile.length_mm,
            "scenario": sc.name,
        }

    def render(self):
        if not ready_to_render(self, "TurningEnv"):
            return None
        log = self._log
        t = log["t"]
        img = render_signals(
            t,
            [
                (
                    "force (N)",
                    [
                        ("cutting force", log["force"], "C0-"),
                        ("measured", log["measured"], "C1-"),
                        ("reference", [self._fr] * len(t), "k--"),
                    ],
                ),
                ("feed (mm/rev)", [("feed", log["feed"], "C2-")]),
                ("depth of cut (mm)", [("depth", log["depth"], "C3-")]),
            ],
            f"Turning-v0 | {self.scenario.name} | {self.scenario.spindle_rpm:.0f} rpm",
        )
        return present_frame(img, self.render_mode, "Turning-v0")
