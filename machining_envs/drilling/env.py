"""``machining_envs/MicroDrilling-v0``: hold the drilling torque by the spindle speed (or feed)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

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
from machining_envs.drilling.metrics import DRILLING_TASK
from machining_envs.drilling.plant import DrillingParams, DrillingPlant
from machining_envs.drilling.scenarios import (
    DRILLING_SCENARIOS,
    DrillingScenario,
    drilling_scenario,
)

__all__ = ["MicroDrillingEnv", "DrillingReward", "CONTROL_MODES"]

_HISTORY = 3
_TORQUE_OBS = (-1.0, 10.0)
_NOISE_BLOCK = 256
#: What the action commands: the valve voltage (the paper's loop) or the feed velocity.
CONTROL_MODES = ("voltage", "feed")
#: The signals render() draws: name -> the info key each is read from.
_LOG_FIELDS = {
    "t": "t_s",
    "torque": "torque_Nmm",
    "measured": "measured",
    "speed": "spindle_hz",
    "depth": "depth_mm",
    "position": "position_mm",
}


@dataclass(frozen=True)
class DrillingReward:
    r"""Weights of the drilling reward (see :class:`MicroDrillingEnv`, section Rewards).

    .. math::

        r = -w_t \frac{|T - T_r|}{T_r} - w_o \max\!\left(0, \frac{T}{T_r} - \theta_o\right)
            + w_p \frac{\Delta z}{T_s v_0} - w_b [\text{breakage}]
    """

    tracking: float = 1.0
    """w_t, weight of the normalised torque error."""
    overtorque: float = 4.0
    """w_o, extra weight on torque above ``overtorque_threshold`` x reference."""
    overtorque_threshold: float = 1.1
    """theta_o, the multiple of the reference above which torque counts as a violation."""
    progress: float = 0.0
    """w_p, weight of the hole deepening this step, as a share of the nominal feed's."""
    breakage: float = 50.0
    """w_b, one-off penalty when the drill breaks."""

    def __post_init__(self) -> None:
        check_reward_weights(self)


