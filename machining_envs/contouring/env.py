"""``machining_envs/Contouring-v0``: drive both axes of an XY table along a toolpath."""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from machining_envs.contouring.metrics import CONTOURING_TASK
from machining_envs.contouring.paths import Path
from machining_envs.contouring.plant import ContouringParams, ContouringPlant
from machining_envs.contouring.scenarios import (
    CONTOURING_SCENARIOS,
    ContouringScenario,
    contouring_scenario,
)
from machining_envs.core.checks import PY_NUMBER_TYPES, check_range
from machining_envs.core.env import (
    ActionMap,
    EpisodeLog,
    check_render_mode,
    check_scenario_spec,
    present_frame,
    ready_to_render,
    record_step,
    resolve_params,
    resolve_reward,
    scenario_option,
)

__all__ = [
    "ContouringEnv",
    "ContouringReward",
    "check_action_vector",
    "render_xy",
    "render_trace",
    "TRACE_LOG_FIELDS",
    "ERROR_SCALE_MM",
    "POSITION_SCALE_MM",
    "VELOCITY_SCALE_MM_S",
    "PREVIEW_TICKS",
]

#: Tracking errors in observations are divided by this, mm.
ERROR_SCALE_MM = 1.0
#: Positions (the set point) in observations are divided by this, mm.
POSITION_SCALE_MM = 100.0
#: Velocities in observations are divided by this, mm/s.
VELOCITY_SCALE_MM_S = 100.0
#: The observation previews the set point this many servo periods ahead (0.2, 2 and 10 ms
#: at 5 kHz), as the mean reference velocity over each horizon.
PREVIEW_TICKS = (1, 10, 50)
_P0, _P1, _P2 = PREVIEW_TICKS

#: The signals the contouring envs' render() draws: name -> the info key each is read from.
TRACE_LOG_FIELDS = {"t": "t_s", "x": "x_mm", "y": "y_mm", "eps": "contour_error_mm"}

_CHUNK = 4096
_ERR_LIM = 100.0
_VEL_LIM = 10.0
_POS_LIM = 20.0
_PRE_LIM = 20.0


def check_action_vector(action, n: int, env_name: str) -> tuple[list[float], bool]:
    """The action as ``n`` floats in [-1, 1] and whether any had to be clipped.

    NaN or inf raise ``ValueError`` naming the env and the values; a wrong size raises
    ``ValueError``; finite values outside the box are clipped (the caller counts them).
    """
    if isinstance(action, np.ndarray) and action.shape == (n,):
        a = action
    else:
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.size != n:
            raise ValueError(
                f"{env_name}: action must hold {n} value(s), got shape {np.shape(action)}"
            )
    vals = a.tolist()
    clipped = False
    for i, v in enumerate(vals):
        if not math.isfinite(v):
            raise ValueError(f"{env_name}: action must be finite, got {a!r}")
        if v > 1.0:
            vals[i] = 1.0
            clipped = True
        elif v < -1.0:
            vals[i] = -1.0
            clipped = True
    return vals, clipped


