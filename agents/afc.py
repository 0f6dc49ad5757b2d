"""Industrial adaptive feed control (AFC) for Turning-v0 and EndMilling-v0.

The controller production CNCs ship (Heidenhain's AFC, software option 45 of the TNC
controls; similar options from other makers) as the TNC user manuals describe it, on the
env's load channel: the spindle power where the env's ``power_sensor`` option is on (what
the machine measures; ``machining_envs.core.sensors``), else the dynamometer's force or
torque. What it does, rule by rule (the manual's column names in brackets):

- **Programmed feed.** The NC program's feed is the process planner's constant feed
  (:class:`agents.turning.ConstantFeed`, :class:`agents.milling.MillingConstantFeed`:
  ``setpoint`` x the limit at the deepest cut expected, ``design_depth_mm``; where the
  observation shows a power, the nominal force or torque limit). AFC moves only the feed
  override, a factor on that feed.
- **Reference load.** Given (``reference``: a share of the observed limit, as the tool
  table's AFC-LOAD gives it) or learnt by a **teach-in** (``teach_in_s`` > 0): the first
  ``teach_in_s`` seconds in the material are cut at 100 % override and the largest load
  seen becomes the reference (at most the limit). The idle load (the first observation,
  feed at rest) is subtracted: the controller regulates the cutting load.
- **Override bounds.** In the material the factor stays within ``[fmin, fmax]`` (FMIN,
  FMAX; e.g. 70-130 %); it moves by ``gain`` x the relative load error each control
  period (integral action on ``1 - load / reference``).
- **In air** (cutting load below ``pout`` x the reference, POUT, recommended 8 %) the tool
  traverses at the idle factor ``fidl`` (FIDL); on entering the material the factor starts
  from ``fent`` (FENT, at most 100 %).
- **Approach** (the library's rule, not the manual's): before the first contact the tool
  approaches at ``fapp`` (default ``fidl``). The contact shows in the load only, so a
  control whose override takes effect ``d`` periods late (a machine with interpolator
  delay, ``machining_envs.core.actuation``) enters the material at the approach factor
  whatever it commands on contact; ``from_env`` therefore sets ``fapp = fent`` on an env
  whose actuation has a delay (later air cuts still run at ``fidl``).
- **Overload reaction** (OVLD = S): the load above the reference for more than
  ``overload_s`` (one second) while the factor sits at ``fmin``: NC stop, the feed held at
  zero for the rest of the episode, and the ``stop`` flag raised.
- **Tool monitoring**: wear (AFC-OVLD1, ``wear_margin``): the load above
  ``(1 + wear_margin)`` x the reference raises the ``wear`` flag (a message; machining
  goes on); tool load (AFC-OVLD2, ``breakage_margin``): above ``(1 + breakage_margin)`` x the
  reference, the ``breakage`` flag and a machining stop. As on the control, load monitoring
  (OVLD2) set disables wear monitoring (OVLD1). Both watch the controlled cut only.
- **Log** (the manual's per-step log: LTIME, CTIME, PMAX, PREF, FMIN, OVLD):
  :meth:`AdaptiveFeedControl.episode_log` gives, per episode, the teach-in and controlled
  times, the peak and reference loads (in the load's unit, ``load_unit``), the smallest
  feed factor in the material and the flags; the evaluation harness records them in each
  episode's row (``afc_*`` columns).

The law is the industrial one (integral action on the relative load, bounded override),
not a model-based design: it knows nothing of the plant's gain or filter, and of the
machine's delay only whether there is one (the approach rule); its ``gain``, reference
and override bounds are tuned (``TUNABLE``; for a described machine ``MACHINE_TUNABLE``,
with ``fmin``) by the protocol every classical agent follows.
"""

from __future__ import annotations

import numpy as np

from agents.base import Agent, check_positive, check_setting, unwrap

__all__ = ["AdaptiveFeedControl", "AFC_LOG_FIELDS"]

#: The fields of :meth:`AdaptiveFeedControl.episode_log`, in order.
AFC_LOG_FIELDS = (
    "teach_in_time_s",
    "control_time_s",
    "peak_load",
    "reference_load",
    "min_feed_factor",
    "stop",
    "wear",
    "breakage",
)

# Columns of the state.
_OVR, _REF, _IDLE, _PHASE, _T_TEACH, _T_CTRL, _T_OVER, _PEAK, _FMIN_SEEN = range(9)
_STOP, _WEAR, _BREAK, _AIR, _LIMIT = range(9, 13 + 1)
# Phases: before the first contact, teach-in, control, stopped.
_WAIT, _TEACH, _CONTROL, _STOPPED = 0.0, 1.0, 2.0, 3.0


