"""``machining_envs/MicroDrilling-v0``: hold the drilling torque by the spindle speed (or feed)."""

from __future__ import annotations

from machining_envs.core.actions import check_action_vector
from machining_envs.core.env import LaneEnv
from machining_envs.core.rendering import (
    render_signals,
)
from machining_envs.core.vector import (
    LaneVectorEnv,
)
from machining_envs.drilling.lanes import (
    CONTROL_MODES,
    LENGTH_SCALE_MM,
    SPEED_SCALE_HZ,
    DrillingCore,
    DrillingReward,
)
from machining_envs.drilling.metrics import DRILLING_TASK
from machining_envs.drilling.plant import (
    DrillingParams,
)
from machining_envs.drilling.scenarios import (
    DrillingScenario,
)

__all__ = ["MicroDrillingEnv", "MicroDrillingVectorEnv", "DrillingReward", "CONTROL_MODES"]


class MicroDrillingEnv(LaneEnv):
    """Micro drilling under a torque limit by the spindle speed (Cheong & Cho, seed 003).

    ## Description
    An air-turbine spindle drives a 0.5-0.8 mm drill into SS40 mild steel at a constant feed
    velocity (0.32 mm/s). As the hole deepens, chips pack in the flutes and the torque climbs
    (their Fig. 12) until the drill breaks; industry pecks (retracts to clear the chips),
    which is safe but slow. Here the controller keeps the torque under the scenario's
    process limit (the drill's nominal chip-free torque, the paper's reference) by the
    spindle speed, choosing where to regulate below it: a faster spindle cuts a thinner chip per revolution, and the torque falls
    as ``k4 / omega`` (eq. 20). The spindle is driven through a pneumatic proportional valve
    (second order, eq. 17), its air friction grows as ``omega^0.608`` (eq. 19) and the
    drilling torque slows it. The plant is ``machining_envs.drilling.plant``; the valve is
    integrated exactly and the spindle by RK4 sub-steps; the controller samples at 100 Hz.

    ## Action Space
    ``Box(-1, 1, (1,), float32)`` (``(2,)`` with ``control="voltage_feed"``), mapped affinely
    onto the command (``action_to_command`` / ``command_to_action``):

    - ``control="voltage"`` (default, the paper's loop): the valve voltage in
      ``[0, voltage_max]`` V (0 to 10 V; 5 V, action 0, runs the free spindle at 545 Hz); the
      feed velocity is the scenario's constant 0.32 mm/s;
    - ``control="feed"``: the feed velocity of the stage in
      ``[-feed_speed_max_mm_s, feed_speed_max_mm_s]`` (negative retracts the drill; a retract
      that takes the point out of the hole clears the chips); the voltage is held at
      ``nominal_voltage``;
    - ``control="voltage_feed"``: both, ``[voltage, feed]``, each on the map above (an
      ``ActionMaps``; ``info["command"]`` is the pair): a controller can peck (retract to
      clear the chips) while it runs the spindle fast, which thins the chip so that the
      stage can feed faster at the same torque. The observation gains entry 12, the feed's
      previous action (entry 4 is then the voltage's).

    A finite action outside the box is clipped and counted in ``info["n_action_clipped"]``;
    NaN or inf raises ``ValueError``.

    ## Observation Space
    ``Box(float32, (12,))`` (``(13,)`` with ``control="voltage_feed"``): only what the machine
    measures or the operator set, normalised.

    | index | observation | unit | range |
    |---|---|---|---|
    | 0 | measured torque (filtered, noisy) / ``torque_scale_Nmm`` | - | [-1, 10] |
    | 1 | torque limit / ``torque_scale_Nmm`` | - | [0, 10] |
    | 2 | measured thrust / ``thrust_scale_N`` | - | [-1, 10] |
    | 3 | measured spindle frequency / 1000 Hz | - | [0, 3] |
    | 4 | previous action (the command now applied) | - | [-1, 1] |
    | 5 | drill point position below the surface / 10 mm | - | [-1, 2] |
    | 6 | hole depth / 10 mm | - | [0, 2] |
    | 7 | target hole depth / 10 mm | - | [0, 2] |
    | 8 | drill diameter / 1 mm | - | [0, 1] |
    | 9-11 | measured torque one, two, three samples ago / ``torque_scale_Nmm`` | - | [-1, 10] |
    | 12 | previous feed action (``control="voltage_feed"`` only) | - | [-1, 1] |

    The packed chips, the true cutting constant and the valve's spool position are hidden
    (they are in ``info``).

    ## Rewards
    With ``T`` the torque at the sample instant, ``L`` the limit, ``dz`` the hole's
    deepening in the step and ``v0`` the nominal feed (weights in :class:`DrillingReward`,
    configurable with ``reward=``):
    ``r = -1.0 |T/(0.9 L) - 1| - 4.0 max(0, T/L - 1) + 0.0 dz/(Ts v0) - 50 [breakage]``.
    The weights, and the setpoint 0.9 L that is the reward's own (a training choice, not the
    task's), are a :class:`~machining_envs.core.reward.LimitReward` (``DrillingReward`` here).

    ## Cost and score
    ``info["cost"]`` is 1.0 on a step where the drill is cutting and its torque is above the
    limit, else 0.0 (the Safety-Gymnasium convention); ``info["excess"]`` is how far over
    (torque / limit - 1 on such a step, else 0) and ``info["overload_ratio"]`` the
    scenario's overload ceiling (an episode past it does not count: ``docs/benchmark.md``).
    The score (``task``) is the drilling
    time, counted if the hole was finished, the drill did not break and under 2 % of the
    drilling steps had a cost; else the time limit is charged. **What the score ranks:**
    with ``control="voltage"`` the feed is the programmed constant, so every hole that
    counts takes the same time (``info["score_bound"]``, the travel at the programmed feed)
    and the score ranks the share of holes kept under the limit; the torque fluctuation is
    reported beside it. ``control="feed"`` lets the agent drill faster (its floor is the
    travel at the stage's top speed, which no hole kept under the limit approaches: at the
    nominal spindle speed the chip-free torque of the programmed feed is the limit itself).
    ``control="voltage_feed"`` ranks time and kept holes together: its floor
    (``machining_envs.drilling.lanes.floor_time_s``) is the point's entry at the stage's
    top speed and the rest of the hole at the feed whose chip-free torque at the top
    spindle speed (the free spindle at ``voltage_max``) is the limit (eq. 20: packed chips
    only add torque and the load only slows the spindle), so no hole drilled under the
    limit is faster but by the steps an allowance lets over it; the spindle's run-up from
    545 Hz (about a second) and the pecks' trips keep real holes well above it.

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
    ``diverged``, ``finished``, ``torque_Nmm`` (true torque), ``torque_limit_Nmm``,
    ``cost``, ``score_bound`` (s),
    ``measured`` (torque the controller saw, N·mm), ``peak_torque_Nmm`` (the largest
    torque over the step's sub-steps),
    ``breakage_torque_Nmm``, ``thrust_N``, ``measured_thrust_N``, ``spindle_hz``,
    ``measured_spindle_hz``, ``spindle_rpm``, ``voltage_V``, ``valve_opening``,
    ``feed_velocity_mm_s``, ``feed_mm_per_rev``, ``cutting``, ``engagement`` (engaged share
    of the full torque while the point enters), ``position_mm`` (drill point),
    ``depth_mm`` (hole depth), ``target_depth_mm``, ``packed_chip_mm``, ``chip_ratio``,
    ``diameter_mm``, ``segment`` (0 before the first cut, 1 after), ``scenario``, and
    ``drilling_time_s`` / ``machining_time_s`` once the hole is finished.

    ## Vector env
    ``gym.make_vec("machining_envs/MicroDrilling-v0", num_envs=N)`` gives a
    :class:`MicroDrillingVectorEnv`: N drilling machines stepped by one compiled kernel,
    lane ``i`` after ``reset(seed=s)`` exactly this env after ``reset(seed=s + i)``.

    ## Version History
    * v0: first version. The physics now runs as a batched kernel shared with the vector
      env (same numbers to the last bit, the same noise draws from ``np_random``, five
      normals a step, drawn by the kernel as the step needs them: the episodes of an
      unseeded reset after the first differ from those of the versions that drew them in
      blocks of 256 steps).
      The task is a process limit, not a reference: scenarios carry ``torque_limit_Nmm``
      and ``torque_limit_scale`` (was ``torque_ref_Nmm``), observation 1 is the limit,
      ``info`` gives ``torque_limit_Nmm``, ``cost`` and ``score_bound``; the reward tracks
      ``target`` x limit and penalises torque above the limit (was above 1.1x the
      reference); the scenarios ``train``, ``validation``, ``test`` (one distribution,
      separate streams) and ``ood`` (the former ``test`` ranges, varying limit) replace
      ``train``/``test``.

    ## Example
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> import machining_envs
    >>> env = gym.make("machining_envs/MicroDrilling-v0", scenario="paper_0.8")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["diameter_mm"], info["target_depth_mm"], round(info["spindle_hz"])
    ((12,), 0.8, 8.0, 545)
    >>> obs, reward, terminated, truncated, info = env.step(np.array([0.0], dtype=np.float32))
    >>> info["command"], info["t_s"], info["cutting"]
    (5.0, 0.01, True)
    """

    metadata = {**LaneEnv.metadata, "render_fps": 25}
    _ID = "MicroDrilling-v0"
    #: Episode metrics and primary score of this env (``machining_envs.core.score.Task``).
    task = DRILLING_TASK
    #: Positions of the observation's fields, for controllers that read them by name.
    OBS_INDEX = {
        "measured": 0,
        "limit": 1,
        "thrust": 2,
        "spindle": 3,
        "prev_action": 4,
        "position": 5,
        "depth": 6,
        "target": 7,
        "diameter": 8,
        "history": 9,
        "prev_feed_action": 12,  # control="voltage_feed" only
    }
    #: The signals render() draws: name -> the info key each is read from.
    _LOG_FIELDS = {
        "t": "t_s",
        "torque": "torque_Nmm",
        "measured": "measured",
        "speed": "spindle_hz",
        "depth": "depth_mm",
        "position": "position_mm",
        "limit": "torque_limit_Nmm",
    }
    #: Scales of the observation fields that are not set by the parameters.
    SPEED_SCALE_HZ = SPEED_SCALE_HZ
    LENGTH_SCALE_MM = LENGTH_SCALE_MM

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
        core = self._open(DrillingCore, locals())  # the core's options by their names
        self.control = core.control

    def _set_action(self, action) -> None:
        if self.control == "voltage_feed":
            self._core.set_action(0, *check_action_vector(action, 2, "MicroDrillingEnv"))
        else:
            super()._set_action(action)

    def _draw(self):
        log = self._log
        t = log["t"]
        return render_signals(
            t,
            [
                (
                    "torque (N·mm)",
                    [
                        ("torque", log["torque"], "C0-"),
                        ("measured", log["measured"], "C1-"),
                        ("limit", log["limit"], "k--"),
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


class MicroDrillingVectorEnv(LaneVectorEnv):
    """``machining_envs/MicroDrilling-v0`` as a native vector env: N drilling machines
    stepped as arrays, each lane exactly :class:`MicroDrillingEnv` with the lane's seed
    (``drilling_time_s`` and ``machining_time_s`` come with masks); its arguments are
    ``MicroDrillingEnv``'s, ``control`` included (not ``render_mode``), ``num_threads`` and
    ``autoreset_mode`` (:class:`~machining_envs.core.vector.LaneVectorEnv`).
    """

    single_env = MicroDrillingEnv
    core_cls = DrillingCore

    def _took(self, core) -> None:
        self.control = core.control
