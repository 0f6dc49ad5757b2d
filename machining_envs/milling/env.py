"""``machining_envs/EndMilling-v0``: hold the cutting torque at a reference by adjusting the feed."""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from machining_envs.core.env import (
    ACTION_MAPS,
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
from machining_envs.milling.metrics import MILLING_TASK
from machining_envs.milling.plant import SPINDLE_RPM_RANGE, MillingParams, MillingPlant
from machining_envs.milling.scenarios import (
    MILLING_SCENARIOS,
    CutArea,
    MillingScenario,
    milling_scenario,
)

__all__ = ["EndMillingEnv", "MillingReward"]

_HISTORY = 3
#: Decades spanned by the command on the default logarithmic action map: the feeds that
#: hold the torque on the test set span about two (the feed exponent m ~ 0.4 turns a 2x
#: change of depth, Ks or reference into a ~5x change of feed), and one more keeps slow
#: approach feeds resolvable.
COMMAND_DECADES = 3.0
_TORQUE_OBS = (-1.0, 10.0)
#: The signals render() draws: name -> the info key each is read from.
_LOG_FIELDS = {
    "t": "t_s",
    "torque": "torque_Nmm",
    "measured": "measured",
    "feed": "feed_mm_per_rev",
    "depth": "depth_mm",
}


@dataclass(frozen=True)
class MillingReward:
    r"""Weights of the end-milling reward (see :class:`EndMillingEnv`, section Rewards).

    .. math::

        r = -w_t \frac{|T - T_r|}{T_r} - w_o \max\!\left(0, \frac{T}{T_r} - \theta_o\right)
            + w_p \frac{V_f}{V_{max}} - w_b [\text{breakage}]
    """

    tracking: float = 1.0
    """w_t, weight of the normalised torque error."""
    overtorque: float = 4.0
    """w_o, extra weight on torque above ``overtorque_threshold`` x reference."""
    overtorque_threshold: float = 1.1
    """theta_o, the 1.1 x reference above which torque counts as a constraint violation."""
    progress: float = 0.0
    """w_p, weight of the feed velocity as a share of the servo's top feed velocity."""
    breakage: float = 50.0
    """w_b, one-off penalty when the tool breaks."""

    def __post_init__(self) -> None:
        check_reward_weights(self)


class EndMillingEnv(gym.Env):
    """Constant cutting-torque regulation in end milling by feed (Park & Yoon 1986).

    ## Description
    A vertical machining centre end-mills SM45C steel with a 16 mm, 4-tooth HSS end mill
    (up-milling, 32 mm axial depth, 400 rpm). The radial depth of cut changes along the
    workpiece (the paper's steps and tapers, or random profiles); the controller must keep
    the cutting torque at the reference by commanding the CNC feed, as fast as the torque
    allows. The plant is ``machining_envs.milling.plant``: a second-order CNC feed servo
    (eq. 5-7), feed per revolution and per tooth (eq. 6), the torque law
    ``T = Ks d^l f_t^m D`` (eq. 8) or the average-force model of seed 002
    (``force_model="average_force"``), a first-order process lag (eq. 10) and a torque
    sensor with noise (eq. 9), sampled every 0.1 s. Because the process gain grows with the
    radial depth, a fixed-gain controller tuned for a shallow cut oscillates in a deep one
    (Fig. 5).

    ## Action Space
    ``Box(-1, 1, (1,), float32)``, mapped onto the command ``U`` in ``[0, command_max]``
    counts (``action_to_command`` / ``command_to_action``); the servo's steady feed velocity
    is ``servo_gain * U`` mm/s. The map is logarithmic by default (``action_map="log"``):
    ``U = command_max (1000^((a+1)/2) - 1) / 999``, so -1 holds the feed, +1 is full feed,
    and each third of the action's range multiplies the command tenfold. The feeds that
    hold the torque span two decades over the test set and sit in the bottom tenth of the
    command range, where an affine map (``action_map="linear"``) leaves a learned policy
    almost no resolution; classical agents go through ``command_to_action`` and are
    unaffected by the choice. A finite action outside the box is clipped and counted in
    ``info["n_action_clipped"]``; NaN or inf raises ``ValueError``.

    ## Observation Space
    ``Box(float32, (7,))``: only what the machine measures, normalised to order one. The
    torques are multiples of this cut's reference ``Tr``, so that holding the reference
    looks the same at every reference; the reference itself is a multiple of the nominal
    ``Tn = params.torque_ref_Nmm``.

    | index | observation | unit | range |
    |---|---|---|---|
    | 0 | measured torque (lagged, noisy) / Tr | - | [-1, 10] |
    | 1 | reference torque / Tn | - | [0, 10] |
    | 2 | previous action (the command now applied) | - | [-1, 1] |
    | 3 | spindle speed / 1000 rpm | - | [0, 6] |
    | 4-6 | measured torque one, two, three samples ago / Tr | - | [-1, 10] |

    The radial depth, the feed and the true process constants are hidden (they are in
    ``info``).

    ## Rewards
    With ``T`` the cutting torque at the sample instant, ``Tr`` the reference, ``Vf`` the
    feed velocity and ``Vmax`` the servo's top feed velocity (weights in
    :class:`MillingReward`, configurable with ``reward=``):
    ``r = -1.0 |T - Tr|/Tr - 4.0 max(0, T/Tr - 1.1) + 0.0 Vf/Vmax - 50 [breakage]``.
    Holding the torque at the reference is also the fastest safe cut, so the default reward
    needs no progress term. Benchmark metrics are computed from ``info``, not from rewards.

    ## Starting State
    Tool at the start of the workpiece, feed at rest, torque zero; the scenario (workpiece,
    spindle speed, reference, hidden Ks and m, noise) is drawn from ``self.np_random``.

    ## Episode End
    Terminated when the workpiece is cut to its end (``info["finished"]``), when the torque
    passes ``breakage_torque_Nmm`` at any 10 ms sub-step (``info["breakage"]``), or when a
    state goes non-finite (``info["diverged"]``). Truncated at ``max_episode_time_s``.

    ## Arguments
    ``gym.make("machining_envs/EndMilling-v0", scenario="train", render_mode=None,
    params=None, reward=None, max_episode_time_s=1200.0, action_map="log", **overrides)``:
    ``scenario`` is the default for resets without one (a name of ``MILLING_SCENARIOS`` or
    a ``MillingScenario``); ``action_map`` is ``"log"`` or ``"linear"`` (Action Space);
    ``params`` a ``MillingParams`` (nominal: what controllers are
    designed from; ``MillingParams.ahn_choi_al6061()`` for the Al6061 set); ``overrides``
    change single fields of it (``servo_gain=0.025``, ``force_model="average_force"``,
    ``spindle_rpm=500``). Unknown keywords raise ``TypeError``; out-of-range values raise
    ``ValueError`` naming the parameter.

    Reset options: ``{"scenario": name_or_MillingScenario}``.

    ## info
    ``t_s``, ``command`` (U, counts), ``action_clipped``, ``n_action_clipped``,
    ``breakage``, ``diverged``, ``finished``, ``torque_Nmm`` (true torque),
    ``torque_ref_Nmm``, ``measured`` (torque the controller saw, N·mm),
    ``measured_counts``, ``peak_torque_Nmm``, ``feed_mm_per_rev`` (at the sample instant),
    ``mean_feed_mm_per_rev`` (over the last sample: the f(i) of eq. 20),
    ``feed_per_tooth_mm``, ``feed_velocity_mm_s``, ``depth_mm`` (radial), ``spindle_rpm``,
    ``position_mm``, ``segment`` (index of the workpiece segment being cut),
    ``removed_volume_mm3``, ``workpiece_length_mm``, ``workpiece_volume_mm3``,
    ``scenario``, and ``machining_time_s`` once the cut is finished.

    ## Version History
    * v0: first version.

    ## Example
    >>> import gymnasium as gym
    >>> import machining_envs
    >>> env = gym.make("machining_envs/EndMilling-v0", scenario="paper_step")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["depth_mm"], info["spindle_rpm"], info["torque_ref_Nmm"]
    ((7,), 1.0, 400.0, 3600.0)
    >>> action = np.array([env.unwrapped.command_to_action(7.5)], dtype=np.float32)
    >>> obs, reward, terminated, truncated, info = env.step(action)
    >>> round(info["command"], 3), info["t_s"]
    (7.5, 0.1)
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}
    #: Episode metrics and primary score of this env (``machining_envs.core.score.Task``).
    task = MILLING_TASK
    #: Positions of the observation's fields, for controllers that read them by name.
    OBS_INDEX = {"measured": 0, "reference": 1, "prev_action": 2, "spindle": 3, "history": 4}

    def __init__(
        self,
        scenario: str | MillingScenario = "train",
        render_mode: str | None = None,
        params: MillingParams | None = None,
        reward: MillingReward | dict | None = None,
        max_episode_time_s: float = 1200.0,
        action_map: str = "log",
        **overrides,
    ):
        self.params = resolve_params(
            type(self).__name__, params, MillingParams, MillingParams.park_yoon_1986, overrides
        )
        self.reward_weights = resolve_reward(reward, MillingReward)
        self.max_episode_time_s = check_episode_time(max_episode_time_s)
        check_scenario_spec(scenario, MillingScenario, MILLING_SCENARIOS)
        self.default_scenario = scenario
        self.render_mode = check_render_mode(render_mode, self.metadata["render_modes"])

        if action_map not in ACTION_MAPS:
            raise ValueError(
                f"EndMillingEnv: action_map must be one of {list(ACTION_MAPS)}, got {action_map!r}"
            )
        self.command_map = ActionMap(
            0.0, self.params.command_max, scale=action_map, decades=COMMAND_DECADES
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        t_lo, t_hi = _TORQUE_OBS
        low = np.array([t_lo, 0.0, -1.0, 0.0] + [t_lo] * _HISTORY, dtype=np.float32)
        high = np.array(
            [t_hi, 10.0, 1.0, SPINDLE_RPM_RANGE[1] / 1000.0] + [t_hi] * _HISTORY, dtype=np.float32
        )
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.scenario: MillingScenario | None = None
        self.plant: MillingPlant | None = None

    # ---- the command map, for classical agents -----------------------------------------
    def action_to_command(self, action):
        """Command U (counts) for an action in [-1, 1]."""
        return self.command_map.action_to_command(action)

    def command_to_action(self, command):
        """Action in [-1, 1] for a command U (counts)."""
        return self.command_map.command_to_action(command)

    # ---- gymnasium API -------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        spec = scenario_option(options, self.default_scenario)
        sc = milling_scenario(spec, self.np_random)
        rpm = sc.spindle_rpm(self.params)
        self.scenario = sc
        self._truth = sc.true_params(self.params)
        self.plant = MillingPlant(self._truth, rpm, sc.profile)
        self._rpm = rpm
        self._tr = sc.torque_ref_Nmm(self.params)
        self._length = sc.profile.length_mm
        self._w = self._truth.axial_depth_mm
        self._area = CutArea(sc.profile)
        self._volume = self._w * self._area.total
        self._vmax = self._truth.max_feed_velocity_mm_s
        self._ke = self.params.sensor_gain
        self._noise_counts = self._truth.sensor_gain * self._truth.noise_std_Nmm
        self._meas = [0.0] * (_HISTORY + 1)  # newest first, N·mm
        self._tr_obs = min(self._tr / self.params.torque_ref_Nmm, 10.0)
        self._rpm_obs = rpm / 1000.0
        self._prev_action = -1.0
        self._n_clipped = 0
        self._log = EpisodeLog(_LOG_FIELDS)
        info = self._info_reset()
        self._log.record(info)
        return self._obs(), info

    def step(self, action):
        if self.plant is None:
            raise RuntimeError("EndMillingEnv: call reset() before step()")
        a, clipped = check_action(action, "EndMillingEnv")
        self._n_clipped += clipped
        u = self.command_map.action_to_command(a)
        noise = (
            self._noise_counts * float(self.np_random.standard_normal())
            if self._noise_counts
            else 0.0
        )
        s = self.plant.step(u, noise)
        t = self.plant.t_s
        torque, peak, counts = s.torque_Nmm, s.peak_torque_Nmm, s.measured_counts
        diverged = not (
            math.isfinite(torque)
            and math.isfinite(peak)
            and math.isfinite(counts)
            and math.isfinite(s.position_mm)
            and math.isfinite(s.mean_feed_mm_per_rev)
        )
        if diverged:  # never seen; kept so that no NaN can reach an observation or a reward
            torque = peak = counts = 0.0
        measured = counts / self._ke
        meas = self._meas
        meas.pop()
        meas.insert(0, measured)
        self._prev_action = a
        breakage = peak > self._truth.breakage_torque_Nmm
        finished = s.finish_time_s is not None
        terminated = diverged or breakage or finished
        truncated = (not terminated) and t >= self.max_episode_time_s - 1e-9

        w = self.reward_weights
        e = torque / self._tr
        reward = -w.tracking * abs(e - 1.0) - w.overtorque * max(0.0, e - w.overtorque_threshold)
        if w.progress and not diverged:
            reward += w.progress * s.feed_velocity_mm_s / self._vmax
        if breakage or diverged:
            reward -= w.breakage

        ok = not diverged
        position = s.position_mm if ok else 0.0
        info = {
            "t_s": t,
            "command": u,
            "action_clipped": clipped,
            "n_action_clipped": self._n_clipped,
            "breakage": breakage,
            "diverged": diverged,
            "finished": finished,
            "torque_Nmm": torque,
            "torque_ref_Nmm": self._tr,
            "measured": measured,
            "measured_counts": counts,
            "peak_torque_Nmm": peak,
            "feed_mm_per_rev": s.feed_mm_per_rev if ok else 0.0,
            "mean_feed_mm_per_rev": s.mean_feed_mm_per_rev if ok else 0.0,
            "feed_per_tooth_mm": s.feed_mm_per_rev / self._truth.n_teeth if ok else 0.0,
            "feed_velocity_mm_s": s.feed_velocity_mm_s if ok else 0.0,
            "position_mm": position,
            "depth_mm": s.depth_mm,
            "segment": s.segment,
            "spindle_rpm": self._rpm,
            "removed_volume_mm3": self._w * self._area(position),
            "workpiece_length_mm": self._length,
            "workpiece_volume_mm3": self._volume,
            "scenario": self.scenario.name,
        }
        if finished:
            info["machining_time_s"] = s.finish_time_s
        record_step(self, self._log, info)
        return self._obs(), float(reward), terminated, truncated, info

    # ---- helpers -------------------------------------------------------------------------
    def _obs(self) -> np.ndarray:
        sc = self._tr
        lo, hi = _TORQUE_OBS
        m = self._meas
        return np.array(
            (
                min(max(m[0] / sc, lo), hi),
                self._tr_obs,
                self._prev_action,
                self._rpm_obs,
                min(max(m[1] / sc, lo), hi),
                min(max(m[2] / sc, lo), hi),
                min(max(m[3] / sc, lo), hi),
            ),
            dtype=np.float32,
        )

    def _info_reset(self) -> dict:
        sc = self.scenario
        return {
            "t_s": 0.0,
            "command": 0.0,
            "action_clipped": False,
            "n_action_clipped": 0,
            "breakage": False,
            "diverged": False,
            "finished": False,
            "torque_Nmm": 0.0,
            "torque_ref_Nmm": float(self._tr),
            "measured": 0.0,
            "measured_counts": 0.0,
            "peak_torque_Nmm": 0.0,
            "feed_mm_per_rev": 0.0,
            "mean_feed_mm_per_rev": 0.0,
            "feed_per_tooth_mm": 0.0,
            "feed_velocity_mm_s": 0.0,
            "position_mm": 0.0,
            "depth_mm": float(sc.profile.start_depths_mm[0]),
            "segment": 0,
            "spindle_rpm": float(self._rpm),
            "removed_volume_mm3": 0.0,
            "workpiece_length_mm": self._length,
            "workpiece_volume_mm3": self._volume,
            "scenario": sc.name,
        }

    def render(self):
        if not ready_to_render(self, "EndMillingEnv"):
            return None
        log = self._log
        t = log["t"]
        img = render_signals(
            t,
            [
                (
                    "torque (N·mm)",
                    [
                        ("cutting torque", log["torque"], "C0-"),
                        ("measured", log["measured"], "C1-"),
                        ("reference", [self._tr] * len(t), "k--"),
                    ],
                ),
                ("feed (mm/rev)", [("feed", log["feed"], "C2-")]),
                ("radial depth (mm)", [("depth", log["depth"], "C3-")]),
            ],
            f"EndMilling-v0 | {self.scenario.name} | {self._rpm:.0f} rpm",
        )
        return present_frame(img, self.render_mode, "EndMilling-v0")