@dataclass(frozen=True)
class ContouringReward:
    r"""Weights of the Contouring-v0 reward (see :class:`ContouringEnv`, section Rewards).

    .. math::

        r = -w_c \frac{\varepsilon}{\varepsilon_0} - w_t \frac{|e|}{e_0}
            - w_u \sum_{i=x,y} \left(\frac{\tau_i}{\tau_0}\right)^2 - w_d [\text{diverged}]

    with the contour error ``epsilon``, the tracking error ``|e| = |r - p|`` and the motor
    torques ``tau``.
    """

    contour: float = 1.0
    """w_c, weight of the contour error."""
    contour_scale_mm: float = 0.01
    """epsilon_0, mm: 10 um, a finishing tolerance."""
    tracking: float = 0.01
    """w_t, weight of the tracking error. Small but not zero: the contour error alone is
    zero for a table that never leaves the path's start."""
    tracking_scale_mm: float = 1.0
    """e_0, mm."""
    effort: float = 0.001
    """w_u, weight of the squared motor torques (the control effort the drive pays)."""
    torque_scale_Nm: float = 5.4
    """tau_0, N m: the rated torque of a 0.85 kW servo motor."""
    divergence: float = 100.0
    """w_d, one-off penalty when the run diverges."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            ok = isinstance(v, (int, float)) and math.isfinite(v) and v >= 0
            if f.name.endswith(("_mm", "_Nm")):
                ok = ok and v > 0
            if not ok:
                raise ValueError(
                    f"reward field {f.name} must be a finite number >= 0 "
                    f"(> 0 for scales), got {v!r}"
                )


#: ``_positive(name, value, lo, hi)``: ``value`` as a float if it is a Python number in
#: ``(lo, hi]``, else ``ValueError`` (the contouring envs' keyword checks).
_positive = functools.partial(check_range, lo_open=True, types=PY_NUMBER_TYPES)


def _run_limits(
    max_episode_time_s, in_position_mm, divergence_mm
) -> tuple[float | None, float, float]:
    """The keywords that end a contouring run, checked: ``(max_episode_time_s or None,
    in_position_mm, divergence_mm)`` as floats."""
    return (
        None
        if max_episode_time_s is None
        else _positive("max_episode_time_s", max_episode_time_s, 0.0, 1e4),
        _positive("in_position_mm", in_position_mm, 0.0, 10.0),
        _positive("divergence_mm", divergence_mm, 0.0, 1e4),
    )


def _circle_info(path: Path) -> dict:
    """The circle's centre and radius for a one-arc path (a circle test), else nothing."""
    c = path.circle()
    if c is None:
        return {}
    return {"circle_cx_mm": c[0], "circle_cy_mm": c[1], "circle_radius_mm": c[2]}