class AdaptiveFeedControl(Agent):
    """Industrial adaptive feed control on the load channel (module docstring).

    Parameters
    ----------
    programmed : Agent
        The programmed (constant) feed: an agent whose action is the NC program's feed.
    command_map : ActionMap
        The env's map between actions and commands (the override scales the command).
    load_units : callable
        ``obs (n, 7) -> (load, limit)``, each (n,), in the load's physical unit.
    programmed_obs : callable or None
        ``obs -> obs`` the programmed feed reads (where the observation's limit is a power,
        one with the nominal force or torque limit); None: the observation itself.
    sample_time_s : float
        The env's control period.
    load_unit : str
        ``"W"``, ``"N"`` or ``"N*mm"``, for the log.
    reference : float
        The given reference as a share of the observed limit, in (0, 1.5] (used when
        ``teach_in_s`` is 0). Set between steps (one value, or one per lane: a residual
        policy's setpoint, ``agents.rl.residual`` with ``knob: reference``), it applies
        from the next step on.
    teach_in_s : float
        Seconds of teach-in at 100 % override once in the material, in [0, 100] (0: the
        reference is given).
    fmin, fmax : float
        Override bounds in the material, shares of the programmed feed: ``fmin`` in
        [0.05, 1], ``fmax`` in [1, 5].
    fidl : float
        Override in air, in [0.05, 5].
    fent : float
        Override on entering the material, in [0.05, 1].
    fapp : float or None
        Override before the first contact (the approach), in [0.05, 5]; None: ``fidl``.
    pout : float
        Cutting load below which the tool is in air, as a share of the reference, in
        [0.01, 0.5] (manual: 8 %).
    gain : float
        Change of the override per control period per unit of relative load error, in
        (0, 2].
    overload_s : float
        Seconds above the reference at ``fmin`` before the overload stop, in (0, 100].
    wear_margin : float or None
        AFC-OVLD1 as a share of the reference, in (0, 5] (None: no wear monitoring).
    breakage_margin : float or None
        AFC-OVLD2 as a share of the reference, in (0, 5] (None: no load monitoring).
    """

    obs_dim = 7
    state_size = 14
    #: The prefix of the log's columns in the evaluation harness's rows.
    log_prefix = "afc_"
    #: Free parameters and their search ranges (low, high, log scale) for tuning.
    TUNABLE = {
        "design_depth_mm": (0.5, 6.0, False),
        "reference": (0.5, 1.0, False),
        "gain": (0.02, 1.0, True),
        "fmax": (1.0, 3.0, False),
        "fidl": (0.5, 3.0, False),
    }
    #: Tuned for a described machine (``machining-bench tune --machine``), also ``fmin``: the
    #: overload stop (above the reference at ``fmin``) is reached there, where a delayed,
    #: rate-limited override and a spindle that slows when overloaded leave the load above
    #: the reference longer.
    MACHINE_TUNABLE = {
        "design_depth_mm": TUNABLE["design_depth_mm"],
        "reference": TUNABLE["reference"],
        "gain": TUNABLE["gain"],
        "fmin": (0.2, 1.0, False),
        "fmax": TUNABLE["fmax"],
        "fidl": TUNABLE["fidl"],
    }

    def __init__(
        self,
        programmed: Agent,
        command_map,
        load_units,
        sample_time_s: float,
        programmed_obs=None,
        load_unit: str = "",
        *,
        reference: float = 0.9,
        teach_in_s: float = 0.0,
        fmin: float = 0.7,
        fmax: float = 1.3,
        fidl: float = 1.0,
        fent: float = 1.0,
        fapp: float | None = None,
        pout: float = 0.08,
        gain: float = 0.2,
        overload_s: float = 1.0,
        wear_margin: float | None = 0.1,
        breakage_margin: float | None = None,
    ):
        self.programmed = programmed
        #: The programmed feed's design depth (a tuned setting; NaN for a feed given).
        self.design_depth_mm = float(getattr(programmed, "design_depth_mm", float("nan")))
        self.command_map = command_map
        self.load_units = load_units
        self.programmed_obs = programmed_obs
        self.obs_index = getattr(programmed, "obs_index", None)
        self.ts = check_positive("sample_time_s", sample_time_s, 100.0)
        self.load_unit = str(load_unit)
        self.reference = check_positive("reference", reference, 1.5)
        self._reference = self.reference  # the reference the state was started with
        self.teach_in_s = check_setting("teach_in_s", teach_in_s, 0.0, 100.0)
        self.fmin = check_setting("fmin", fmin, 0.05, 1.0)
        self.fmax = check_setting("fmax", fmax, 1.0, 5.0)
        self.fidl = check_setting("fidl", fidl, 0.05, 5.0)
        self.fent = check_setting("fent", fent, 0.05, 1.0)
        self.fapp = self.fidl if fapp is None else check_setting("fapp", fapp, 0.05, 5.0)
        self.pout = check_setting("pout", pout, 0.01, 0.5)
        self.gain = check_positive("gain", gain, 2.0)
        self.overload_s = check_positive("overload_s", overload_s, 100.0)
        self.wear_margin = (
            None if wear_margin is None else check_positive("wear_margin", wear_margin, 5.0)
        )
        self.breakage_margin = (
            None
            if breakage_margin is None
            else check_positive("breakage_margin", breakage_margin, 5.0)
        )
        ref = f"teach-in {self.teach_in_s:g} s" if self.teach_in_s else f"ref {reference:.2g}"
        self.name = f"AFC {ref}, {self.fmin:.0%}-{self.fmax:.0%}"

    # -- construction from an env -----------------------------------------------------

    @classmethod
    def from_env(cls, env, design_depth_mm: float = 3.0, setpoint: float = 1.0, **kwargs):
        """The AFC for a Turning-v0 or EndMilling-v0 env: its programmed feed is the
        constant feed designed for ``design_depth_mm`` at ``setpoint`` x the limit; the
        load channel is the env's (its ``power_sensor`` if on). Where the env's actuation
        delays the override and ``fapp`` is not given, the approach runs at ``fent``
        (module docstring)."""
        from machining_envs.milling.env import EndMillingEnv
        from machining_envs.turning.env import TurningEnv

        base = unwrap(env)
        sensor = getattr(base, "power_sensor", None)
        if isinstance(base, TurningEnv):
            from agents.turning import ConstantFeed

            programmed = ConstantFeed.from_env(env, None, design_depth_mm, setpoint)
            fs = float(base.params.force_scale_N)
            nominal_limit = 1000.0 / fs  # the scenarios' process limit, 1 kN

            def load_units(obs):
                return fs * obs[:, 0], fs * obs[:, 1]

            unit = "N"
        elif isinstance(base, EndMillingEnv):
            from agents.milling import MillingConstantFeed

            programmed = MillingConstantFeed.from_env(env, None, design_depth_mm, setpoint)
            ts_ = float(base.params.torque_limit_Nmm)
            nominal_limit = 1.0  # the nominal torque limit

            def load_units(obs):  # the torque is observed as a multiple of the limit
                lim = ts_ * obs[:, 1]
                return lim * obs[:, 0], lim

            unit = "N*mm"
        else:
            raise TypeError(
                "AdaptiveFeedControl needs a TurningEnv or an EndMillingEnv, got "
                f"{type(base).__name__}"
            )
        act = getattr(base, "actuation", None)
        if act is not None and act.delay_steps > 0 and kwargs.get("fapp") is None:
            kwargs["fapp"] = kwargs.get("fent", 1.0)
        programmed_obs = None
        if sensor is not None:  # the observation shows powers: the planner's limit is nominal
            scale = float(sensor.power_scale_W)

            def load_units(obs):  # noqa: F811 - the power's, W
                return scale * obs[:, 0], scale * obs[:, 1]

            def programmed_obs(obs):
                o = obs.copy()
                o[:, 1] = nominal_limit
                return o

            unit = "W"
        return cls(
            programmed,
            base.command_map,
            load_units,
            float(base.params.sample_time_s),
            programmed_obs,
            unit,
            **kwargs,
        )

    # -- the controller ---------------------------------------------------------------

    def initial_state(self, n, obs):
        st = np.zeros((n, self.state_size))
        load, limit = self.load_units(obs)
        st[:, _OVR] = self.fapp
        st[:, _IDLE] = load  # feed at rest: the idle load
        st[:, _LIMIT] = limit
        st[:, _REF] = np.maximum(self.reference * limit - load, 1e-9)
        st[:, _PHASE] = _WAIT
        st[:, _FMIN_SEEN] = self.fmax
        st[:, _AIR] = 1.0
        return st

    def _act(self, obs, state):
        ts = self.ts
        load, limit = self.load_units(obs)
        cut = load - state[:, _IDLE]  # the cutting load
        phase = state[:, _PHASE]
        ref = state[:, _REF]
        if self.teach_in_s <= 0 and np.any(self.reference != self._reference):
            # a supervisor (agents.rl.residual) moved the given reference: it applies now,
            # as a share of the limit above the idle load, as initial_state computes it
            ref = np.maximum(self.reference * limit - state[:, _IDLE], 1e-9)
        ovr = state[:, _OVR]
        limit_cut = np.maximum(limit - state[:, _IDLE], 1e-9)
        state[:, _PEAK] = np.maximum(state[:, _PEAK], cut)
        air = (cut < self.pout * ref) & (phase != _TEACH)
        teach = phase == _TEACH
        entering = (state[:, _AIR] == 1.0) & ~air
        # first contact: teach-in, or control on the given reference
        first = (phase == _WAIT) & ~air
        if self.teach_in_s > 0:
            # the teach-in's reference: the largest cutting load seen, at most the limit
            ref = np.where(first, np.minimum(np.maximum(cut, 1e-9), limit_cut), ref)
            ref = np.where(teach, np.minimum(np.maximum(ref, cut), limit_cut), ref)
            phase = np.where(first, _TEACH, phase)
            state[:, _T_TEACH] += np.where(phase == _TEACH, ts, 0.0)
            done = (phase == _TEACH) & (state[:, _T_TEACH] >= self.teach_in_s - 1e-9)
            phase = np.where(done, _CONTROL, phase)
        else:
            phase = np.where(first, _CONTROL, phase)
        control = phase == _CONTROL
        stopped = phase == _STOPPED
        # the override: integral action on the relative load in the material, bounded
        e = 1.0 - cut / np.maximum(ref, 1e-9)
        new = np.where(entering, self.fent, ovr + self.gain * e)
        new = np.clip(new, self.fmin, self.fmax)
        ovr = np.where(control & ~air, new, ovr)
        ovr = np.where(phase == _TEACH, 1.0, ovr)
        idle = np.where(phase == _WAIT, self.fapp, self.fidl)  # before the first contact: fapp
        ovr = np.where(air & ~stopped, idle, ovr)
        in_ctrl = control & ~air
        state[:, _T_CTRL] += np.where(control, ts, 0.0)
        # overload: above the reference at fmin for more than overload_s -> NC stop
        over = in_ctrl & (cut > ref) & (ovr <= self.fmin + 1e-12)
        state[:, _T_OVER] = np.where(over, state[:, _T_OVER] + ts, 0.0)
        stop = state[:, _T_OVER] > self.overload_s + 1e-9
        # tool monitoring on the controlled cut: load (OVLD2, stops) or wear (OVLD1)
        if self.breakage_margin is not None:
            broken = in_ctrl & (cut > (1.0 + self.breakage_margin) * ref)
            state[:, _BREAK] = np.maximum(state[:, _BREAK], broken)
            stop = stop | broken
        elif self.wear_margin is not None:
            worn = in_ctrl & (cut > (1.0 + self.wear_margin) * ref)
            state[:, _WEAR] = np.maximum(state[:, _WEAR], worn)
        state[:, _STOP] = np.maximum(state[:, _STOP], stop)
        phase = np.where(stop | stopped, _STOPPED, phase)
        ovr = np.where(phase == _STOPPED, 0.0, ovr)
        in_material = ~air & (phase != _STOPPED)
        state[:, _FMIN_SEEN] = np.where(
            in_material, np.minimum(state[:, _FMIN_SEEN], ovr), state[:, _FMIN_SEEN]
        )
        state[:, _PHASE] = phase
        if self.teach_in_s > 0:  # (a moved given reference is not kept: the state's is)
            state[:, _REF] = ref
        state[:, _OVR] = ovr
        state[:, _AIR] = air
        state[:, _LIMIT] = limit
        prog_obs = obs if self.programmed_obs is None else self.programmed_obs(obs)
        a0 = self.programmed._act(prog_obs, np.zeros((obs.shape[0], 0)))[:, 0]
        command = self.command_map.action_to_command(a0) * ovr
        lo, hi = self.command_map.command_min, self.command_map.command_max
        return self.command_map.command_to_action(np.clip(command, lo, hi))[:, None]

    def episode_log(self, state) -> list[dict]:
        """Per lane of ``state`` (as :meth:`predict` returned it), the episode's log
        (:data:`AFC_LOG_FIELDS`): seconds of teach-in and of control, the peak and the
        reference cutting load (``load_unit``), the smallest feed factor in the material
        (NaN if never in it) and the flags (1.0 raised, 0.0 not)."""
        st = np.asarray(state, dtype=np.float64).reshape(-1, self.state_size)
        rows = []
        for s in st:
            seen = s[_PHASE] != _WAIT
            rows.append(
                {
                    "teach_in_time_s": float(s[_T_TEACH]),
                    "control_time_s": float(s[_T_CTRL]),
                    "peak_load": float(s[_PEAK]),
                    "reference_load": float(s[_REF]) if seen else float("nan"),
                    "min_feed_factor": float(s[_FMIN_SEEN]) if seen else float("nan"),
                    "stop": float(s[_STOP]),
                    "wear": float(s[_WEAR]),
                    "breakage": float(s[_BREAK]),
                }
            )
        return rows
