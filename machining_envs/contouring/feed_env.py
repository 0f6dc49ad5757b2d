"""``machining_envs/ContouringFeed-v0``: choose the feed override along a toolpath while the
CNC's own position loop (PI or H-infinity) drives the axes."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from machining_envs.contouring.env import (
    ERROR_SCALE_MM,
    TRACE_LOG_FIELDS,
    VELOCITY_SCALE_MM_S,
    _circle_info,
    _positive,
    _run_limits,
    check_action_vector,
    render_trace,
)
from machining_envs.contouring.metrics import FEED_TASK
from machining_envs.contouring.plant import AXES, ContouringParams
from machining_envs.contouring.scenarios import (
    CONTOURING_SCENARIOS,
    ContouringScenario,
    contouring_scenario,
)
from machining_envs.contouring.servo import SERVO_KINDS, ServoLoop, servo_design
from machining_envs.core.env import (
    ActionMap,
    EpisodeLog,
    check_render_mode,
    check_reward_weights,
    check_scenario_spec,
    present_frame,
    ready_to_render,
    record_step,
    resolve_params,
    resolve_reward,
    scenario_option,
)

__all__ = ["ContouringFeedEnv", "FeedReward", "LOOKAHEAD_MM", "DEFAULT_TOLERANCE_MM"]

#: The observation previews the path's turn over these distances ahead of the set point, mm.
LOOKAHEAD_MM = (0.5, 1.0, 2.0, 5.0, 10.0)
#: Contour-error tolerance of each servo by default, mm: a finishing tolerance each loop
#: can hold at the programmed feed on straight and gently curved parts but not everywhere
#: at twice it (see docs/contouring.md).
DEFAULT_TOLERANCE_MM = {"pi": 0.05, "hinf": 0.005}

# Upper bounds of the observation (index 4, the path speed, is set to ``override_max``).
_LIMS = [100.0, 100.0, 100.0, 100.0, 2.0, 1.0, 10.0, *[10.0] * len(LOOKAHEAD_MM)]
_LIMS += [10.0, 10.0, 10.0, 1.0]


@dataclass(frozen=True)
class FeedReward:
    r"""Weights of the ContouringFeed-v0 reward (see :class:`ContouringFeedEnv`, Rewards).

    .. math::

        r = w_p \frac{\Delta s}{L} - w_t \frac{\Delta t}{L / F}
            - w_e \frac{1}{N} \sum_{j=1}^{N} \max\!\left(0, \frac{\varepsilon_j}{\varepsilon_{tol}} - 1\right)
            - w_d [\text{diverged}]

    over the step's ``N`` servo periods: progress along the path of length ``L``, the time
    spent as a share of the programmed cycle time ``L / F``, and the contour error beyond the
    tolerance. At the programmed feed without error the first two cancel over a run; a
    faster run without error earns the time it saves.
    """

    progress: float = 1.0
    """w_p, weight of the share of the path covered in the step."""
    time: float = 1.0
    """w_t, weight of the time spent, per programmed cycle time."""
    tolerance: float = 1.0
    """w_e, weight of the relative excess of the contour error over the tolerance."""
    divergence: float = 10.0
    """w_d, one-off penalty when the run diverges."""

    def __post_init__(self) -> None:
        check_reward_weights(self, allow_bool=True)


@functools.lru_cache(maxsize=16)
def _servo_loop(truth: ContouringParams, nominal: ContouringParams, kind: str, block: int):
    designs = tuple(servo_design(kind, nominal, ax) for ax in AXES)
    return ServoLoop(truth, designs, block)


class ContouringFeedEnv(gym.Env):
    """Feed override for contouring: as fast as the contour-error tolerance allows.

    ## Description
    The XY table of ``Contouring-v0`` under its CNC's own position loop: the paper's PI or
    H-infinity 2-DOF controller per axis (``servo=``), designed from the nominal
    parameters, runs at the 5 kHz servo rate. The agent is the feed-override knob: every
    ``decision_interval_s`` (10 ms) it sets the speed at which the set point advances along
    the path, as a multiple of the programmed feed. Going faster shortens the cycle; on
    tight arcs, at the start from rest and where the axes' lags differ it also makes the
    contour error grow, and the reward charges the error beyond ``tolerance_mm``. The
    constant-feed baseline is ``agents.ConstantOverride``.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``, mapped affinely onto the feed override in
    ``[0, override_max]`` (default 2; action 0 is the programmed feed, -1 holds the feed).
    Clipped and counted when outside the box; NaN or inf raises ``ValueError``.

    ## Observation Space
    ``Box(float32, (16,))``:

    | index | observation | unit | range |
    |---|---|---|---|
    | 0 | contour error at the step's end / tolerance | - | [0, 100] |
    | 1 | largest contour error over the step / tolerance | - | [0, 100] |
    | 2-3 | tracking error X, Y / 1 mm | - | [-100, 100] |
    | 4 | path speed of the set point / programmed feed | - | [0, 2] |
    | 5 | share of the path done | - | [0, 1] |
    | 6 | path left / 100 mm | - | [0, 10] |
    | 7-11 | path's turn over the next 0.5, 1, 2, 5, 10 mm / pi | - | [-10, 10] |
    | 12 | programmed feed / 100 mm/s | - | [0, 10] |
    | 13-14 | axis velocities / 100 mm/s | - | [-10, 10] |
    | 15 | previous action | - | [-1, 1] |

    ## Rewards
    ``r = 1.0 ds/L - 1.0 dt/(L/F) - 1.0 mean_j max(0, eps_j/tol - 1) - 10 [diverged]``
    (weights in :class:`FeedReward`, configurable with ``reward=``).

    ## Starting State
    Table and controllers at rest at the path's start; the scenario is drawn from
    ``self.np_random`` (step scenarios are refused: they have no path to feed along).

    ## Episode End
    Terminated when the set point has reached the path's end and the table is within
    ``in_position_mm`` of it (``info["finished"]``), or on divergence (tracking error over
    ``divergence_mm`` or a non-finite state). Truncated at ``max_episode_time_s`` (default
    five times the programmed cycle time plus 0.5 s).

    ## Arguments
    ``gym.make("machining_envs/ContouringFeed-v0", scenario="train", render_mode=None,
    params=None, servo="hinf", tolerance_mm=None, reward=None, decision_interval_s=0.01,
    override_max=2.0, max_episode_time_s=None, in_position_mm=0.005, divergence_mm=50.0,
    **overrides)``: ``servo`` is ``"hinf"`` (``agents.HInf2DOF``'s design, the default) or
    ``"pi"`` (``agents.PIPosition``'s); ``tolerance_mm`` defaults to
    ``DEFAULT_TOLERANCE_MM[servo]`` (5 um for H-infinity, 50 um for PI); ``overrides`` change
    fields of ``ContouringParams``. Unknown keywords raise ``TypeError``; out-of-range values
    raise ``ValueError`` naming the parameter.

    ## info
    The keys of ``Contouring-v0`` at the step's end (``x_mm``, ``contour_error_mm``,
    ``command``...; ``torque_sq_Nm2`` is the step's mean) plus ``peak_contour_error_mm``
    (largest over the step), ``tolerance_mm``, ``feed_override``, ``path_speed_mm_s``,
    ``servo``, ``programmed_time_s`` (path length over programmed feed), ``time_limit_s``
    (this episode's truncation time), and ``machining_time_s`` (the cycle time, to the servo
    period) once finished.

    ## Version History
    * v0: first version.

    ## Example
    >>> import gymnasium as gym
    >>> import machining_envs
    >>> env = gym.make("machining_envs/ContouringFeed-v0", scenario="paper_circle")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["tolerance_mm"], info["servo"]
    ((16,), 0.005, 'hinf')
    >>> obs, reward, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
    >>> round(info["t_s"], 6), info["feed_override"], round(info["path_s_mm"], 6)
    (0.01, 1.0, 0.5)
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}
    #: Episode metrics and primary score of this env (``machining_envs.core.score.Task``).
    task = FEED_TASK

    def __init__(
        self,
        scenario: str | ContouringScenario = "train",
        render_mode: str | None = None,
        params: ContouringParams | None = None,
        servo: str = "hinf",
        tolerance_mm: float | None = None,
        reward: FeedReward | dict | None = None,
        decision_interval_s: float = 0.01,
        override_max: float = 2.0,
        max_episode_time_s: float | None = None,
        in_position_mm: float = 0.005,
        divergence_mm: float = 50.0,
        **overrides,
    ):
        self.params = resolve_params(
            type(self).__name__, params, ContouringParams, ContouringParams.choi_et_al, overrides
        )
        if servo not in SERVO_KINDS:
            raise ValueError(f"servo must be one of {SERVO_KINDS}, got {servo!r}")
        self.servo = servo
        if tolerance_mm is None:
            tolerance_mm = DEFAULT_TOLERANCE_MM[servo]
        self.tolerance_mm = _positive("tolerance_mm", tolerance_mm, 0.0, 100.0)
        self.reward_weights = resolve_reward(reward, FeedReward)
        ts = self.params.sample_time_s
        dec = _positive("decision_interval_s", decision_interval_s, 0.0, 1.0)
        n_sub = int(round(dec / ts))
        if n_sub < 1 or abs(n_sub * ts - dec) > 1e-9 * dec:
            raise ValueError(
                f"decision_interval_s must be a whole number of servo periods "
                f"({ts} s), got {decision_interval_s!r}"
            )
        self.decision_interval_s = dec
        self._n_sub = n_sub
        self.override_max = _positive("override_max", override_max, 0.0, 10.0)
        self.max_episode_time_s, self.in_position_mm, self.divergence_mm = _run_limits(
            max_episode_time_s, in_position_mm, divergence_mm
        )
        check_scenario_spec(scenario, ContouringScenario, CONTOURING_SCENARIOS)
        self.default_scenario = scenario
        self.render_mode = check_render_mode(render_mode, self.metadata["render_modes"])
        # Design the servo now (cached per process), so that a bad design fails here.
        for ax in AXES:
            servo_design(servo, self.params, ax)
        self.command_map = ActionMap(0.0, self.override_max)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        high = np.array(_LIMS, dtype=np.float32)
        high[4] = self.override_max
        low = -high
        low[[0, 1, 4, 5, 6, 12]] = 0.0
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self._bounds = (low.tolist(), high.tolist())
        self.scenario: ContouringScenario | None = None
        self.loop: ServoLoop | None = None

    def action_to_command(self, action):
        """Feed override for an action in [-1, 1]."""
        return self.command_map.action_to_command(action)

    def command_to_action(self, override):
        """Action in [-1, 1] for a feed override."""
        return self.command_map.command_to_action(override)

    # ---- gymnasium API -------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        spec = scenario_option(options, self.default_scenario)
        sc = contouring_scenario(spec, self.np_random)
        if sc.is_step:
            raise ValueError(
                f"scenario {sc.name!r} is a step command; ContouringFeed-v0 needs a path with a feed"
            )
        self.scenario = sc
        self._truth = sc.true_params(self.params)
        self.loop = _servo_loop(self._truth, self.params, self.servo, self._n_sub)
        self._state = self.loop.initial_state()
        path = sc.path
        self._path = path
        self._x0, self._y0 = path.start
        self._feed = sc.feed_mm_s
        self._prog_time = path.length / sc.feed_mm_s
        t_max = self.max_episode_time_s
        if t_max is None:
            t_max = 5.0 * self._prog_time + 0.5
        self._t_max = t_max
        self._k = 0
        self._s = 0.0
        self._override = 0.0
        self._prev_action = -1.0
        self._n_clipped = 0
        self._load_t = np.array([t for t, _, _ in sc.load_steps] or [math.inf])
        self._load_v = np.array([[0.0, 0.0]] + [[a, b] for _, a, b in sc.load_steps])
        self._circle = _circle_info(path)
        self._log = EpisodeLog(TRACE_LOG_FIELDS)
        info = self._info(0.0, (0.0, 0.0), self._x0, self._y0, (0.0, 0.0), 0.0, 0.0, 0.0, 0.0)
        info.update(diverged=False, finished=False, action_clipped=False)
        if self.render_mode is not None:
            self._log.record(info)
        return self._obs(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), info

    def step(self, action):
        if self.loop is None:
            raise RuntimeError("ContouringFeedEnv: call reset() before step()")
        (a,), clipped = check_action_vector(action, 1, "ContouringFeedEnv")
        self._n_clipped += clipped
        ov = float(self.action_to_command(a))
        n = self._n_sub
        ts = self.params.sample_time_s
        length = self._path.length
        v = self._feed * ov
        s_ticks = np.minimum(self._s + v * ts * np.arange(n + 1), length)
        rx, ry = self._path.points(s_ticks[:n])
        ref = np.column_stack([rx - self._x0, ry - self._y0])
        t_ticks = (self._k + np.arange(n)) * ts
        load = self._load_v[np.searchsorted(self._load_t, t_ticks + 1e-12, side="right")]
        pos, vel, cmd, torque, _ = self.loop.run(self._state, ref, load)
        px = pos[:, 0] + self._x0
        py = pos[:, 1] + self._y0
        diverged = not bool(np.all(np.isfinite(pos)) and np.all(np.isfinite(vel)))
        if diverged:  # kept so that no NaN can reach an observation or a reward
            px, py = rx.copy(), ry.copy()
            vel = np.zeros_like(vel)
            torque = np.zeros_like(torque)
            cmd = np.zeros_like(cmd)
            self._state = self.loop.initial_state()
        eps = self._path.distances(px, py)
        ds = float(s_ticks[-1] - self._s)
        self._s = float(s_ticks[-1])
        self._k += n
        t = self._k * ts
        # Set point at the end of the step (the next period's), for the tracking error.
        rxe, rye = self._path.point(self._s)
        x, y = float(px[-1]), float(py[-1])
        etrack = math.hypot(rxe - x, rye - y)
        diverged = diverged or etrack > self.divergence_mm
        end = self._path.end
        done_ref = s_ticks[1:] >= length
        inpos = np.hypot(px - end[0], py - end[1]) <= self.in_position_mm
        hit = np.flatnonzero(done_ref & inpos)
        finished = bool(hit.size) and not diverged
        terminated = diverged or finished
        truncated = (not terminated) and t >= self._t_max - 1e-12
        tol = self.tolerance_mm
        w = self.reward_weights
        excess = float(np.mean(np.maximum(0.0, eps / tol - 1.0)))
        reward = (
            w.progress * ds / length - w.time * (n * ts) / self._prog_time - w.tolerance * excess
        )
        if diverged:
            reward -= w.divergence
        self._override = ov
        self._prev_action = a
        tsq = float(np.mean(torque[:, 0] ** 2 + torque[:, 1] ** 2))
        info = self._info(
            t,
            (float(cmd[-1, 0]), float(cmd[-1, 1])),
            x,
            y,
            (float(vel[-1, 0]), float(vel[-1, 1])),
            float(eps[-1]),
            float(eps.max()),
            etrack,
            tsq,
        )
        info.update(
            torque_x_Nm=float(torque[-1, 0]),
            torque_y_Nm=float(torque[-1, 1]),
            load_x_Nm=float(load[-1, 0]),
            load_y_Nm=float(load[-1, 1]),
            action_clipped=bool(clipped),
            diverged=bool(diverged),
            finished=finished,
        )
        if finished:
            info["machining_time_s"] = float((self._k - n + hit[0] + 1) * ts)
        record_step(self, self._log, info)
        obs = self._obs(
            float(eps[-1]), float(eps.max()), rxe - x, rye - y, info["vx_mm_s"], info["vy_mm_s"]
        )
        return obs, float(reward), terminated, truncated, info

    # ---- helpers -------------------------------------------------------------------------
    def _obs(self, eps, peak, ex, ey, vx, vy) -> np.ndarray:
        tol = self.tolerance_mm
        path = self._path
        s = self._s
        ahead = np.array([s, *(s + d for d in LOOKAHEAD_MM)])
        h = path.headings(ahead)
        turn = ((h[1:] - h[0]) / math.pi).tolist()
        o = [
            eps / tol,
            peak / tol,
            ex / ERROR_SCALE_MM,
            ey / ERROR_SCALE_MM,
            self._override if s < path.length else 0.0,
            s / path.length,
            (path.length - s) / 100.0,
            *turn,
            self._feed / 100.0,
            vx / VELOCITY_SCALE_MM_S,
            vy / VELOCITY_SCALE_MM_S,
            self._prev_action,
        ]
        return np.array(
            [
                lo if v < lo else (hi if v > hi else v)
                for v, lo, hi in zip(o, *self._bounds, strict=True)
            ],
            dtype=np.float32,
        )

    def _info(self, t, cmd, x, y, vel, eps, peak, etrack, tsq) -> dict:
        sc = self.scenario
        rx, ry = self._path.point(self._s)
        info = {
            "t_s": t,
            "command": np.array(cmd),
            "command_x_mm_s": cmd[0],
            "command_y_mm_s": cmd[1],
            "action_clipped": False,
            "n_action_clipped": self._n_clipped,
            "breakage": False,
            "diverged": False,
            "finished": False,
            "x_mm": x,
            "y_mm": y,
            "x_ref_mm": rx,
            "y_ref_mm": ry,
            "contour_error_mm": eps,
            "peak_contour_error_mm": peak,
            "tracking_error_mm": etrack,
            "tolerance_mm": self.tolerance_mm,
            "vx_mm_s": vel[0],
            "vy_mm_s": vel[1],
            "torque_x_Nm": 0.0,
            "torque_y_Nm": 0.0,
            "torque_sq_Nm2": tsq,
            "load_x_Nm": 0.0,
            "load_y_Nm": 0.0,
            "feed_override": self._override,
            "path_speed_mm_s": self._override * self._feed if self._s < self._path.length else 0.0,
            "path_s_mm": self._s,
            "path_length_mm": self._path.length,
            "segment": self._path.segment_index(self._s),
            "feed_mm_s": self._feed,
            "programmed_time_s": self._prog_time,
            "time_limit_s": self._t_max,
            "servo": self.servo,
            "scenario": sc.name,
        }
        info.update(self._circle)
        return info

    def render(self):
        if not ready_to_render(self, "ContouringFeedEnv", started=self.loop is not None):
            return None
        img = render_trace(
            self._path,
            self._log,
            f"ContouringFeed-v0 | {self.scenario.name} | servo {self.servo}",
        )
        return present_frame(img, self.render_mode, "ContouringFeed-v0")
