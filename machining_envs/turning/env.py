"""``machining_envs/Turning-v0``: cut as fast as the cutting-force limit allows, by the feed."""

from __future__ import annotations

from machining_envs.core.actuation import (
    Actuation,
)
from machining_envs.core.env import FeedRegulationEnv
from machining_envs.core.lanes import REGULATION_OBS_INDEX
from machining_envs.core.sensors import PowerSensor
from machining_envs.core.vector import (
    LaneVectorEnv,
)
from machining_envs.turning.lanes import (
    TurningCore,
    TurningReward,
)
from machining_envs.turning.metrics import TURNING_TASK
from machining_envs.turning.plant import (
    TurningParams,
)
from machining_envs.turning.scenarios import (
    TurningScenario,
)

__all__ = ["TurningEnv", "TurningVectorEnv", "TurningReward"]


class TurningEnv(FeedRegulationEnv):
    """Turning as fast as the cutting-force limit allows, by feed (Noh, Kim & Kim 1992).

    ## Description
    A lathe turns an SM45C bar with a carbide tool. The depth of cut changes along the bar
    (pre-machined steps, tapers); the controller commands the feed servo to cut the bar as
    fast as it can while the main cutting force stays under the scenario's process limit
    (1 kN, the force the paper's controllers regulated at). The controller sees the limit and
    chooses where to regulate below it.
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
    | 1 | force limit / ``force_scale_N`` | - | [0, 10] |
    | 2 | previous action (the command now applied) | - | [-1, 1] |
    | 3 | spindle speed / 1000 rpm | - | [0, 3] |
    | 4-6 | measured force one, two, three samples ago / ``force_scale_N`` | - | [-1, 10] |

    The depth of cut, the feed and the true process constants are hidden (they are in
    ``info``).

    ## Rewards
    With ``F`` the cutting force at the sample instant, ``L`` the limit, ``dx`` the distance
    fed in the step and ``Vmax`` the servo's top feed velocity (weights in
    :class:`TurningReward`, configurable with ``reward=``):
    ``r = -1.0 |F/(0.9 L) - 1| - 4.0 max(0, F/L - 1) + 0.0 dx/(Ts Vmax) - 50 [breakage]``.
    The weights, and the setpoint 0.9 L that is the reward's own (a training choice, not the
    task's), are a :class:`~machining_envs.core.reward.LimitReward` (``TurningReward`` here).

    ## Cost and score
    ``info["cost"]`` is 1.0 on a step whose force sample is above the limit, else 0.0 (the
    Safety-Gymnasium convention); ``info["excess"]`` is how far over (force / limit - 1 on
    such a step, else 0) and ``info["overload_ratio"]`` the scenario's overload ceiling (an
    episode past it does not count: ``docs/benchmark.md``).
    The task's score (``task``, ``machining_envs.core.score``)
    is the machining time, counted if the bar was finished, the tool did not break and
    under 2 % of the steps had a cost; else the time limit is charged.
    ``info["score_bound"]`` is the floor of the machining time from the cut's truth
    (``machining_time_bound``): the force exactly at the limit everywhere, within the
    servo's top speed.

    ## Starting State
    Tool at the start of the workpiece, feed at rest, force zero; the scenario (workpiece,
    spindle speed, hidden Kf and p, noise) is drawn from ``self.np_random``.

    ## Episode End
    Terminated when the workpiece is cut to its end (``info["finished"]``), when the force
    passes ``breakage_force_N`` at any 2 ms sub-step (``info["breakage"]``), or when a state
    goes non-finite (``info["diverged"]``). Truncated at ``max_episode_time_s``.

    ## Arguments
    ``gym.make("machining_envs/Turning-v0", scenario="train", render_mode=None,
    params=None, spindle_rpm=None, reward=None, max_episode_time_s=200.0, actuation=None,
    power_sensor=None, **overrides)``:
    ``scenario`` is the default for resets without one (a name of ``TURNING_SCENARIOS`` or a
    ``TurningScenario``); ``params`` a ``TurningParams`` (nominal: what controllers are
    designed from); ``overrides`` change single fields of it (``sensor_gain=15``);
    ``spindle_rpm`` fixes the spindle speed of every scenario; ``actuation`` (off by
    default) puts a real CNC between the action and the servo: interpolator delay, override
    quantisation and rate limit (``machining_envs.core.actuation.Actuation`` or a dict,
    e.g. ``{"quantum": 0.01, "max_rate_per_s": 2.0, "delay_steps": 2}``; ``info["command"]``
    is then what the servo got); ``power_sensor`` (off by default) shows the spindle drive's
    power reading in the load channels instead of the dynamometer's force, and the limit as
    a power (``machining_envs.core.sensors.PowerSensor``, a dict of its fields or ``True``
    for the defaults; ``info`` adds ``spindle_power_measured_W`` and ``power_limit_W``;
    the task, its cost and its score stay on the force). Unknown keywords raise
    ``TypeError``; out-of-range values raise ``ValueError`` naming the parameter.

    Reset options: ``{"scenario": name_or_TurningScenario}``.

    ## info
    ``t_s``, ``command`` (U, counts), ``action_clipped``, ``n_action_clipped``,
    ``breakage``, ``diverged``, ``finished``, ``force_N`` (true force), ``force_limit_N``,
    ``cost``, ``score_bound`` (s),
    ``measured`` (force the controller saw, N), ``measured_counts``, ``peak_force_N``
    (the largest force over the sample's sub-steps, N), ``feed_mm_per_rev``,
    ``feed_velocity_mm_s``, ``depth_mm``, ``spindle_rpm``, ``position_mm``, ``segment``
    (index of the workpiece segment being cut), ``workpiece_length_mm``, ``scenario``, and
    ``machining_time_s`` once the cut is finished.

    ## Vector env
    ``gym.make_vec("machining_envs/Turning-v0", num_envs=N)`` gives a
    :class:`TurningVectorEnv`: N lathes stepped by one compiled kernel, lane ``i`` after
    ``reset(seed=s)`` exactly this env after ``reset(seed=s + i)``.

    ## Version History
    * v0: first version. The physics now runs as a batched kernel shared with the vector
      env (same numbers to the last bit); the sensor noise is drawn by the kernel from
      ``np_random``, one normal a step (the normals of the first implementation, in the
      same order within an episode; the episodes of an unseeded reset after the first
      differ from those of the versions that drew the noise in blocks).
      The task is a process limit, not a reference: scenarios carry ``force_limit_N``
      (was ``force_ref_N``), observation 1 is the limit, ``info`` gives ``force_limit_N``,
      ``cost`` and ``score_bound``; the reward tracks ``target`` x limit and penalises
      force above the limit (was above 1.1x the reference); the scenarios ``train``,
      ``validation``, ``test`` (one distribution, separate streams) and ``ood`` (the
      former ``test`` ranges, varying limit) replace ``train``/``test``.

    ## Example
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> import machining_envs
    >>> env = gym.make("machining_envs/Turning-v0", scenario="paper_405")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["depth_mm"], info["spindle_rpm"]
    ((7,), 1.0, 405.0)
    >>> obs, reward, terminated, truncated, info = env.step(np.array([0.0], dtype=np.float32))
    >>> round(info["command"]), info["t_s"]
    (2048, 0.1)
    """

    _ID = "Turning-v0"
    #: Episode metrics and primary score of this env (``machining_envs.core.score.Task``).
    task = TURNING_TASK
    #: Positions of the observation's fields, for controllers that read them by name.
    OBS_INDEX = REGULATION_OBS_INDEX
    _LOAD = ("force_N", "force (N)", "cutting force")
    _DEPTH_LABEL = "depth of cut (mm)"

    def __init__(
        self,
        scenario: str | TurningScenario = "train",
        render_mode: str | None = None,
        params: TurningParams | None = None,
        spindle_rpm: float | None = None,
        reward: TurningReward | dict | None = None,
        max_episode_time_s: float = 200.0,
        actuation: Actuation | dict | None = None,
        power_sensor: PowerSensor | dict | bool | None = None,
        **overrides,
    ):
        core = self._open(TurningCore, locals())  # the core's options by their names
        self.spindle_rpm_override = core.spindle_rpm_override

    def _limit(self) -> float:
        return self._core.force_limit[0]

    def _title(self) -> str:
        return f"Turning-v0 | {self.scenario.name} | {self.scenario.spindle_rpm:.0f} rpm"


class TurningVectorEnv(LaneVectorEnv):
    """``machining_envs/Turning-v0`` as a native vector env: N lathes stepped as arrays,
    each lane exactly :class:`TurningEnv` with the lane's seed; its arguments are
    ``TurningEnv``'s (not ``render_mode``), ``num_threads`` and ``autoreset_mode``
    (:class:`~machining_envs.core.vector.LaneVectorEnv`).
    """

    # A lane's sample costs about 0.5 µs compiled (50 sub-steps), so a block of 64 lanes
    # is some 30 µs of work, well above handing it to a thread: at N = 128-192 on two
    # threads two blocks step 13-15 % faster than one.
    min_block = 64

    single_env = TurningEnv
    core_cls = TurningCore