class ContouringEnv(gym.Env):
    """Two-axis contouring: command both feed axes so that the tool follows a path.

    ## Description
    The XY table of a machining centre (Choi et al., seed 004): each axis is a motor with a
    proportional velocity loop driving the table through a ball screw,
    ``G(s) = Ksp Kt / (J s^2 + Ksp Kt s)`` from the velocity command to the position, with
    the load torque of the cut as a disturbance (``machining_envs.contouring.plant``),
    discretised exactly at the 5 kHz servo rate. A set point runs along the toolpath at the
    programmed feed (or jumps, in the step tests); the agent is the position controller. The
    measure of quality is the **contour error**: the distance from the table's position to
    the path (``machining_envs.contouring.paths``), not to the current set point. The paper's
    controllers are in ``agents``: ``PIPosition`` and ``HInf2DOF``.

    ## Action Space
    ``Box(-1, 1, (2,), float32)``: the X and Y velocity commands, mapped affinely onto
    ``[-command_max, +command_max]`` mm/s (the motors' top speed through the screw lead,
    333 mm/s by default; ``action_to_command`` / ``command_to_action``). A finite action
    outside the box is clipped and counted in ``info["n_action_clipped"]``; NaN or inf
    raises ``ValueError``.

    ## Observation Space
    ``Box(float32, (14,))``, measured or known to the CNC only, normalised to order one:

    | index | observation | unit | range |
    |---|---|---|---|
    | 0-1 | tracking error ``r - p`` of X, Y / ``ERROR_SCALE_MM`` (1 mm) | - | [-100, 100] |
    | 2-3 | axis velocities / ``VELOCITY_SCALE_MM_S`` (100 mm/s) | - | [-10, 10] |
    | 4-5 | set point X, Y / ``POSITION_SCALE_MM`` (100 mm) | - | [-20, 20] |
    | 6-11 | preview: ``(r(t + k Ts) - r(t)) / (k Ts)`` / 100 mm/s for ``k`` = 1, 10, 50, X then Y | - | [-20, 20] |
    | 12-13 | previous action | - | [-1, 1] |

    The table's position is ``set point - tracking error``. The inertias and load torques are
    hidden (they are in ``info``).

    ## Rewards
    With the contour error ``eps`` (mm), the tracking error ``|e|`` (mm) and the mean motor
    torques ``tau`` (N m) over the period (weights in :class:`ContouringReward`, configurable
    with ``reward=``): ``r = -1.0 eps/0.01 - 0.01 |e|/1.0 - 0.001 sum (tau/5.4)^2
    - 100 [diverged]``. Benchmark metrics come from ``info``, not from rewards
    (``machining_envs.contouring.metrics``).

    ## Starting State
    Table at rest at the path's start; the scenario (path, feed, load steps, hidden
    inertias) is drawn from ``self.np_random``.

    ## Episode End
    Terminated when the set point has reached the path's end (plus the scenario's dwell)
    and the table is within ``in_position_mm`` of it (``info["finished"]``), or when the
    tracking error passes ``divergence_mm`` or a state goes non-finite
    (``info["diverged"]``). Truncated at ``max_episode_time_s`` (default: the reference's
    duration plus the dwell plus 0.5 s).

    ## Arguments
    ``gym.make("machining_envs/Contouring-v0", scenario="train", render_mode=None,
    params=None, reward=None, max_episode_time_s=None, in_position_mm=0.005,
    divergence_mm=50.0, **overrides)``: ``scenario`` is the default for resets without one
    (a name of ``CONTOURING_SCENARIOS`` or a ``ContouringScenario``); ``params`` a
    ``ContouringParams`` (nominal: what controllers are designed from); ``overrides`` change
    single fields of it (``screw_lead_mm=5``). Unknown keywords raise ``TypeError``;
    out-of-range values raise ``ValueError`` naming the parameter.

    Reset options: ``{"scenario": name_or_ContouringScenario}``.

    ## info
    ``t_s``, ``command`` (array of the two commands, mm/s), ``command_x_mm_s``,
    ``command_y_mm_s``, ``action_clipped``, ``n_action_clipped``, ``breakage`` (always False:
    no tool is at risk here), ``diverged``, ``finished``, ``x_mm``, ``y_mm``, ``x_ref_mm``,
    ``y_ref_mm``, ``contour_error_mm``, ``tracking_error_mm``, ``vx_mm_s``, ``vy_mm_s``,
    ``torque_x_Nm``, ``torque_y_Nm``, ``torque_sq_Nm2`` (sum of squares), ``load_x_Nm``,
    ``load_y_Nm``, ``path_s_mm`` (set point's arc length), ``path_length_mm``, ``segment``
    (path segment of the set point), ``feed_mm_s`` (0 for a step command), ``reference_end_s``, ``circle_cx_mm``,
    ``circle_cy_mm`` and ``circle_radius_mm`` (only when the path is one arc),
    ``scenario``, and ``machining_time_s`` (the cycle time) once finished.

    ## Version History
    * v0: first version.

    ## Example
    >>> import gymnasium as gym
    >>> import machining_envs
    >>> env = gym.make("machining_envs/Contouring-v0", scenario="paper_circle")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["x_mm"], info["circle_radius_mm"]
    ((14,), 10.0, 10.0)
    >>> obs, reward, terminated, truncated, info = env.step(np.zeros(2, dtype=np.float32))
    >>> info["t_s"], info["command_x_mm_s"], round(info["contour_error_mm"], 9)
    (0.0002, 0.0, 0.0)
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}
    #: Episode metrics and primary score of this env (``machining_envs.core.score.Task``).
    task = CONTOURING_TASK
    #: Positions of the observation's fields, for controllers that read them by name.
    OBS_INDEX = {"error": 0, "velocity": 2, "reference": 4, "preview": 6, "prev_action": 12}

    def __init__(
        self,
        scenario: str | ContouringScenario = "train",
        render_mode: str | None = None,
        params: ContouringParams | None = None,
        reward: ContouringReward | dict | None = None,
        max_episode_time_s: float | None = None,
        in_position_mm: float = 0.005,
        divergence_mm: float = 50.0,
        **overrides,
    ):
        self.params = resolve_params(
            type(self).__name__, params, ContouringParams, ContouringParams.choi_et_al, overrides
        )
        self.reward_weights = resolve_reward(reward, ContouringReward)
        self.max_episode_time_s, self.in_position_mm, self.divergence_mm = _run_limits(
            max_episode_time_s, in_position_mm, divergence_mm
        )
        check_scenario_spec(scenario, ContouringScenario, CONTOURING_SCENARIOS)
        self.default_scenario = scenario
        self.render_mode = check_render_mode(render_mode, self.metadata["render_modes"])

        umax = self.params.command_max_mm_s
        self.command_map = ActionMap(-umax, umax)
        self._umax = umax
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        lim = [_ERR_LIM] * 2 + [_VEL_LIM] * 2 + [_POS_LIM] * 2 + [_PRE_LIM] * 6 + [1.0] * 2
        high = np.array(lim, dtype=np.float32)
        self.observation_space = spaces.Box(-high, high, dtype=np.float32)
        self.scenario: ContouringScenario | None = None
        self.plant: ContouringPlant | None = None

    # ---- the command map, for classical agents -----------------------------------------
    def action_to_command(self, action):
        """Velocity commands (mm/s) for actions in [-1, 1]."""
        return self.command_map.action_to_command(action)

    def command_to_action(self, command):
        """Actions in [-1, 1] for velocity commands (mm/s)."""
        return self.command_map.command_to_action(command)

    # ---- gymnasium API -------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        spec = scenario_option(options, self.default_scenario)
        sc = contouring_scenario(spec, self.np_random)
        self.scenario = sc
        self._truth = sc.true_params(self.params)
        self.plant = ContouringPlant(self._truth)
        path = sc.path
        self._path = path
        ts = self.params.sample_time_s
        self._ts = ts
        self._ref_end = sc.reference_time_s
        t_max = self.max_episode_time_s
        if t_max is None:
            t_max = self._ref_end + sc.dwell_s + 0.5
        self._t_max = t_max
        self._n_max = int(math.ceil(t_max / ts - 1e-9))
        self._t_finish = self._ref_end + sc.dwell_s
        # Set points are computed in chunks as the run goes (a long path's whole schedule
        # would make every reset slow): ``_extend`` keeps them ahead of the preview.
        self._rx, self._ry, self._s, self._seg = [], [], [], []
        self._extend(PREVIEW_TICKS[-1] + 1)
        self._end = path.end
        x0, y0 = path.start
        self.plant.reset(x0, y0)
        self._k = 0
        self._loads = list(sc.load_steps)
        self._load_i = 0
        self._load = (0.0, 0.0)
        self._advance_load(0.0)
        self._prev_action = [0.0, 0.0]
        self._n_clipped = 0
        self._circle = _circle_info(path)
        self._pre_scale = [1.0 / (k * ts * VELOCITY_SCALE_MM_S) for k in PREVIEW_TICKS]
        self._log = EpisodeLog(TRACE_LOG_FIELDS)
        info = self._info(0.0, 0.0, 0.0, x0, y0, 0.0, 0.0, 0.0, 0.0, False, False, False)
        if self.render_mode is not None:
            self._log.record(info)
        return self._obs(x0, y0, 0.0, 0.0), info

    def _extend(self, n_needed: int) -> None:
        """Compute set points up to index ``n_needed`` (exclusive), a chunk at a time."""
        start = len(self._rx)
        stop = max(n_needed, start + _CHUNK)
        sc = self.scenario
        path = self._path
        k = np.arange(start, stop)
        if sc.is_step:
            s = np.full(k.size, path.length)
        else:
            s = np.minimum(k * (sc.feed_mm_s * self._ts), path.length)
        rx, ry = path.points(s)
        self._rx += rx.tolist()
        self._ry += ry.tolist()
        self._s += s.tolist()
        self._seg += path._index(s).tolist()

    def _advance_load(self, t: float) -> None:
        loads = self._loads
        while self._load_i < len(loads) and loads[self._load_i][0] <= t + 1e-12:
            _, a, b = loads[self._load_i]
            self._load = (a, b)
            self._load_i += 1

    def step(self, action):
        if self.plant is None:
            raise RuntimeError("ContouringEnv: call reset() before step()")
        (ax, ay), clipped = check_action_vector(action, 2, "ContouringEnv")
        self._n_clipped += clipped
        umax = self._umax
        ux, uy = ax * umax, ay * umax
        if self._load_i < len(self._loads):
            self._advance_load(self._k * self._ts)
        lx, ly = self._load
        s = self.plant.step(ux, uy, lx, ly)
        self._k += 1
        k = self._k
        if k + PREVIEW_TICKS[-1] >= len(self._rx):
            self._extend(k + PREVIEW_TICKS[-1] + 1)
        t = k * self._ts
        x, y = s.x_mm, s.y_mm
        diverged = not (
            math.isfinite(x)
            and math.isfinite(y)
            and math.isfinite(s.vx_mm_s)
            and math.isfinite(s.vy_mm_s)
        )
        rx, ry = self._rx[k], self._ry[k]
        if diverged:  # kept so that no NaN can reach an observation or a reward
            x, y = rx, ry
            vx = vy = tx = ty = 0.0
            self.plant.reset(rx, ry)
        else:
            vx, vy, tx, ty = s.vx_mm_s, s.vy_mm_s, s.torque_x_Nm, s.torque_y_Nm
        ex, ey = rx - x, ry - y
        etrack = math.hypot(ex, ey)
        eps = self._path.distance(x, y)
        diverged = diverged or etrack > self.divergence_mm
        finished = (
            t >= self._t_finish - 1e-12
            and math.hypot(x - self._end[0], y - self._end[1]) <= self.in_position_mm
        )
        terminated = diverged or finished
        truncated = (not terminated) and k >= self._n_max
        w = self.reward_weights
        t0 = w.torque_scale_Nm
        reward = (
            -w.contour * eps / w.contour_scale_mm
            - w.tracking * etrack / w.tracking_scale_mm
            - w.effort * ((tx / t0) ** 2 + (ty / t0) ** 2)
        )
        if diverged:
            reward -= w.divergence
        self._prev_action = [ax, ay]
        info = self._info(t, ux, uy, x, y, vx, vy, tx, ty, clipped, diverged, finished)
        info["contour_error_mm"] = eps
        info["tracking_error_mm"] = etrack
        if finished:
            info["machining_time_s"] = t
        record_step(self, self._log, info)
        return self._obs(x, y, vx, vy), float(reward), terminated, truncated, info

    # ---- helpers -------------------------------------------------------------------------
    def _obs(self, x: float, y: float, vx: float, vy: float) -> np.ndarray:
        k = self._k
        rx, ry = self._rx, self._ry
        r0x, r0y = rx[k], ry[k]
        ps = self._pre_scale
        # The preview cannot leave its bounds (feeds are at most 1000 mm/s); the rest can
        # (a diverging run, or a drive overridden to more than 1000 mm/s).
        ex = (r0x - x) / ERROR_SCALE_MM
        ey = (r0y - y) / ERROR_SCALE_MM
        px = r0x / POSITION_SCALE_MM
        py = r0y / POSITION_SCALE_MM
        o = [
            min(max(ex, -_ERR_LIM), _ERR_LIM),
            min(max(ey, -_ERR_LIM), _ERR_LIM),
            min(max(vx / VELOCITY_SCALE_MM_S, -_VEL_LIM), _VEL_LIM),
            min(max(vy / VELOCITY_SCALE_MM_S, -_VEL_LIM), _VEL_LIM),
            min(max(px, -_POS_LIM), _POS_LIM),
            min(max(py, -_POS_LIM), _POS_LIM),
            (rx[k + _P0] - r0x) * ps[0],
            (rx[k + _P1] - r0x) * ps[1],
            (rx[k + _P2] - r0x) * ps[2],
            (ry[k + _P0] - r0y) * ps[0],
            (ry[k + _P1] - r0y) * ps[1],
            (ry[k + _P2] - r0y) * ps[2],
            *self._prev_action,
        ]
        return np.array(o, dtype=np.float32)

    def _info(self, t, ux, uy, x, y, vx, vy, tx, ty, clipped, diverged, finished) -> dict:
        k = self._k
        sc = self.scenario
        info = {
            "t_s": t,
            "command": np.array([ux, uy]),
            "command_x_mm_s": ux,
            "command_y_mm_s": uy,
            "action_clipped": bool(clipped),
            "n_action_clipped": self._n_clipped,
            "breakage": False,
            "diverged": bool(diverged),
            "finished": bool(finished),
            "x_mm": x,
            "y_mm": y,
            "x_ref_mm": self._rx[k],
            "y_ref_mm": self._ry[k],
            "contour_error_mm": 0.0,
            "tracking_error_mm": math.hypot(self._rx[k] - x, self._ry[k] - y),
            "vx_mm_s": vx,
            "vy_mm_s": vy,
            "torque_x_Nm": tx,
            "torque_y_Nm": ty,
            "torque_sq_Nm2": tx * tx + ty * ty,
            "load_x_Nm": self._load[0],
            "load_y_Nm": self._load[1],
            "path_s_mm": self._s[k],
            "path_length_mm": self._path.length,
            "segment": self._seg[k],
            "feed_mm_s": 0.0 if sc.is_step else sc.feed_mm_s,
            "reference_end_s": self._ref_end,
            "scenario": sc.name,
        }
        info.update(self._circle)
        return info

    def render(self):
        if not ready_to_render(self, "ContouringEnv"):
            return None
        img = render_trace(self._path, self._log, f"Contouring-v0 | {self.scenario.name}")
        return present_frame(img, self.render_mode, "Contouring-v0")


def render_trace(path: Path, log: EpisodeLog, title: str) -> np.ndarray:
    """:func:`render_xy` of an episode recorded with :data:`TRACE_LOG_FIELDS`."""
    return render_xy(
        path,
        np.array(log["x"]),
        np.array(log["y"]),
        np.array(log["t"]),
        np.array(log["eps"]),
        title,
    )


def render_xy(path: Path, x, y, t, eps, title: str) -> np.ndarray:
    """XY plot of the path and the table's trace with the contour error magnified, above
    the contour error against time; returned as an RGB array."""
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - matplotlib is a dependency
        raise ImportError("rendering needs matplotlib: pip install matplotlib") from exc
    fig = Figure(figsize=(6, 7), dpi=80)
    canvas = FigureCanvasAgg(fig)
    ax1, ax2 = fig.subplots(2, 1, gridspec_kw={"height_ratios": [2.2, 1]})
    s = np.linspace(0.0, path.length, 800)
    px, py = path.points(s)
    ax1.plot(px, py, "k--", lw=0.8, label="path")
    if len(x):
        d, qx, qy = path.closest_many(x, y)
        xmin, xmax, ymin, ymax = path.bounds()
        size = max(xmax - xmin, ymax - ymin, 1e-6)
        emax = float(np.max(d)) if d.size else 0.0
        gain = 1.0
        if emax > 0:
            # Magnify so that the largest error shows as 5 % of the path's size (10^n steps).
            gain = 10.0 ** max(0.0, math.floor(math.log10(0.05 * size / emax)))
        ax1.plot(
            qx + gain * (x - qx),
            qy + gain * (y - qy),
            "C0-",
            lw=1.2,
            label=f"table (error x{gain:g})",
        )
        ax2.plot(t, 1000.0 * np.asarray(eps), "C0-", lw=1.0)
    ax1.set_aspect("equal", adjustable="datalim")
    ax1.set_xlabel("X (mm)")
    ax1.set_ylabel("Y (mm)")
    ax1.legend(fontsize=8, loc="best")
    ax1.set_title(title, fontsize=10)
    ax1.grid(alpha=0.3)
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("contour error (um)")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
