"""``machining_envs/Contouring-v0``: drive both axes of an XY table along a toolpath."""

from __future__ import annotations

import math

import numpy as np

from machining_envs.contouring.lanes import (
    ERROR_SCALE_MM,
    POSITION_SCALE_MM,
    PREVIEW_TICKS,
    TRACE_LOG_FIELDS,
    VELOCITY_SCALE_MM_S,
    ContouringCore,
    ContouringReward,
)
from machining_envs.contouring.metrics import CONTOURING_TASK
from machining_envs.contouring.paths import (
    Path,
)
from machining_envs.contouring.plant import (
    ContouringParams,
    ContouringPlant,
)
from machining_envs.contouring.scenarios import (
    ContouringScenario,
)
from machining_envs.core.actions import check_action_vector
from machining_envs.core.env import LaneEnv
from machining_envs.core.rendering import (
    EpisodeLog,
)
from machining_envs.core.vector import (
    LaneVectorEnv,
)

__all__ = [
    "ContouringEnv",
    "ContouringVectorEnv",
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
class ContouringEnv(LaneEnv):
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

    ## Vector env
    ``gym.make_vec("machining_envs/Contouring-v0", num_envs=N)`` gives a
    :class:`ContouringVectorEnv`: N tables stepped by one compiled function, lane ``i``
    after ``reset(seed=s)`` exactly this env after ``reset(seed=s + i)``.

    ## Version History
    * v0: first version. The step now runs compiled, shared with the vector env (the same
      numbers to the last bit). ``info`` gives ``contour_tolerance_mm``
      (``CONTOUR_TOLERANCE_MM``, 10 µm), ``cost`` (1 on a servo period whose contour error
      is above it), ``excess`` (error / tolerance - 1 there, else 0) and ``overload_ratio``
      (the scenario's overload ceiling, ``docs/benchmark.md``); no ``score_bound`` (the floor of a contour error is zero); the
      scenarios ``train``, ``validation``, ``test`` (one distribution, separate streams)
      and ``ood`` (the former ``test`` ranges) replace ``train``/``test``.

    ## Example
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> import machining_envs
    >>> env = gym.make("machining_envs/Contouring-v0", scenario="paper_circle")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["x_mm"], info["circle_radius_mm"]
    ((14,), 10.0, 10.0)
    >>> obs, reward, terminated, truncated, info = env.step(np.zeros(2, dtype=np.float32))
    >>> info["t_s"], info["command_x_mm_s"], round(info["contour_error_mm"], 9)
    (0.0002, 0.0, 0.0)
    """

    _ID = "Contouring-v0"
    #: Episode metrics and primary score of this env (``machining_envs.core.score.Task``).
    task = CONTOURING_TASK
    #: Positions of the observation's fields, for controllers that read them by name.
    OBS_INDEX = {"error": 0, "velocity": 2, "reference": 4, "preview": 6, "prev_action": 12}
    _LOG_FIELDS = TRACE_LOG_FIELDS

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
        core = self._open(ContouringCore, locals())  # the core's options by their names
        self.in_position_mm = core.in_position_mm
        self.divergence_mm = core.divergence_mm
        self._umax = self.params.command_max_mm_s
        self.plant: ContouringPlant | None = None

    def _began(self, core) -> None:
        #: The table of this episode (its true parameters in ``plant.params``).
        self.plant = core.plants[0]
        self._path = self.scenario.path

    def _set_action(self, action) -> None:
        self._core.set_action(0, *check_action_vector(action, 2, "ContouringEnv"))

    def _draw(self):
        return render_trace(self._path, self._log, f"Contouring-v0 | {self.scenario.name}")


class ContouringVectorEnv(LaneVectorEnv):
    """``machining_envs/Contouring-v0`` as a native vector env: N XY tables, each on its own
    path with its own hidden inertias and loads, stepped by one compiled function, each
    lane exactly :class:`ContouringEnv` with the lane's seed (the circle's keys and
    ``machining_time_s`` come with masks); its arguments are ``ContouringEnv``'s (not
    ``render_mode``), ``num_threads`` and ``autoreset_mode``
    (:class:`~machining_envs.core.vector.LaneVectorEnv`).
    """

    single_env = ContouringEnv
    core_cls = ContouringCore


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
