"""``machining_envs/ContouringFeed-v0``: choose the feed override along a toolpath while the
CNC's own position loop (PI or H-infinity) drives the axes."""

from __future__ import annotations

from machining_envs.contouring.env import (
    TRACE_LOG_FIELDS,
    check_action_vector,
    render_trace,
)
from machining_envs.contouring.feed_lanes import (
    DEFAULT_TOLERANCE_MM,
    LOOKAHEAD_MM,
    FeedCore,
    FeedReward,
)
from machining_envs.contouring.metrics import FEED_TASK
from machining_envs.contouring.plant import ContouringParams
from machining_envs.contouring.scenarios import (
    ContouringScenario,
)
from machining_envs.core.actuation import (
    Actuation,
)
from machining_envs.core.env import LaneEnv
from machining_envs.core.vector import (
    LaneVectorEnv,
)

__all__ = ["ContouringFeedEnv", "ContouringFeedVectorEnv", "FeedReward", "LOOKAHEAD_MM"]
__all__ += ["DEFAULT_TOLERANCE_MM"]


class ContouringFeedEnv(LaneEnv):
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

    ## Cost and score
    The limit is the contour-error tolerance ``tolerance_mm`` (the errors are observed as
    multiples of it). ``info["cost"]`` is 1.0 on a step whose largest contour error passed
    it; ``info["excess"]`` is how far (error / tolerance - 1 on such a step, else 0) and
    ``info["overload_ratio"]`` the scenario's overload ceiling (a run past it does not
    count: ``docs/benchmark.md``). The score (``task``) is the cycle time, counted if the run finished without
    diverging and under 2 % of its steps had a cost; else the run's time limit is charged.
    ``info["score_bound"]`` is the floor of the cycle time: the path at the largest override
    of the programmed feed (``override_max x F``; the drives' acceleration is left out, so
    the floor is loose on tight curves).

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
    actuation=None, **overrides)``: ``actuation`` (off by default: the override takes
    effect as asked) puts a real CNC's override handling between the action and the
    interpolator: delay in decisions, quantisation, rate and acceleration limits
    (``machining_envs.core.actuation.Actuation`` or a dict of its fields, as shares of
    ``[0, override_max]``; a scenario's own ``actuation``, as in the ``shopfloor`` split,
    wins for its episode), and ``info["feed_override"]`` is the override applied; ``servo``
    is ``"hinf"`` (``agents.HInf2DOF``'s design, the default) or
    ``"pi"`` (``agents.PIPosition``'s); ``tolerance_mm`` defaults to
    ``DEFAULT_TOLERANCE_MM[servo]`` (5 um for H-infinity, 50 um for PI); ``overrides`` change
    fields of ``ContouringParams``. Unknown keywords raise ``TypeError``; out-of-range values
    raise ``ValueError`` naming the parameter.

    ## info
    The keys of ``Contouring-v0`` at the step's end (``x_mm``, ``contour_error_mm``,
    ``command``...; ``torque_sq_Nm2`` is the step's mean) plus ``peak_contour_error_mm``
    (largest over the step), ``contour_tolerance_mm``, ``cost``, ``score_bound`` (s),
    ``feed_override``, ``path_speed_mm_s``,
    ``servo``, ``programmed_time_s`` (path length over programmed feed), ``time_limit_s``
    (this episode's truncation time), and ``machining_time_s`` (the cycle time, to the servo
    period) once finished.

    ## Vector env
    ``gym.make_vec("machining_envs/ContouringFeed-v0", num_envs=N)`` gives a
    :class:`ContouringFeedVectorEnv`: N tables stepped by one compiled function, lane ``i``
    after ``reset(seed=s)`` exactly this env after ``reset(seed=s + i)``.

    ## Version History
    * v0: first version. The step now runs compiled, shared with the vector env: the 50
      servo periods of a step run as the closed loop's recursion, eight values of a
      matrix column at a time in vector registers (the numbers agree with the block's
      lifted linear map to rounding; the golden data were recorded anew).
      The contour tolerance is the task's limit: ``info["contour_tolerance_mm"]`` (was
      ``tolerance_mm``), ``cost`` (1 on a step whose largest contour error is above it) and
      ``score_bound`` (the path at the largest override of the programmed feed); the
      scenarios ``train``, ``validation``, ``test`` and ``ood`` replace ``train``/``test``.

    ## Example
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> import machining_envs
    >>> env = gym.make("machining_envs/ContouringFeed-v0", scenario="paper_circle")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["contour_tolerance_mm"], info["servo"]
    ((16,), 0.005, 'hinf')
    >>> obs, reward, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
    >>> round(info["t_s"], 6), info["feed_override"], round(info["path_s_mm"], 6)
    (0.01, 1.0, 0.5)
    """

    _ID = "ContouringFeed-v0"
    #: Episode metrics and primary score of this env (``machining_envs.core.score.Task``).
    task = FEED_TASK
    _LOG_FIELDS = TRACE_LOG_FIELDS

    def __init__(
        self,
        scenario: str | ContouringScenario = "train",
        render_mode: str | None = None,
        *,
        params: ContouringParams | None = None,
        servo: str = "hinf",
        tolerance_mm: float | None = None,
        reward: FeedReward | dict | None = None,
        decision_interval_s: float = 0.01,
        override_max: float = 2.0,
        max_episode_time_s: float | None = None,
        in_position_mm: float = 0.005,
        divergence_mm: float = 50.0,
        actuation: Actuation | dict | None = None,
        **overrides,
    ):
        core = self._open(FeedCore, locals())  # the core's options by their names
        self.servo = core.servo
        self.tolerance_mm = core.tolerance_mm
        self.decision_interval_s = core.decision_interval_s
        self._n_sub = core.n_sub
        self.override_max = core.override_max
        self.in_position_mm = core.in_position_mm
        self.divergence_mm = core.divergence_mm

    def _began(self, core) -> None:
        self._path = self.scenario.path

    def _set_action(self, action) -> None:
        self._core.set_action(0, *check_action_vector(action, 1, "ContouringFeedEnv"))

    def _draw(self):
        return render_trace(
            self._path,
            self._log,
            f"ContouringFeed-v0 | {self.scenario.name} | servo {self.servo}",
        )


class ContouringFeedVectorEnv(LaneVectorEnv):
    """``machining_envs/ContouringFeed-v0`` as a native vector env: N tables, each on its
    own path with its own hidden inertias and loads, stepped by one compiled function, each
    lane exactly :class:`ContouringFeedEnv` with the lane's seed (the circle's keys and
    ``machining_time_s`` come with masks); its arguments are ``ContouringFeedEnv``'s (not
    ``render_mode``), ``num_threads`` and ``autoreset_mode``
    (:class:`~machining_envs.core.vector.LaneVectorEnv`).
    """

    # A lane's decision costs about 1.3 µs compiled (50 servo periods), so a block of 64
    # lanes is some 80 µs of work: at N = 128-192 on two threads two blocks step 22-33 %
    # faster than one.
    min_block = 64

    single_env = ContouringFeedEnv
    core_cls = FeedCore

    def _took(self, core) -> None:
        self.servo = core.servo
        self.tolerance_mm = core.tolerance_mm
        self.override_max = core.override_max