class MicroDrillingEnv(gym.Env):
    """Torque regulation in micro drilling by the spindle speed (Cheong & Cho, seed 003).

    ## Description
    An air-turbine spindle drives a 0.5-0.8 mm drill into SS40 mild steel at a constant feed
    velocity (0.32 mm/s). As the hole deepens, chips pack in the flutes and the torque climbs
    (their Fig. 12) until the drill breaks; industry pecks (retracts to clear the chips),
    which is safe but slow. Here the controller holds the torque at a reference by the
    spindle speed: a faster spindle cuts a thinner chip per revolution, and the torque falls
    as ``k4 / omega`` (eq. 20). The spindle is driven through a pneumatic proportional valve
    (second order, eq. 17), its air friction grows as ``omega^0.608`` (eq. 19) and the
    drilling torque slows it. The plant is ``machining_envs.drilling.plant``; the valve is
    integrated exactly and the spindle by RK4 sub-steps; the controller samples at 100 Hz.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``, mapped affinely onto the command (``action_to_command`` /
    ``command_to_action``):

    - ``control="voltage"`` (default, the paper's loop): the valve voltage in
      ``[0, voltage_max]`` V (0 to 10 V; 5 V, action 0, runs the free spindle at 545 Hz); the
      feed velocity is the scenario's constant 0.32 mm/s;
    - ``control="feed"``: the feed velocity of the stage in
      ``[-feed_speed_max_mm_s, feed_speed_max_mm_s]`` (negative retracts the drill; a retract
      that takes the point out of the hole clears the chips); the voltage is held at
      ``nominal_voltage``.

    A finite action outside the box is clipped and counted in ``info["n_action_clipped"]``;
    NaN or inf raises ``ValueError``.

    ## Observation Space
    ``Box(float32, (12,))``: only what the machine measures or the operator set, normalised.

    | index | observation | unit | range |
    |---|---|---|---|
    | 0 | measured torque (filtered, noisy) / ``torque_scale_Nmm`` | - | [-1, 10] |
    | 1 | torque reference / ``torque_scale_Nmm`` | - | [0, 10] |
    | 2 | measured thrust / ``thrust_scale_N`` | - | [-1, 10] |
    | 3 | measured spindle frequency / 1000 Hz | - | [0, 3] |
    | 4 | previous action (the command now applied) | - | [-1, 1] |
    | 5 | drill point position below the surface / 10 mm | - | [-1, 2] |
    | 6 | hole depth / 10 mm | - | [0, 2] |
    | 7 | target hole depth / 10 mm | - | [0, 2] |
    | 8 | drill diameter / 1 mm | - | [0, 1] |
    | 9-11 | measured torque one, two, three samples ago / ``torque_scale_Nmm`` | - | [-1, 10] |

    The packed chips, the true cutting constant and the valve's spool position are hidden
    (they are in ``info``).

    ## Rewards
    With ``T`` the torque at the sample instant, ``Tr`` the reference, ``dz`` the hole's
    deepening in the step and ``v0`` the nominal feed (weights in :class:`DrillingReward`,
    configurable with ``reward=``):
    ``r = -1.0 |T - Tr|/Tr - 4.0 max(0, T/Tr - 1.1) + 0.0 dz/(Ts v0) - 50 [breakage]``.
    Benchmark metrics are computed from ``info``, not from rewards.

    ## Starting State
    The spindle runs free at the nominal voltage (545 Hz, Table 1), the valve settled, the
    drill point touching the work surface; the scenario (drill, hole depth, hidden cutting
    constant and chip packing, noise) comes from ``self.np_random``.

    ## Episode End
    Terminated when the hole reaches its target depth (``info["finished"]``), when the torque
    passes the drill's breakage torque at any sub-step (``info["breakage"]``), or when a
    state goes non-finite (``info["diverged"]``). Truncated at ``max_episode_time_s``.

    ## Arguments
    ``gym.make("machining_envs/MicroDrilling-v0", scenario="train", control="voltage",
    render_mode=None, params=None, reward=None, max_episode_time_s=150.0, **overrides)``:
    ``scenario`` is the default for resets without one (a name of ``DRILLING_SCENARIOS`` or a
    ``DrillingScenario``); ``params`` a ``DrillingParams`` (nominal: what controllers are
    designed from); ``overrides`` change single fields of it (``torque_noise_Nmm=0.02``).
    Unknown keywords raise ``TypeError``; out-of-range values raise ``ValueError`` naming
    the parameter.

    Reset options: ``{"scenario": name_or_DrillingScenario}``.

    ## info
    ``t_s``, ``command`` (V or mm/s), ``action_clipped``, ``n_action_clipped``, ``breakage``,
    ``diverged``, ``finished``, ``torque_Nmm`` (true torque), ``torque_ref_Nmm``,
    ``measured`` (torque the controller saw, N·mm), ``peak_torque_Nmm``,
    ``breakage_torque_Nmm``, ``thrust_N``, ``measured_thrust_N``, ``spindle_hz``,
    ``measured_spindle_hz``, ``spindle_rpm``, ``voltage_V``, ``valve_opening``,
    ``feed_velocity_mm_s``, ``feed_mm_per_rev``, ``cutting``, ``engagement`` (engaged share
    of the full torque while the point enters), ``position_mm`` (drill point),
    ``depth_mm`` (hole depth), ``target_depth_mm``, ``packed_chip_mm``, ``chip_ratio``,
    ``diameter_mm``, ``segment`` (0 before the first cut, 1 after), ``scenario``, and
    ``drilling_time_s`` / ``machining_time_s`` once the hole is finished.

    ## Version History
    * v0: first version.

    ## Example
    >>> import gymnasium as gym
    >>> import machining_envs
    >>> env = gym.make("machining_envs/MicroDrilling-v0", scenario="paper_0.8")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["diameter_mm"], info["target_depth_mm"], round(info["spindle_hz"])
    ((12,), 0.8, 8.0, 545)
    >>> obs, reward, terminated, truncated, info = env.step(np.array([0.0], dtype=np.float32))
    >>> info["command"], info["t_s"], info["cutting"]
    (5.0, 0.01, True)
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 25}
    #: Episode metrics and primary score of this env (``machining_envs.core.score.Task``).
    task = DRILLING_TASK
    #: Positions of the observation's fields, for controllers that read them by name.
    OBS_INDEX = {
        "measured": 0,
        "reference": 1,
        "thrust": 2,
        "spindle": 3,
        "prev_action": 4,
        "position": 5,
        "depth": 6,
        "target": 7,
        "diameter": 8,
        "history": 9,
    }
    #: Scales of the observation fields that are not set by the parameters.
    SPEED_SCALE_HZ = 1000.0
    LENGTH_SCALE_MM = 10.0

    def __init__(
        self,
        scenario: str | DrillingScenario = "train",
        control: str = "voltage",
        render_mode: str | None = None,
        params: DrillingParams | None = None,
        reward: DrillingReward | dict | None = None,
        max_episode_time_s: float = 150.0,
        **overrides,
    ):
        self.params = resolve_params(
            type(self).__name__, params, DrillingParams, DrillingParams.cheong_cho, overrides
        )
        if control not in CONTROL_MODES:
            raise ValueError(f"control must be one of {CONTROL_MODES}, got {control!r}")
        self.control = control
        self.reward_weights = resolve_reward(reward, DrillingReward)
        self.max_episode_time_s = check_episode_time(max_episode_time_s)
        check_scenario_spec(scenario, DrillingScenario, DRILLING_SCENARIOS)
        self.default_scenario = scenario
        self.render_mode = check_render_mode(render_mode, self.metadata["render_modes"])

        p = self.params
        if control == "voltage":
            self.command_map = ActionMap(0.0, p.voltage_max)
        else:
            self.command_map = ActionMap(-p.feed_speed_max_mm_s, p.feed_speed_max_mm_s)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        t_lo, t_hi = _TORQUE_OBS
        low = np.array(
            [t_lo, 0.0, t_lo, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0] + [t_lo] * _HISTORY,
            dtype=np.float32,
        )
        high = np.array(
            [t_hi, 10.0, t_hi, 3.0, 1.0, 2.0, 2.0, 2.0, 1.0] + [t_hi] * _HISTORY,
            dtype=np.float32,
        )
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.scenario: DrillingScenario | None = None
        self.plant: DrillingPlant | None = None

    # ---- the command map, for classical agents -----------------------------------------
    def action_to_command(self, action):
        """Physical command (V, or mm/s with ``control="feed"``) for an action in [-1, 1]."""
        return self.command_map.action_to_command(action)

    def command_to_action(self, command):
        """Action in [-1, 1] for a physical command (V, or mm/s with ``control="feed"``)."""
        return self.command_map.command_to_action(command)

    # ---- gymnasium API -------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        spec = scenario_option(options, self.default_scenario)
        sc = drilling_scenario(spec, self.np_random)
        self.scenario = sc
        self._truth = sc.true_params(self.params)
        self.plant = DrillingPlant(self._truth, sc.diameter_mm, sc.target_depth_mm)
        self._tr = sc.reference_Nmm(self.params)
        p = self.params
        self._ts = p.sample_time_s
        self._v0 = p.feed_velocity_mm_s
        if self.control == "voltage":
            self._prev_action = float(self.command_to_action(p.nominal_voltage))
        else:
            self._prev_action = float(self.command_to_action(p.feed_velocity_mm_s))
        self._noise = self.np_random.standard_normal((_NOISE_BLOCK, 5)).tolist()
        self._noise_i = 0
        self._meas = [0.0] * (_HISTORY + 1)  # newest first, N·mm
        self._thrust_meas = 0.0
        self._speed_meas = self.plant.omega / (2.0 * math.pi)
        self._n_clipped = 0
        self._segment = 0
        self._static_obs = (
            min(self._tr / p.torque_scale_Nmm, 10.0),
            min(sc.target_depth_mm / self.LENGTH_SCALE_MM, 2.0),
            sc.diameter_mm,
        )
        self._log = EpisodeLog(_LOG_FIELDS)
        info = self._info_reset()
        self._log.record(info)
        return self._obs(), info

    def step(self, action):
        if self.plant is None:
            raise RuntimeError("MicroDrillingEnv: call reset() before step()")
        a, clipped = check_action(action, "MicroDrillingEnv")
        self._n_clipped += clipped
        command = self.command_map.action_to_command(a)
        p = self.params
        if self.control == "voltage":
            voltage, feed = command, self._v0
        else:
            voltage, feed = p.nominal_voltage, command
        if self._noise_i == _NOISE_BLOCK:
            self._noise = self.np_random.standard_normal((_NOISE_BLOCK, 5)).tolist()
            self._noise_i = 0
        noise = self._noise[self._noise_i]
        self._noise_i += 1
        s = self.plant.step(voltage, feed, noise)
        t = self.plant.t_s
        torque, peak, meas = s.torque_Nmm, s.peak_torque_Nmm, s.measured_torque_Nmm
        diverged = not (
            math.isfinite(torque)
            and math.isfinite(peak)
            and math.isfinite(meas)
            and math.isfinite(s.thrust_N)
            and math.isfinite(s.measured_thrust_N)
            and math.isfinite(s.speed_hz)
            and math.isfinite(s.measured_speed_hz)
        )
        if diverged:  # never seen; kept so that no NaN can reach an observation or a reward
            torque = peak = meas = 0.0
        hist = self._meas
        hist.pop()
        hist.insert(0, meas)
        self._thrust_meas = s.measured_thrust_N if not diverged else 0.0
        self._speed_meas = s.measured_speed_hz if not diverged else 0.0
        self._prev_action = a
        if s.cutting:
            self._segment = 1
        breakage = peak > self.plant.breakage_torque_Nmm
        finished = s.finish_time_s is not None
        terminated = diverged or breakage or finished
        truncated = (not terminated) and t >= self.max_episode_time_s - 1e-9

        w = self.reward_weights
        e = torque / self._tr
        reward = -w.tracking * abs(e - 1.0) - w.overtorque * max(0.0, e - w.overtorque_threshold)
        if w.progress:
            reward += w.progress * s.cutting_feed_mm_s / self._v0
        if breakage or diverged:
            reward -= w.breakage

        sc = self.scenario
        info = {
            "t_s": t,
            "command": command,
            "action_clipped": clipped,
            "n_action_clipped": self._n_clipped,
            "breakage": breakage,
            "diverged": diverged,
            "finished": finished,
            "torque_Nmm": torque,
            "torque_ref_Nmm": self._tr,
            "measured": meas,
            "peak_torque_Nmm": peak,
            "breakage_torque_Nmm": self.plant.breakage_torque_Nmm,
            "thrust_N": s.thrust_N if not diverged else 0.0,
            "measured_thrust_N": self._thrust_meas,
            "spindle_hz": s.speed_hz if not diverged else 0.0,
            "measured_spindle_hz": self._speed_meas,
            "spindle_rpm": 60.0 * s.speed_hz if not diverged else 0.0,
            "voltage_V": voltage,
            "valve_opening": s.valve_opening,
            "feed_velocity_mm_s": s.feed_velocity_mm_s,
            "feed_mm_per_rev": s.feed_mm_per_rev if not diverged else 0.0,
            "cutting": s.cutting,
            "engagement": s.engagement,
            "position_mm": s.position_mm,
            "depth_mm": s.depth_mm,
            "target_depth_mm": sc.target_depth_mm,
            "packed_chip_mm": s.packed_mm,
            "chip_ratio": s.chip_ratio,
            "diameter_mm": sc.diameter_mm,
            "segment": self._segment,
            "scenario": sc.name,
        }
        if finished:
            info["drilling_time_s"] = s.finish_time_s
            info["machining_time_s"] = s.finish_time_s
        record_step(self, self._log, info)
        return self._obs(), float(reward), terminated, truncated, info

    # ---- helpers -------------------------------------------------------------------------
    def _obs(self) -> np.ndarray:
        p = self.params
        ts = p.torque_scale_Nmm
        lo, hi = _TORQUE_OBS
        m = self._meas
        pl = self.plant
        tr, target, diameter = self._static_obs
        ls = self.LENGTH_SCALE_MM
        return np.array(
            (
                min(max(m[0] / ts, lo), hi),
                tr,
                min(max(self._thrust_meas / p.thrust_scale_N, lo), hi),
                min(max(self._speed_meas / self.SPEED_SCALE_HZ, 0.0), 3.0),
                self._prev_action,
                min(max(pl.position_mm / ls, -1.0), 2.0),
                min(pl.depth_mm / ls, 2.0),
                target,
                diameter,
                min(max(m[1] / ts, lo), hi),
                min(max(m[2] / ts, lo), hi),
                min(max(m[3] / ts, lo), hi),
            ),
            dtype=np.float32,
        )

    def _info_reset(self) -> dict:
        sc = self.scenario
        pl = self.plant
        hz = pl.omega / (2.0 * math.pi)
        command = self.action_to_command(self._prev_action)
        return {
            "t_s": 0.0,
            "command": float(command),
            "action_clipped": False,
            "n_action_clipped": 0,
            "breakage": False,
            "diverged": False,
            "finished": False,
            "torque_Nmm": 0.0,
            "torque_ref_Nmm": float(self._tr),
            "measured": 0.0,
            "peak_torque_Nmm": 0.0,
            "breakage_torque_Nmm": pl.breakage_torque_Nmm,
            "thrust_N": 0.0,
            "measured_thrust_N": 0.0,
            "spindle_hz": hz,
            "measured_spindle_hz": hz,
            "spindle_rpm": 60.0 * hz,
            "voltage_V": pl.voltage,
            "valve_opening": pl.x1,
            "feed_velocity_mm_s": 0.0,
            "feed_mm_per_rev": 0.0,
            "cutting": False,
            "engagement": 0.0,
            "position_mm": pl.position_mm,
            "depth_mm": 0.0,
            "target_depth_mm": sc.target_depth_mm,
            "packed_chip_mm": 0.0,
            "chip_ratio": 0.0,
            "diameter_mm": sc.diameter_mm,
            "segment": 0,
            "scenario": sc.name,
        }

    def render(self):
        if not ready_to_render(self, "MicroDrillingEnv"):
            return None
        log = self._log
        t = log["t"]
        img = render_signals(
            t,
            [
                (
                    "torque (N·mm)",
                    [
                        ("torque", log["torque"], "C0-"),
                        ("measured", log["measured"], "C1-"),
                        ("reference", [self._tr] * len(t), "k--"),
                    ],
                ),
                ("spindle (Hz)", [("spindle", log["speed"], "C2-")]),
                (
                    "drill (mm)",
                    [("hole depth", log["depth"], "C3-"), ("point", log["position"], "C4-")],
                ),
            ],
            f"MicroDrilling-v0 | {self.scenario.name} | D = {self.scenario.diameter_mm:.2f} mm"
            f" | control = {self.control}",
        )
        return present_frame(img, self.render_mode, "MicroDrilling-v0")
