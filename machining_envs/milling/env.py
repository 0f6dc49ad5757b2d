"""``machining_envs/EndMilling-v0``: mill as fast as the cutting-torque limit allows, by the feed."""

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
from machining_envs.milling.lanes import (
    MillingCore,
    MillingReward,
)
from machining_envs.milling.metrics import MILLING_TASK
from machining_envs.milling.plant import (
    MillingParams,
)
from machining_envs.milling.scenarios import (
    MillingScenario,
)

__all__ = ["EndMillingEnv", "EndMillingVectorEnv", "MillingReward"]


class EndMillingEnv(FeedRegulationEnv):
    """End milling as fast as the cutting-torque limit allows, by feed (Park & Yoon 1986).

    ## Description
    A vertical machining centre end-mills SM45C steel with a 16 mm, 4-tooth HSS end mill
    (up-milling, 32 mm axial depth, 400 rpm). The radial depth of cut changes along the
    workpiece (the paper's steps and tapers, or random profiles); the controller commands the
    CNC feed to mill the workpiece as fast as it can while the cutting torque stays under the
    scenario's process limit (the paper's reference torque by default). The controller sees
    the limit and chooses where to regulate below it. The plant is ``machining_envs.milling.plant``: a second-order CNC feed servo
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
    torques are multiples of this cut's limit ``L``, so that running at a share of the limit
    looks the same at every limit; the limit itself is a multiple of the nominal
    ``Tn = params.torque_limit_Nmm``.

    | index | observation | unit | range |
    |---|---|---|---|
    | 0 | measured torque (lagged, noisy) / L | - | [-1, 10] |
    | 1 | torque limit L / Tn | - | [0, 10] |
    | 2 | previous action (the command now applied) | - | [-1, 1] |
    | 3 | spindle speed / 1000 rpm | - | [0, 6] |
    | 4-6 | measured torque one, two, three samples ago / L | - | [-1, 10] |

    The radial depth, the feed and the true process constants are hidden (they are in
    ``info``).

    ## Rewards
    With ``T`` the cutting torque at the sample instant, ``L`` the limit, ``Vf`` the
    feed velocity and ``Vmax`` the servo's top feed velocity (weights in
    :class:`MillingReward`, configurable with ``reward=``):
    ``r = -1.0 |T/(0.9 L) - 1| - 4.0 max(0, T/L - 1) + 0.0 Vf/Vmax - 50 [breakage]``.
    The weights, and the setpoint 0.9 L that is the reward's own (a training choice, not the
    task's), are a :class:`~machining_envs.core.reward.LimitReward` (``MillingReward`` here).

    ## Cost and score
    ``info["cost"]`` is 1.0 on a step whose torque sample is above the limit, else 0.0 (the
    Safety-Gymnasium convention); ``info["excess"]`` is how far over (torque / limit - 1 on
    such a step, else 0) and ``info["overload_ratio"]`` the scenario's overload ceiling (an
    episode past it does not count: ``docs/benchmark.md``).
    The score (``task``) is the machining time, counted if the
    workpiece was finished, the tool did not break and under 2 % of the steps had a cost;
    else the time limit is charged. ``info["score_bound"]`` is the floor of the machining
    time from the cut's truth (``machining_time_bound``).

    ## Starting State
    Tool at the start of the workpiece, feed at rest, torque zero; the scenario (workpiece,
    spindle speed, torque limit, hidden Ks and m, noise) is drawn from ``self.np_random``.

    ## Episode End
    Terminated when the workpiece is cut to its end (``info["finished"]``), when the torque
    passes ``breakage_torque_Nmm`` at any 10 ms sub-step (``info["breakage"]``), or when a
    state goes non-finite (``info["diverged"]``). Truncated at ``max_episode_time_s``.

    ## Arguments
    ``gym.make("machining_envs/EndMilling-v0", scenario="train", render_mode=None,
    params=None, reward=None, max_episode_time_s=1200.0, action_map="log", actuation=None,
    **overrides)``:
    ``scenario`` is the default for resets without one (a name of ``MILLING_SCENARIOS`` or
    a ``MillingScenario``); ``action_map`` is ``"log"`` or ``"linear"`` (Action Space);
    ``actuation`` (off by default: the papers' ideal actuator) puts a real CNC's feed
    override between the command and the servo: delay, quantisation, rate and acceleration
    limits (``machining_envs.core.actuation.Actuation`` or a dict of its fields; a
    scenario's own ``actuation``, as in the ``shopfloor`` split, wins for its episode);
    ``power_sensor`` (off by default) shows the spindle drive's power reading in the load
    channels instead of the torque sensor's, and the limit as a power
    (``machining_envs.core.sensors.PowerSensor``, a dict of its fields or ``True``; ``info``
    adds ``spindle_power_measured_W`` and ``power_limit_W``; the task stays on the torque);
    ``params`` a ``MillingParams`` (nominal: what controllers are
    designed from; ``MillingParams.ahn_choi_al6061()`` for the Al6061 set); ``overrides``
    change single fields of it (``servo_gain=0.025``, ``force_model="average_force"``,
    ``spindle_rpm=500``). Unknown keywords raise ``TypeError``; out-of-range values raise
    ``ValueError`` naming the parameter.

    Reset options: ``{"scenario": name_or_MillingScenario}``.

    ## info
    ``t_s``, ``command`` (U, counts), ``action_clipped``, ``n_action_clipped``,
    ``breakage``, ``diverged``, ``finished``, ``torque_Nmm`` (true torque),
    ``torque_limit_Nmm``, ``cost``, ``score_bound`` (s), ``measured`` (torque the
    controller saw, N·mm),
    ``measured_counts``, ``peak_torque_Nmm`` (the largest torque over the sample's
    sub-steps), ``feed_mm_per_rev`` (at the sample instant),
    ``mean_feed_mm_per_rev`` (over the last sample: the f(i) of eq. 20),
    ``feed_per_tooth_mm``, ``feed_velocity_mm_s``, ``depth_mm`` (radial), ``spindle_rpm``,
    ``position_mm``, ``segment`` (index of the workpiece segment being cut),
    ``removed_volume_mm3``, ``workpiece_length_mm``, ``workpiece_volume_mm3``,
    ``scenario``, and ``machining_time_s`` once the cut is finished.

    ## Vector env
    ``gym.make_vec("machining_envs/EndMilling-v0", num_envs=N)`` gives an
    :class:`EndMillingVectorEnv`: N machining centres stepped by one compiled kernel, lane
    ``i`` after ``reset(seed=s)`` exactly this env after ``reset(seed=s + i)``.

    ## Version History
    * v0: first version. The physics now runs as a batched kernel shared with the vector
      env (same numbers to the last bit); the sensor noise is drawn by the kernel from
      ``np_random``, one normal a step (the normals of the first implementation, in the
      same order within an episode; the episodes of an unseeded reset after the first
      differ from those of the versions that drew the noise in blocks).
      The task is a process limit, not a reference: ``MillingParams.torque_limit_Nmm`` and
      the scenarios' ``torque_limit_scale`` (were ``torque_ref_*``), observation 1 is the
      limit, ``info`` gives ``torque_limit_Nmm``, ``cost`` and ``score_bound``; the reward
      tracks ``target`` x limit and penalises torque above the limit (was above 1.1x the
      reference); the scenarios ``train``, ``validation``, ``test`` (one distribution,
      separate streams) and ``ood`` (the former ``test`` ranges) replace ``train``/``test``.

    ## Example
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> import machining_envs
    >>> env = gym.make("machining_envs/EndMilling-v0", scenario="paper_step")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["depth_mm"], info["spindle_rpm"], info["torque_limit_Nmm"]
    ((7,), 1.0, 400.0, 3600.0)
    >>> action = np.array([env.unwrapped.command_to_action(7.5)], dtype=np.float32)
    >>> obs, reward, terminated, truncated, info = env.step(action)
    >>> round(info["command"], 3), info["t_s"]
    (7.5, 0.1)
    """

    _ID = "EndMilling-v0"
    #: Episode metrics and primary score of this env (``machining_envs.core.score.Task``).
    task = MILLING_TASK
    #: Positions of the observation's fields, for controllers that read them by name.
    OBS_INDEX = REGULATION_OBS_INDEX
    _LOAD = ("torque_Nmm", "torque (N·mm)", "cutting torque")
    _DEPTH_LABEL = "radial depth (mm)"

    def __init__(
        self,
        scenario: str | MillingScenario = "train",
        render_mode: str | None = None,
        params: MillingParams | None = None,
        reward: MillingReward | dict | None = None,
        max_episode_time_s: float = 1200.0,
        action_map: str = "log",
        actuation: Actuation | dict | None = None,
        power_sensor: PowerSensor | dict | bool | None = None,
        **overrides,
    ):
        self._open(MillingCore, locals())  # the core's options by their names

    def _limit(self) -> float:
        return float(self._core.torque_limit[0])

    def _title(self) -> str:
        return f"EndMilling-v0 | {self.scenario.name} | {float(self._core.spindle[0]):.0f} rpm"


class EndMillingVectorEnv(LaneVectorEnv):
    """``machining_envs/EndMilling-v0`` as a native vector env: N end-milling cuts stepped
    as arrays, each lane exactly :class:`EndMillingEnv` with the lane's seed; its arguments
    are ``EndMillingEnv``'s (not ``render_mode``), ``num_threads`` and ``autoreset_mode``
    (:class:`~machining_envs.core.vector.LaneVectorEnv`).
    """

    single_env = EndMillingEnv
    core_cls = MillingCore
