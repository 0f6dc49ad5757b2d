r"""Micro-drilling controllers: no control, PD on the torque error, sliding mode (Cheong &
Cho) and peck drilling (the industrial baseline).

Every drilling controller is built with ``from_env(env)`` from the env's nominal parameters
(:class:`DrillingIO`) and reads only the observation: the measured torque and spindle
frequency, the torque limit, the drill's position and the previous command. The voltage
controllers regulate at ``setpoint`` x the observed limit (1.0, the paper's choice, by
default) and declare their free parameters in ``TUNABLE`` for ``agents.bench.tune``.

**Peck drilling.** The drill feeds at the nominal feed velocity for ``q`` mm, retracts at rapid speed until its
point is out of the hole (the chips leave with it), rapids back to just above the bottom and
feeds on; the spindle runs at the nominal voltage throughout. Safe, because the chips never
pack deeper than ``q``; slow, because every peck costs the trip out and back.

**Sliding mode** (Cheong & Cho §6, eq. 17-23, Appendix A). **The model.** With ``x1 = x_v``, ``x2 = dx_v/dt`` and ``x3 = omega`` (eq. 18-20):

.. math::

    \dot x_1 = x_2, \quad
    \dot x_2 = k_1 u - 2\zeta\omega_n x_2 - \omega_n^2 x_1, \quad
    \dot x_3 = k_2 x_1 - k_3 x_3^{n} - \frac{k_4}{I x_3}, \quad
    y = \frac{k_4}{x_3}

The last term of :math:`\dot x_3` (the drilling torque slowing the spindle) is not in the
paper's eq. (19); it is kept here because the plant has it (``I -> inf`` gives the paper's
model back). ``k4`` is treated as constant over a sample and estimated every sample as
measured torque times measured speed (eq. 20 inverted), low-pass filtered.

**Feedback linearisation** (the OCR'd Appendix A is garbled; derived again). Write
:math:`a = \dot x_3`. Differentiating the output three times,

.. math::

    \ddot x_3 &= k_2 x_2 - n k_3 x_3^{n-1} a + \frac{k_4 a}{I x_3^2} \\
    \dot y &= -\frac{k_4 a}{x_3^2}, \qquad
    \ddot y = k_4\left(-\frac{\ddot x_3}{x_3^2} + \frac{2 a^2}{x_3^3}\right) \\
    y^{(3)} &= k_4\left(-\frac{x_3^{(3)}}{x_3^2} + \frac{6 a \ddot x_3}{x_3^3}
              - \frac{6 a^3}{x_3^4}\right) \\
    x_3^{(3)} &= k_2 \dot x_2 - n(n-1) k_3 x_3^{n-2} a^2 - n k_3 x_3^{n-1}\ddot x_3
              + \frac{k_4}{I}\left(\frac{\ddot x_3}{x_3^2} - \frac{2 a^2}{x_3^3}\right)

and ``u`` first appears in :math:`y^{(3)}` through :math:`\dot x_2`: the relative degree
is 3 (Appendix A). With the error ``e = x_{4d} - y`` and the surface of eq. (21)

.. math:: S = \ddot e + 2\lambda\dot e + \lambda^2 e,
          \qquad \dot S = -y^{(3)} - 2\lambda\ddot y - \lambda^2\dot y

asking for :math:`\dot S = -K\,\mathrm{sat}(S/\phi)` gives the required output jerk
:math:`y^{(3)}_* = K\,\mathrm{sat}(S/\phi) - 2\lambda\ddot y - \lambda^2\dot y`, hence the
required spindle jerk
:math:`x^{(3)}_{3*} = 6 a\ddot x_3/x_3 - 6a^3/x_3^2 - x_3^2 y^{(3)}_*/k_4`, and the input

.. math::

    u = \frac{2\zeta\omega_n x_2 + \omega_n^2 x_1}{k_1}
        + \frac{1}{k_1 k_2}\left[x^{(3)}_{3*} + n(n-1)k_3 x_3^{n-2}a^2
        + n k_3 x_3^{n-1}\ddot x_3
        - \frac{k_4}{I}\left(\frac{\ddot x_3}{x_3^2} - \frac{2a^2}{x_3^3}\right)\right]

The valve states are not measured: the controller runs the nominal valve model (eq. 17,
discretised exactly) on the voltages it applied.

**Two gain levels** (§7): far from the surface (``|S| > phi``) the small gain ``K_far``
moves ``S`` towards it slowly, so that a poor model early in the cut cannot drive the input
hard; inside the boundary layer the larger ``K_near`` makes it react to torque changes.
Inside the layer :math:`\dot S = -(K_{near}/\phi) S + \Delta` (``Delta``: what the model
misses, chiefly the change of ``k4`` as chips pack), so the layer is invariant while
``K_near >= |Delta|``, and then the error, the output of
:math:`\ddot e + 2\lambda\dot e + \lambda^2 e = S` (DC gain and impulse-response L1 norm
both ``1/lambda^2``), obeys :math:`|e| \le \phi/\lambda^2` once the initial transient has
decayed (Slotine & Li, §7.2). The boundary layer is set from that bound:
``phi = epsilon T_r lambda^2``, so the torque stays within ``epsilon`` of the reference.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from agents.base import (
    SETPOINT,
    ProcessController,
    Setting,
    check_setting,
    tunable,
    unwrap_as,
)
from machining_envs.core.checks import PY_NUMBER_TYPES
from machining_envs.core.lti import zoh
from machining_envs.drilling.env import MicroDrillingEnv
from machining_envs.drilling.plant import DrillingParams

__all__ = [
    "DrillingIO",
    "NoControl",
    "PD",
    "PeckDrilling",
    "TorquePeck",
    "VoltagePeck",
    "VoltageTorquePeck",
    "SlidingMode",
    "sliding_mode_input",
]

_I = MicroDrillingEnv.OBS_INDEX
_OBS_DIM = 12


#: The drilling controllers' settings are Python numbers (a numpy scalar other than
#: ``np.float64`` is refused, as it always was).
_in_range = functools.partial(check_setting, types=PY_NUMBER_TYPES)


@dataclass(frozen=True)
class DrillingIO:
    """What a drilling controller knows of the machine: its nominal constants and the maps.

    Converts the normalised observation to physical units and commands back to actions.
    """

    params: DrillingParams
    """The nominal plant (what the controller is designed from)."""
    control: str
    """``"voltage"``, ``"feed"`` or ``"voltage_feed"``: what the action commands."""
    command_min: float
    """The command range of the action (``"voltage_feed"``: of its voltage)."""
    command_max: float
    speed_scale_hz: float
    length_scale_mm: float
    feed_min: float = math.nan
    """``control="voltage_feed"``: the feed's command range, mm/s (else NaN)."""
    feed_max: float = math.nan

    @classmethod
    def from_env(cls, env) -> DrillingIO:
        base = unwrap_as(env, MicroDrillingEnv, "a drilling controller")
        m = base.command_map
        feed = ()
        if base.control == "voltage_feed":
            m, f = m.maps
            feed = (f.command_min, f.command_max)
        return cls(
            base.params,
            base.control,
            m.command_min,
            m.command_max,
            base.SPEED_SCALE_HZ,
            base.LENGTH_SCALE_MM,
            *feed,
        )

    @property
    def obs_dim(self) -> int:
        """The observation's length (13 with ``control="voltage_feed"``)."""
        return _OBS_DIM + (self.control == "voltage_feed")

    def require(self, control: str, who: str) -> None:
        if self.control != control:
            raise ValueError(f"{who} needs the env's control={control!r}, got {self.control!r}")

    @property
    def sample_time_s(self) -> float:
        return self.params.sample_time_s

    def torque(self, obs: np.ndarray, setpoint: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Measured torque and the set point (``setpoint`` x the observed limit), N·mm."""
        s = self.params.torque_scale_Nmm
        return s * obs[:, _I["measured"]], s * obs[:, _I["limit"]] * setpoint

    def speed_hz(self, obs: np.ndarray) -> np.ndarray:
        """Measured spindle frequency, Hz."""
        return self.speed_scale_hz * obs[:, _I["spindle"]]

    def lengths_mm(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Drill point position, hole depth and target depth, mm."""
        s = self.length_scale_mm
        return s * obs[:, _I["position"]], s * obs[:, _I["depth"]], s * obs[:, _I["target"]]

    def diameter_mm(self, obs: np.ndarray) -> np.ndarray:
        """Drill diameter, mm."""
        return obs[:, _I["diameter"]].astype(np.float64)

    def previous_command(self, obs: np.ndarray) -> np.ndarray:
        """The command applied over the last sample (V or mm/s)."""
        a = obs[:, _I["prev_action"]]
        return self.command_min + 0.5 * (a + 1.0) * (self.command_max - self.command_min)

    def action(self, command: np.ndarray) -> np.ndarray:
        """Actions (n, 1) for commands (n,)."""
        span = self.command_max - self.command_min
        return (2.0 * (command - self.command_min) / span - 1.0)[:, None]

    def pair_action(self, voltage: np.ndarray, feed: np.ndarray) -> np.ndarray:
        """Actions (n, 2) of ``control="voltage_feed"`` for voltages (V) and feeds (mm/s)."""
        fa = 2.0 * (feed - self.feed_min) / (self.feed_max - self.feed_min) - 1.0
        return np.column_stack([self.action(voltage)[:, 0], fa])


class _DrillingController(ProcessController):
    """What the drilling controllers share: the observation they read and what they are
    designed from."""

    obs_dim = _OBS_DIM
    obs_index = _I
    io_type = DrillingIO
    setting_types = PY_NUMBER_TYPES

    def _voltage_floor(self) -> float:
        """``min_voltage`` (a setting) checked against the machine's range; the nominal
        voltage where it is None."""
        p = self.io.params
        lo = p.nominal_voltage if self.min_voltage is None else self.min_voltage
        return _in_range("min_voltage", lo, 0.0, p.voltage_max)


class NoControl(_DrillingController):
    """The paper's uncontrolled run: the nominal voltage (545 Hz) and the nominal feed, held.

    With ``control="voltage"`` it holds ``voltage`` (default ``nominal_voltage``); with
    ``control="feed"`` it holds the nominal feed velocity (the voltage is then the env's
    nominal one): the same cut.
    """

    #: Free parameters for tuning: the constant voltage (the paper's runs at the nominal
    #: 5 V). A faster spindle cuts a thinner chip, so a constant high speed is a baseline
    #: the regulators must beat: the task charges nothing for spindle speed.
    TUNABLE = {"voltage": (2.0, 10.0, False)}
    state_size = 0

    def __init__(self, io: DrillingIO, voltage: float | None = None):
        self.io = io
        p = io.params
        if io.control == "voltage":
            u = p.nominal_voltage if voltage is None else voltage
            self.command = _in_range("voltage", u, 0.0, p.voltage_max)
            self.voltage = self.command
        else:
            if voltage is not None:
                raise ValueError("voltage applies to control='voltage' only")
            self.command = p.feed_velocity_mm_s
        self.name = "no control" if voltage is None else f"constant {self.command:.3g} V"

    def _act(self, obs, state):
        return self.io.action(np.full(obs.shape[0], self.command))


class PD(_DrillingController):
    r"""PD control of the torque by the valve voltage (the paper's Fig. 15).

    .. math::

        u_k = u_0 + K_p \left(e_k + T_d \frac{e^f_k - e^f_{k-1}}{T_s}\right),
        \qquad e_k = T_{m,k} - T_r, \qquad K_p = \frac{L\, n\, u_0}{T_r}

    clipped to ``[min_voltage, voltage_max]``. A torque above the reference opens the valve
    and speeds the spindle up, which thins the chip per revolution (eq. 20); ``e^f`` is the
    error through a first-order filter of time constant ``Td / N`` (the usual limit on the
    derivative's noise gain). The proportional gain is scaled to the drill: ``L`` is the loop
    gain at the nominal point, since ``dT/du = -T n^{-1} / u_0`` there (torque ``k4/omega``,
    unloaded speed ``~ u^{1/n}``). The paper gives no gains: ``L = 3`` puts the loop's
    crossover at about 12 rad/s, the bandwidth ``lambda`` of the sliding-mode design, so the
    two are compared at equal speed of response; there the linearised loop (valve, loaded
    spindle, sensor, half a sample of delay) has about 96 degrees of phase margin and a gain
    margin of 5.5 (``tests/drilling/test_agents.py``). A PD has no integral action: it
    leaves ``1/(1+L)``, a quarter, of a slow torque rise as steady error.

    ``min_voltage`` (default: the nominal voltage) makes it a speed-up-only regulator, as
    in the paper's runs, where the spindle speeds up from 545 Hz as the chips raise the
    torque (Fig. 16): slowing the spindle below the planned speed would only thicken the
    chip.

    Parameters
    ----------
    io : DrillingIO
    loop_gain : float
        L, dimensionless (see above).
    derivative_time_s : float
        Td, s.
    derivative_filter : float
        N, the derivative's high-frequency gain limit.
    min_voltage : float or None
        Lowest voltage commanded, V (default nominal).
    setpoint : float
        Torque regulated at, as a share of the observed limit (paper: 1.0), in (0, 1.5].
    """

    state_size = 2  # [filtered error e^f_{k-1} (N·mm), started (0/1)]
    #: The settings after ``io``: default, accepted range, search range (``TUNABLE``).
    SETTINGS = {
        "loop_gain": Setting(3.0, hi=1e3, search=(0.3, 30.0, True)),
        "derivative_time_s": Setting(0.02, hi=10.0, lo_open=False, search=(0.002, 0.2, True)),
        "derivative_filter": Setting(5.0, hi=1e3),
        "min_voltage": Setting(None, hi=None),  # (the machine's range: _voltage_floor)
        "setpoint": SETPOINT,
    }

    def _setup(self):
        self.io.require("voltage", "PD")
        p = self.io.params
        self.min_voltage = self._voltage_floor()
        self.u0 = p.nominal_voltage
        ts = p.sample_time_s
        tf = self.derivative_time_s / self.derivative_filter
        self._alpha = 1.0 - math.exp(-ts / tf) if tf > 0 else 1.0
        self.name = f"PD L={self.loop_gain:.3g}"

    def initial_state(self, n, obs):
        st = np.zeros((n, self.state_size))
        return st

    def _act(self, obs, state):
        io = self.io
        p = io.params
        tm, tr = io.torque(obs, self.setpoint)
        tr = np.maximum(tr, 1e-9)
        e = tm - tr
        first = state[:, 1] == 0.0
        ef_prev = np.where(first, e, state[:, 0])
        ef = ef_prev + self._alpha * (e - ef_prev)
        kp = self.loop_gain * p.spindle_friction_exponent * self.u0 / tr
        de = (ef - ef_prev) / p.sample_time_s
        u = self.u0 + kp * (e + self.derivative_time_s * de)
        u = np.clip(u, self.min_voltage, p.voltage_max)
        state[:, 0] = ef
        state[:, 1] = 1.0
        return io.action(u)


_FEED, _OUT, _BACK = 0.0, 1.0, 2.0


class PeckDrilling(_DrillingController):
    """Peck drilling on ``control="feed"``: feed ``q`` mm, retract out of the hole, return.

    On ``control="voltage_feed"`` the same cycle commands the stage while the spindle's
    valve holds ``voltage`` (:class:`VoltagePeck` is this cycle tuned with its voltage).

    The drill retracts once the hole is ``peck_diameters`` x D deeper than where the current
    peck began, with ``peck_diameters`` read at every step: a supervisor that lowers it
    (``agents.rl.residual`` with ``knob="peck_diameters"``) triggers a peck at once, one
    that raises it lets the drill cut on.

    Parameters
    ----------
    io : DrillingIO
    peck_diameters : float
        Peck depth ``q`` in drill diameters (default 1: chips pack at most one diameter deep,
        a usual choice for micro drills in steel).
    clearance_mm : float
        How far above the surface the point retracts, mm (default 0.1).
    approach_gap_mm : float
        Where the rapid return stops above the hole's bottom, mm; the rest is fed at the
        nominal feed (default 0.05).
    rapid_mm_s : float or None
        Retract and return speed, mm/s (default the stage's ``feed_speed_max_mm_s``).
    feed_scale : float
        The feed while cutting as a multiple of the nominal ``feed_velocity_mm_s`` (default
        1, the programmed feed; at most the stage's top speed).
    voltage : float or None
        The valve voltage held, V (``control="voltage_feed"`` only; default the nominal
        voltage, the spindle of ``control="feed"``).
    """

    # [phase (0 feed, 1 out, 2 back), hole depth where the current peck began (mm), started]
    state_size = 3
    #: The settings after ``io``: default, accepted range, search range (``TUNABLE``);
    #: ``hi=None``: the range is the stage's (checked in ``_setup``).
    SETTINGS = {
        "peck_diameters": Setting(1.0, hi=100.0, search=(0.25, 5.0, True)),
        "clearance_mm": Setting(0.1, hi=None),
        "approach_gap_mm": Setting(0.05, hi=5.0, lo_open=False),
        "rapid_mm_s": Setting(None, hi=None),
        "feed_scale": Setting(1.0, hi=None, search=(0.2, 4.0, True)),
        # checked in _setup: control="voltage_feed" only; None: the nominal voltage
        "voltage": Setting(None, hi=None),
    }
    #: The env keywords the agent needs (it commands the feed): tuning makes its env so.
    ENV_KWARGS = {"control": "feed"}
    #: The env's control modes the cycle runs on.
    CONTROLS = ("feed", "voltage_feed")

    def _setup(self):
        io = self.io
        if io.control not in self.CONTROLS:
            modes = " or ".join(f"control={c!r}" for c in self.CONTROLS)
            raise ValueError(f"{type(self).__name__} needs the env's {modes}, got {io.control!r}")
        self.obs_dim = io.obs_dim
        p = io.params
        if io.control == "feed" and self.voltage is not None:
            raise ValueError("voltage applies to control='voltage_feed' only")
        u = p.nominal_voltage if self.voltage is None else self.voltage
        self.voltage = _in_range("voltage", u, 0.0, p.voltage_max)
        self.clearance_mm = _in_range("clearance_mm", self.clearance_mm, 0.0, p.retract_limit_mm)
        rapid = p.feed_speed_max_mm_s if self.rapid_mm_s is None else self.rapid_mm_s
        self.rapid_mm_s = _in_range("rapid_mm_s", rapid, 1e-3, p.feed_speed_max_mm_s)
        self.feed_mm_s = p.feed_velocity_mm_s
        self.feed_scale = _in_range(
            "feed_scale", self.feed_scale, 1e-3, p.feed_speed_max_mm_s / p.feed_velocity_mm_s
        )
        self.name = f"peck q={self.peck_diameters:.3g}D" + (
            f", {self.feed_scale:.3g}x feed" if self.feed_scale != 1.0 else ""
        )
        self.name += self._spindle()

    def _spindle(self) -> str:
        """The name's spindle part: the voltage held on ``control="voltage_feed"``."""
        return f", {self.voltage:.3g} V" if self.io.control == "voltage_feed" else ""

    def _act(self, obs, state):
        io = self.io
        ts = io.sample_time_s
        pos, depth, _ = io.lengths_mm(obs)
        first = state[:, 2] == 0.0
        state[:, 1] = np.where(first, depth, state[:, 1])
        phase = np.where(first, _FEED, state[:, 0])
        # Transitions, then the command of the phase.
        to_out = (phase == _FEED) & self._peck_now(obs, depth, state[:, 1])
        phase = np.where(to_out, _OUT, phase)
        to_back = (phase == _OUT) & (pos <= -self.clearance_mm + 1e-9)
        phase = np.where(to_back, _BACK, phase)
        state[:, 1] = np.where(to_back, depth, state[:, 1])
        stop = depth - self.approach_gap_mm
        to_feed = (phase == _BACK) & (pos >= stop - 1e-9)
        phase = np.where(to_feed, _FEED, phase)
        back = np.minimum(self.rapid_mm_s, np.maximum((stop - pos) / ts, self.feed_mm_s))
        v = np.where(
            phase == _FEED,
            self.feed_mm_s * self.feed_scale,
            np.where(
                phase == _OUT,
                -np.minimum(self.rapid_mm_s, (pos + self.clearance_mm) / ts + 1e-3),
                back,
            ),
        )
        state[:, 0] = phase
        state[:, 2] = 1.0
        if io.control == "voltage_feed":
            return io.pair_action(np.full(v.shape, self.voltage), v)
        return io.action(v)

    def _peck_now(self, obs, depth, began):
        """Whether a feeding drill retracts now: the hole is ``q`` deeper than where the
        current peck ``began`` (mm)."""
        q = self.peck_diameters * self.io.diameter_mm(obs)
        return depth >= began + q - 1e-9


class TorquePeck(PeckDrilling):
    """Peck drilling triggered by the torque: the drill retracts as soon as the measured
    torque reaches ``torque_share`` x the observed limit (once the peck is at least
    ``min_peck_diameters`` deep), the load-monitored peck cycle of industrial CNCs; the
    cycle is :class:`PeckDrilling`'s otherwise (out of the hole, back, feed on).

    Parameters
    ----------
    io : DrillingIO
    torque_share : float
        The share of the torque limit that triggers a peck (default 0.8), in (0, 2].
    feed_scale : float
        The feed while cutting as a multiple of the nominal feed (default 0.7: at the
        nominal feed the chip-free torque at the nominal spindle speed is the limit itself).
    peck_diameters : float
        The deepest peck, in drill diameters (default 100: none; the torque decides).
    min_peck_diameters : float
        How deep a peck goes at least before the torque may end it, in drill diameters
        (default 0.25): a retract clears the chips, so a torque still high there is noise,
        and the cycle does not peck on the spot.
    clearance_mm, approach_gap_mm, rapid_mm_s, voltage
        As for :class:`PeckDrilling`.
    """

    #: The settings after ``io``; the rest as :class:`PeckDrilling`'s.
    SETTINGS = {
        "torque_share": Setting(0.8, lo=1e-3, hi=2.0, lo_open=False, search=(0.3, 1.0, False)),
        "feed_scale": replace(PeckDrilling.SETTINGS["feed_scale"], default=0.7),
        "peck_diameters": replace(
            PeckDrilling.SETTINGS["peck_diameters"], default=100.0, search=None
        ),
        "min_peck_diameters": Setting(0.25, hi=100.0, lo_open=False),
        **{
            k: PeckDrilling.SETTINGS[k]
            for k in ("clearance_mm", "approach_gap_mm", "rapid_mm_s", "voltage")
        },
    }

    def _setup(self):
        super()._setup()
        self.name = f"torque peck at {self.torque_share:.3g} x limit, {self.feed_scale:.3g}x feed"
        self.name += self._spindle()

    def _peck_now(self, obs, depth, began):
        torque, trigger = self.io.torque(obs, self.torque_share)
        deep = depth >= began + self.min_peck_diameters * self.io.diameter_mm(obs) - 1e-9
        return super()._peck_now(obs, depth, began) | (deep & (torque >= trigger))


#: The voltage's search range of the peck cycles on ``control="voltage_feed"``: NoControl's.
_VOLTAGE_SEARCH = (2.0, 10.0, False)


def _with_voltage_search(settings: dict) -> dict:
    """``settings`` with the voltage searched over :data:`_VOLTAGE_SEARCH`."""
    return {**settings, "voltage": replace(settings["voltage"], search=_VOLTAGE_SEARCH)}


class VoltagePeck(PeckDrilling):
    """:class:`PeckDrilling` on ``control="voltage_feed"``: the peck cycle commands the stage
    while the valve holds ``voltage`` (a fast spindle thins the chip, so the cycle can feed
    faster at the same torque); tuned with its voltage, peck depth and feed."""

    SETTINGS = _with_voltage_search(PeckDrilling.SETTINGS)
    TUNABLE = tunable(SETTINGS, "voltage", "peck_diameters", "feed_scale")
    ENV_KWARGS = {"control": "voltage_feed"}
    CONTROLS = ("voltage_feed",)


class VoltageTorquePeck(TorquePeck):
    """:class:`TorquePeck` on ``control="voltage_feed"``: a constant voltage with a
    torque-triggered peck; tuned with its voltage, trigger and feed."""

    SETTINGS = _with_voltage_search(TorquePeck.SETTINGS)
    TUNABLE = tunable(SETTINGS, "voltage", "torque_share", "feed_scale")
    ENV_KWARGS = {"control": "voltage_feed"}
    CONTROLS = ("voltage_feed",)


_TWO_PI = 2.0 * math.pi


def sliding_mode_input(x1, x2, x3, k4, y_ref, lam, phi, k_near, k_far, params):
    r"""The feedback-linearising sliding-mode voltage and the surface, vectorised.

    Parameters
    ----------
    x1, x2 : array
        Valve spool opening and its rate (model states).
    x3 : array
        Spindle speed, rad/s (> 0).
    k4 : array
        Torque constant, N·mm·rad/s (> 0).
    y_ref : array
        Torque reference x4d, N·mm.
    lam : float
        lambda of the surface, rad/s.
    phi : array
        Boundary-layer width, N·mm/s^2.
    k_near, k_far : array
        K inside and outside the boundary layer, N·mm/s^3.
    params : DrillingParams
        The nominal model.

    Returns
    -------
    u, S, e : arrays
        Unclipped voltage (V), the surface and the modelled torque error ``x4d - k4/x3``.
    """
    p = params
    k1, k2, k3, n = p.k1, p.spindle_drive_gain, p.spindle_friction, p.spindle_friction_exponent
    wn, z = p.valve_natural_freq_rad_s, p.valve_damping
    c = k4 / p.spindle_inertia_Nmm_s2  # k4 / I
    x3n1 = x3 ** (n - 1.0)
    a = k2 * x1 - k3 * x3n1 * x3 - c / x3
    x3dd = k2 * x2 - n * k3 * x3n1 * a + c * a / x3**2
    y = k4 / x3
    yd = -k4 * a / x3**2
    ydd = k4 * (-x3dd / x3**2 + 2.0 * a**2 / x3**3)
    e = y_ref - y
    s = -ydd - 2.0 * lam * yd + lam**2 * e
    ratio = s / phi
    gain = np.where(np.abs(ratio) <= 1.0, k_near, k_far)
    y3 = gain * np.clip(ratio, -1.0, 1.0) - 2.0 * lam * ydd - lam**2 * yd
    x3ddd = 6.0 * a * x3dd / x3 - 6.0 * a**3 / x3**2 - x3**2 * y3 / k4
    bracket = (
        x3ddd
        + n * (n - 1.0) * k3 * x3n1 / x3 * a**2
        + n * k3 * x3n1 * x3dd
        - c * (x3dd / x3**2 - 2.0 * a**2 / x3**3)
    )
    u = (2.0 * z * wn * x2 + wn**2 * x1) / k1 + bracket / (k1 * k2)
    return u, s, e


class SlidingMode(_DrillingController):
    r"""Sliding-mode torque regulation by the valve voltage (see the module docstring).

    Parameters
    ----------
    io : DrillingIO
    lam : float
        lambda of the surface ``S = e'' + 2 lambda e' + lambda^2 e``, rad/s. Not given in
        the paper: 12 rad/s, three times the spindle's own 4 rad/s and a quarter of the
        valve's 50 rad/s, which the feedback linearisation inverts, so the valve model's
        errors stay small at the loop's speed.
    epsilon : float
        Torque-error bound inside the boundary layer as a share of the reference:
        ``phi = epsilon T_r lambda^2`` (default 3 %).
    near_rate : float
        ``K_near / phi``, 1/s: how fast ``S`` decays inside the layer (default 35/s, a third
        of the 100 Hz sample rate, so the sampled loop stays well damped).
    far_ratio : float
        ``K_far / K_near`` (default 0.25: the paper's small gain outside the layer).
    k4_filter_s : float
        Time constant of the low-pass on the ``k4`` estimate, s (default 0.02 s).
    min_voltage : float or None
        Lowest voltage commanded, V (default nominal: speed up only, as in the paper's
        Fig. 22, where the spindle stays near 545 Hz until chips raise the torque).
    engage_fraction : float
        The law runs once the estimated torque passes this share of the reference (the
        drill is cutting); before, and whenever the estimate falls below it, the voltage is
        ``min_voltage`` (``k4 -> 0`` makes the inverse meaningless).
    setpoint : float
        Torque regulated at, as a share of the observed limit (paper: 1.0), in (0, 1.5].
    """

    #: The settings after ``io``: default, accepted range, search range (``TUNABLE``).
    SETTINGS = {
        "lam": Setting(12.0, hi=1e3, search=(2.0, 60.0, True)),
        "epsilon": Setting(0.03, hi=1.0, search=(0.005, 0.2, True)),
        "near_rate": Setting(35.0, hi=1e4),
        "far_ratio": Setting(0.25, hi=1e3),
        "k4_filter_s": Setting(0.02, hi=10.0, lo_open=False),
        "min_voltage": PD.SETTINGS["min_voltage"],
        "engage_fraction": Setting(0.3, hi=1.0, lo_open=False),
        "setpoint": SETPOINT,
    }
    # [x1_hat, x2_hat, k4_hat, S, e, started, near(0/1), u]
    state_size = 8
    STATE = {"x1": 0, "x2": 1, "k4": 2, "S": 3, "e": 4, "started": 5, "near": 6, "u": 7}

    def _setup(self):
        self.io.require("voltage", "SlidingMode")
        p = self.io.params
        self.min_voltage = self._voltage_floor()
        ts = p.sample_time_s
        a = np.array(
            [
                [0.0, 1.0],
                [
                    -(p.valve_natural_freq_rad_s**2),
                    -2.0 * p.valve_damping * p.valve_natural_freq_rad_s,
                ],
            ]
        )
        b = np.array([[0.0], [p.k1]])
        phi, gam = zoh(a, b, ts)
        self._phi = phi
        self._gam = gam[:, 0]
        self._alpha = 1.0 - math.exp(-ts / self.k4_filter_s) if self.k4_filter_s > 0 else 1.0
        self.name = f"sliding mode lambda={self.lam:.3g}"

    def boundary_layer(self, torque_ref_Nmm):
        """phi, N·mm/s^2, for a reference torque."""
        return self.epsilon * np.asarray(torque_ref_Nmm) * self.lam**2

    def error_bound(self, torque_ref_Nmm):
        """|e| <= phi / lambda^2 = epsilon T_r inside the layer, N·mm."""
        return self.boundary_layer(torque_ref_Nmm) / self.lam**2

    def initial_state(self, n, obs):
        st = np.zeros((n, self.state_size))
        u = self.io.previous_command(obs)
        st[:, 0] = self.io.params.valve_static_gain_per_V * u  # the valve has settled
        st[:, 7] = u
        return st

    def _act(self, obs, state):
        io = self.io
        p = io.params
        x1, x2 = state[:, 0].copy(), state[:, 1].copy()
        started = state[:, 5] > 0.0
        u_prev = io.previous_command(obs)
        # Valve model: advance over the sample just applied (not on an episode's first call).
        nx1 = self._phi[0, 0] * x1 + self._phi[0, 1] * x2 + self._gam[0] * u_prev
        nx2 = self._phi[1, 0] * x1 + self._phi[1, 1] * x2 + self._gam[1] * u_prev
        x1 = np.where(started, nx1, x1)
        x2 = np.where(started, nx2, x2)
        tm, tr = io.torque(obs, self.setpoint)
        tr = np.maximum(tr, 1e-9)
        x3 = _TWO_PI * np.maximum(io.speed_hz(obs), 50.0)
        k4_raw = np.maximum(tm, 0.0) * x3
        k4 = np.where(started, state[:, 2] + self._alpha * (k4_raw - state[:, 2]), k4_raw)
        active = k4 > self.engage_fraction * tr * x3
        phi = self.boundary_layer(tr)
        k_near = self.near_rate * phi
        k4_safe = np.where(active, k4, tr * x3)
        u, s, e = sliding_mode_input(
            x1, x2, x3, k4_safe, tr, self.lam, phi, k_near, self.far_ratio * k_near, p
        )
        near = np.abs(s) <= phi
        u = np.where(active, u, self.min_voltage)
        u = np.clip(u, self.min_voltage, p.voltage_max)
        state[:, 0], state[:, 1], state[:, 2] = x1, x2, k4
        state[:, 3] = np.where(active, s, 0.0)
        state[:, 4] = np.where(active, e, tr - tm)
        state[:, 5] = 1.0
        state[:, 6] = near
        state[:, 7] = u
        return io.action(u)
