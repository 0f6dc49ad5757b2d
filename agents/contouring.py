"""Contouring controllers (Choi et al.): a PI position loop per axis, the paper's H-infinity
two-degree-of-freedom loop (``Contouring-v0``), and the constant feed override, the
baseline of ``ContouringFeed-v0``.

Every controller here is a discrete linear system per axis from the set point and the
measured position to the velocity command, designed once from the env's nominal parameters
(``machining_envs.contouring.servo``) and run as difference equations in ``predict``. It reads only the
observation: the set point and the tracking error (the table's position is their
difference).

**H-infinity 2-DOF.** The design (``machining_envs.contouring.servo.hinf_2dof_design``)
comes out of python-control's ``hinfsyn`` at the optimal gamma, whose result depends on the
BLAS and LAPACK kernels of the machine. So the designs the envs and the benchmark run (the
paper's rho and the tuned one, on the env's default axes) are computed once and stored as
data (``machining_envs/contouring/hinf_designs.json``: the matrices and the gamma
reached, every float exact), and the design function reads them: the same controller, and
the same actions, on every machine. Another axis model or rho is synthesised on the spot
(``agent.stored`` says which). ``machining-bench synthesize`` re-synthesises the stored
designs (``synthesize_stored_designs``) and says where it writes. ``predict`` only runs the
difference equations (``agents.contouring.LinearServoAgent``).

**Constant feed override.** A process planner's choice: one override for every path, the largest that keeps the contour
error within the tolerance on the training paths. :func:`calibrate_constant_override` finds
it by bisection over rollouts; :data:`BASELINE_OVERRIDE` holds the values it gives for the
env's defaults (regenerate with ``python -m agents.contouring``).
"""

from __future__ import annotations

import functools
import math

import gymnasium as gym
import numpy as np
from scipy.linalg import block_diag

from agents.base import Agent, Setting, check_positive, tunable, unwrap, unwrap_as
from machining_envs.contouring.env import ERROR_SCALE_MM, POSITION_SCALE_MM, ContouringEnv
from machining_envs.contouring.feed_env import (
    DEFAULT_TOLERANCE_MM,
    LOOKAHEAD_MM,
    ContouringFeedEnv,
)
from machining_envs.contouring.plant import AXES, ContouringParams, vecmat_rows
from machining_envs.contouring.servo import (
    HINF_RHO,
    ServoDesign,
    hinf_2dof_design,
    pi_design,
    stored_hinf_design,
)

__all__ = [
    "LinearServoAgent",
    "PIPosition",
    "contouring_params",
    "HInf2DOF",
    "ConstantOverride",
    "LookAheadFeed",
    "ContourAFC",
    "calibrate_constant_override",
    "BASELINE_OVERRIDE",
    "CALIBRATION_SEEDS",
]

_I = ContouringEnv.OBS_INDEX
#: Smallest override :class:`LookAheadFeed` commands (2 % of the programmed feed).
MIN_OVERRIDE = 0.02


def contouring_params(env) -> ContouringParams:
    """The nominal parameters of a (possibly wrapped) ``ContouringEnv``."""
    return unwrap_as(env, ContouringEnv, "a contouring controller").params


class LinearServoAgent(Agent):
    """Runs one discrete controller per axis (``ServoDesign``) on Contouring-v0 observations.

    State per env: both axes' controller states, then the table's position at the episode's
    start (the origin the controllers' inputs are taken from; see ``machining_envs.contouring.servo``).
    """

    obs_dim = 14
    obs_index = _I

    def __init__(
        self, designs: tuple[ServoDesign, ServoDesign], command_max_mm_s: float, name: str
    ):
        if len(designs) != 2:
            raise ValueError(f"designs must hold one ServoDesign per axis, got {len(designs)}")
        self.designs = tuple(designs)
        self.name = name
        self.command_max_mm_s = float(command_max_mm_s)
        self._nx = sum(d.n_states for d in designs)
        self.state_size = self._nx + 2
        # Both axes as one block-diagonal system on inputs [r_x, y_x, r_y, y_y], as one
        # matrix: [xi, inputs] @ M = [next xi, commands].
        a = block_diag(*(d.a for d in designs))
        b = block_diag(*(d.b for d in designs))
        c = block_diag(*(d.c for d in designs))
        d = block_diag(*(d.d for d in designs))
        self._m = np.block([[a.T, c.T], [b.T, d.T]])
        self._mt = np.ascontiguousarray(self._m.T)
        # Anti-windup by conditioning (Hanus): while an axis's command passes the drive's
        # limit, its controller is updated with the set point that would have produced the
        # limited command, r + (u_sat - u) / d_r; so the states follow what the drive does.
        self._aw = [np.asarray(des.b[:, 0] / des.d[0, 0], dtype=np.float64) for des in self.designs]
        self._aw_slices = []
        k = 0
        for des in self.designs:
            self._aw_slices.append(slice(k, k + des.n_states))
            k += des.n_states

    @staticmethod
    def _positions(obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Set points and table positions (n, 2), mm, from a batch of observations."""
        i, j = _I["reference"], _I["error"]
        r = obs[:, i : i + 2] * POSITION_SCALE_MM
        return r, r - obs[:, j : j + 2] * ERROR_SCALE_MM

    def initial_state(self, n: int, obs: np.ndarray) -> np.ndarray:
        st = np.zeros((n, self.state_size))
        st[:, self._nx :] = self._positions(obs)[1]
        return st

    def _act(self, obs, state):
        r, y = self._positions(obs)
        nx = self._nx
        origin = state[:, nx:]
        z = np.empty((obs.shape[0], nx + 4))
        z[:, :nx] = state[:, :nx]
        z[:, nx::2] = r - origin
        z[:, nx + 1 :: 2] = y - origin
        # Compiled, row by row, in a fixed order (OpenBLAS's Haswell dgemv, as numpy sums a
        # 1-D product here): each env gets the numbers it gets alone, on any CPU. The H-inf
        # controller's near-integrator turns a BLAS kernel's different last bits into
        # differences of 1e-6 of the torques over a long episode.
        out = np.empty((z.shape[0], self._m.shape[1]))
        vecmat_rows(z, self._mt, out)
        state[:, :nx] = out[:, :nx]
        u = out[:, nx:]
        umax = self.command_max_mm_s
        excess = np.minimum(np.maximum(u, -umax), umax) - u
        if excess.any():
            for axis, sl in enumerate(self._aw_slices):
                state[:, sl] += excess[:, axis : axis + 1] * self._aw[axis]
        return u / umax

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """As :meth:`Agent.predict`; one env's observation with a carried state and no new
        episode takes a shorter path (the servo runs 5000 times a simulated second)."""
        if (
            state is not None
            and isinstance(observation, np.ndarray)
            and observation.shape == (self.obs_dim,)
            and observation.dtype.kind == "f"
            and isinstance(state, np.ndarray)
            and state.shape == (1, self.state_size)
            and (
                episode_start is None
                or (
                    isinstance(episode_start, np.ndarray)
                    and episode_start.size == 1
                    and not episode_start.item()
                )
            )
        ):
            nx = self._nx
            o = observation.tolist()
            st = state.copy()
            if not (math.isfinite(sum(o)) and math.isfinite(float(st.sum()))):
                return super().predict(observation, state, episode_start, deterministic)
            i, j = _I["reference"], _I["error"]
            ox, oy = st[0, nx:].tolist()
            rx, ry = o[i] * POSITION_SCALE_MM, o[i + 1] * POSITION_SCALE_MM
            yx, yy = rx - o[j] * ERROR_SCALE_MM, ry - o[j + 1] * ERROR_SCALE_MM
            z = np.concatenate([st[0, :nx], (rx - ox, yx - ox, ry - oy, yy - oy)])
            out = np.empty((1, self._m.shape[1]))
            vecmat_rows(z.reshape(1, -1), self._mt, out)  # as in _act
            out = out[0]
            st[0, :nx] = out[:nx]
            umax = self.command_max_mm_s
            ux, uy = out[nx:].tolist()
            if not (-umax <= ux <= umax and -umax <= uy <= umax):
                for axis, u in enumerate((ux, uy)):
                    excess = min(max(u, -umax), umax) - u
                    if excess:
                        st[0, self._aw_slices[axis]] += excess * self._aw[axis]
            ux, uy = ux / umax, uy / umax
            act = [min(max(ux, -1.0), 1.0), min(max(uy, -1.0), 1.0)]
            return np.array(act, dtype=np.float32), st
        return super().predict(observation, state, episode_start, deterministic)


class PIPosition(LinearServoAgent):
    """PI position controller per axis, tuned by pole placement without overshoot.

    ``u = Kp (b r - y) + Ki int(r - y)`` with ``Kp = a/3``, ``Ki = a^2/27``, ``b = 1/3``
    for the axis ``a / (s (s + a))``: the three closed-loop poles at ``-a/3`` (the fastest
    critically damped placement) and the set-point weight that cancels one of them, so the
    step response is ``p^2 / (s + p)^2`` (no overshoot); see ``machining_envs.contouring.servo.pi_design``.
    Designed from the env's nominal parameters; discretised by Tustin at the servo rate.
    """

    #: Free parameters and their search ranges (low, high, log scale) for tuning: the gains
    #: as multiples of the pole-placement design's, and the set-point weight b.
    TUNABLE = {
        "kp_scale": (0.3, 3.0, True),
        "ki_scale": (0.1, 10.0, True),
        "setpoint_weight": (0.1, 1.0, False),
    }

    @classmethod
    def from_env(
        cls, env, kp_scale: float = 1.0, ki_scale: float = 1.0, setpoint_weight: float = 1.0 / 3.0
    ) -> PIPosition:
        p = contouring_params(env)
        kp_scale = check_positive("kp_scale", kp_scale, 10.0)
        ki_scale = check_positive("ki_scale", ki_scale, 100.0)
        setpoint_weight = check_positive("setpoint_weight", setpoint_weight, 1.0)
        designs = tuple(pi_design(p, ax, kp_scale, ki_scale, setpoint_weight) for ax in AXES)
        agent = cls(designs, p.command_max_mm_s, "PI position")
        agent.kp_scale, agent.ki_scale, agent.setpoint_weight = kp_scale, ki_scale, setpoint_weight
        return agent


class HInf2DOF(LinearServoAgent):
    """Hoyle-Hyde-Limebeer 2-DOF H-infinity loop-shaping controller per axis (paper §4).

    Feedforward ``K1`` on the set point and feedback ``K2`` on the measured position,
    designed together so that the loop follows the reference model ``M0 = 500/(s + 500)``
    robustly, with the paper's loop-shaping weight ``W = 1e6/(s + 1e-3)``; the constant
    prefilter makes the steady state exact. ``gammas`` holds the achieved H-infinity norm
    of each axis's design (X, Y).

    Examples
    --------
    >>> import gymnasium as gym
    >>> import machining_envs
    >>> agent = HInf2DOF.from_env(gym.make("machining_envs/Contouring-v0"))
    >>> [round(g, 2) for g in agent.gammas]
    [5.83, 6.01]
    """

    #: Free parameters and their search ranges (low, high, log scale) for tuning: rho, the
    #: weight of model matching against robust stabilisation (one synthesis per trial).
    TUNABLE = {"rho": (0.3, 3.0, True)}

    @classmethod
    def from_env(cls, env, rho: float = HINF_RHO) -> HInf2DOF:
        """The controller for ``env``'s axes at ``rho``: the stored design
        (``machining_envs/contouring/hinf_designs.json``) where one matches exactly, else
        synthesised."""
        p = contouring_params(env)
        rho = check_positive("rho", rho, 100.0)
        designs = tuple(hinf_2dof_design(p, ax, rho=rho) for ax in AXES)
        agent = cls(designs, p.command_max_mm_s, "H-inf 2-DOF")
        agent.rho = rho
        agent.stored = all(stored_hinf_design(p, ax, rho) is not None for ax in AXES)
        return agent

    @property
    def gammas(self) -> tuple[float, float]:
        """Achieved gamma of the X and Y designs."""
        return tuple(float(d.gamma) for d in self.designs)


#: Training paths the baseline is calibrated on: ``train`` scenarios drawn with these seeds.
CALIBRATION_SEEDS = tuple(range(200))

#: servo -> the largest constant override keeping the default tolerance on every path of
#: ``CALIBRATION_SEEDS`` (default parameters, tolerance and decision interval), rounded down
#: to 0.01. Regenerate: ``python -m agents.contouring``.
BASELINE_OVERRIDE = {"pi": 0.13, "hinf": 0.41}


def _max_error(env, scenario, override: float) -> float:
    base = unwrap(env)
    action = np.array([base.command_to_action(override)], dtype=np.float32)
    env.reset(seed=0, options={"scenario": scenario})
    peak = 0.0
    while True:
        _, _, term, trunc, info = env.step(action)
        peak = max(peak, info["peak_contour_error_mm"])
        if peak > base.tolerance_mm or term or trunc:
            return peak


def calibrate_constant_override(
    env_kwargs: dict | None = None,
    seeds=CALIBRATION_SEEDS,
    resolution: float = 0.01,
    verbose: bool = False,
) -> float:
    """Largest override (a multiple of ``resolution``) whose runs keep the env's tolerance
    on the ``train`` paths drawn with ``seeds``.

    Paths are taken in turn: each is run at the best override so far, and bisected below it
    when it breaks the tolerance. A run stops as soon as its contour error passes the
    tolerance, so failing candidates are cheap.
    """
    env = gym.make("machining_envs/ContouringFeed-v0", **(env_kwargs or {}))
    try:
        base = unwrap(env)
        seeds = list(seeds)
        scenarios = []
        for s in seeds:
            base.reset(seed=int(s), options={"scenario": "train"})
            scenarios.append(base.scenario)
        hi = base.override_max
        for k, sc in enumerate(scenarios):
            if _max_error(env, sc, hi) <= base.tolerance_mm:
                continue
            lo_ok, hi_bad = 0.0, hi
            while hi_bad - lo_ok > resolution:
                mid = 0.5 * (lo_ok + hi_bad)
                if _max_error(env, sc, mid) <= base.tolerance_mm:
                    lo_ok = mid
                else:
                    hi_bad = mid
            hi = math.floor(lo_ok / resolution + 1e-9) * resolution
            if verbose:
                print(f"path {k} (seed {seeds[k]}): override <= {hi:.2f}", flush=True)
        return float(hi)
    finally:
        env.close()


@functools.lru_cache(maxsize=16)
def _calibrated(servo: str, tolerance: float, params, decision: float, omax: float) -> float:
    kwargs = {
        "servo": servo,
        "tolerance_mm": tolerance,
        "params": params,
        "decision_interval_s": decision,
        "override_max": omax,
    }
    return calibrate_constant_override(kwargs)


class ConstantOverride(Agent):
    """The same feed override all along every path (no feedback).

    ``from_env`` takes the override from :data:`BASELINE_OVERRIDE` when the env has the
    default parameters, tolerance and decision interval, and calibrates it on the training
    paths otherwise (once per setting and process; a few minutes).
    """

    state_size = 0
    obs_dim = 16
    #: Free parameters and their search ranges (low, high, log scale) for tuning.
    TUNABLE = {"override": (0.1, 2.0, False)}

    def __init__(self, override: float, override_max: float):
        self.override_max = check_positive("override_max", override_max, 10.0)  # the env's range
        self.override = check_positive("override", override, self.override_max)
        self.name = f"constant override {override:.2f}"

    @classmethod
    def from_env(cls, env, override: float | None = None) -> ConstantOverride:
        base = unwrap_as(env, ContouringFeedEnv, "ConstantOverride")
        if override is None:
            default = (
                base.tolerance_mm == DEFAULT_TOLERANCE_MM[base.servo]
                and base.params == type(base.params)()
                and base.decision_interval_s == 0.01
                and base.override_max == 2.0
            )
            if default and BASELINE_OVERRIDE[base.servo] > 0:
                override = BASELINE_OVERRIDE[base.servo]
            else:
                override = _calibrated(
                    base.servo,
                    base.tolerance_mm,
                    base.params,
                    base.decision_interval_s,
                    base.override_max,
                )
        return cls(override, base.override_max)

    def _act(self, obs, state):
        a = 2.0 * self.override / self.override_max - 1.0
        return np.full((obs.shape[0], 1), a)


class LookAheadFeed(Agent):
    r"""The look-ahead feed planner of a CNC: the feed limited by the path's curvature and
    by the drives' deceleration over the path previewed ahead.

    Read from the observation (ContouringFeed-v0): the programmed feed ``F``, the path's
    turn ``theta_i`` over the next ``d_i`` = 0.5, 1, 2, 5, 10 mm (``LOOKAHEAD_MM``) and the
    path left ``r``. The window from ``d_{i-1}`` to ``d_i`` (``d_0 = 0``) turns by
    ``|theta_i - theta_{i-1}|``; its mean curvature ``kappa_i`` limits the speed there to
    ``v_i = sqrt(a_c / kappa_i)`` (centripetal acceleration ``a_c``). To be able to slow
    down to it by the window's start, the speed now is at most

    .. math:: v = \min_i \sqrt{v_i^2 + 2 a_t d_{i-1}}, \qquad v \le \sqrt{2 a_t r},

    (tangential deceleration ``a_t``; the second bound stops the set point at the path's
    end), and the override is ``min(override_cap, v / F)``. A real planner takes ``a_c`` and
    ``a_t`` from the drives' ratings and the tolerance; here they are the free parameters
    (``TUNABLE``). Designed from nothing hidden: the preview is what a CNC reads from the
    part program.

    Parameters
    ----------
    override_max : float
        The env's largest override (action +1).
    centripetal_mm_s2, tangential_mm_s2 : float
        ``a_c`` and ``a_t``, mm/s^2 (default 1000 each, about 0.1 g).
    override_cap : float
        Largest override the planner commands (default 1: the programmed feed).
    """

    state_size = 0
    obs_dim = 16
    #: The settings after ``override_max``: default, accepted range, search range
    #: (``TUNABLE``); ``override_cap`` is at most ``override_max``.
    SETTINGS = {
        "centripetal_mm_s2": Setting(1000.0, hi=1e7, search=(10.0, 1e5, True)),
        "tangential_mm_s2": Setting(1000.0, hi=1e7, search=(10.0, 1e5, True)),
        "override_cap": Setting(1.0, hi=None, search=(0.1, 2.0, False)),
    }

    def __init__(self, override_max: float, *args, **kwargs):
        self.override_max = check_positive("override_max", override_max, 10.0)
        self.configure(args, kwargs)
        self.override_cap = check_positive("override_cap", self.override_cap, self.override_max)
        self._d = np.asarray(LOOKAHEAD_MM, dtype=np.float64)
        self.name = "look-ahead feed"

    @classmethod
    def from_env(cls, env, *args, **kwargs) -> LookAheadFeed:
        """The planner for a ContouringFeed-v0 env (its override range), with the settings
        above."""
        base = unwrap_as(env, ContouringFeedEnv, "LookAheadFeed")
        return cls(base.override_max, *args, **kwargs)

    def _act(self, obs, state):
        feed = np.maximum(100.0 * obs[:, 12].astype(np.float64), 1e-9)
        heading = obs[:, 7:12].astype(np.float64) * math.pi
        turn = np.abs(np.diff(heading, axis=1, prepend=0.0))
        kappa = turn / np.diff(self._d, prepend=0.0)
        with np.errstate(divide="ignore"):
            v_win = np.sqrt(self.centripetal_mm_s2 / kappa)  # inf on a straight window
        start = np.concatenate(([0.0], self._d[:-1]))
        v = np.min(np.sqrt(v_win**2 + 2.0 * self.tangential_mm_s2 * start), axis=1)
        left = 100.0 * obs[:, 6].astype(np.float64)
        v = np.minimum(v, np.sqrt(2.0 * self.tangential_mm_s2 * np.maximum(left, 0.0)))
        # A floor keeps the set point moving: slowing to zero at the path's end would
        # approach it without ever arriving.
        override = np.clip(v / feed, MIN_OVERRIDE, self.override_cap)
        return (2.0 * override / self.override_max - 1.0)[:, None]


class ContourAFC(Agent):
    r"""Adaptive feed control on the contour error: the industrial AFC's law
    (:class:`agents.AdaptiveFeedControl`) with the contour error as the load, on
    ContouringFeed-v0's override.

    The programmed feed is the look-ahead planner's (:class:`LookAheadFeed`: the feed the
    CNC's planner allows from the path previewed ahead); the controller moves a factor
    ``k`` on it to hold the largest contour error of each decision at ``reference`` x the
    tolerance, by integral action on the relative error, fast down and slow up:

    .. math:: k_j = \mathrm{clip}\big(k_{j-1} + g\,\rho_j\,(1 - e_j / (r\,\varepsilon)),
              f_{min}, f_{max}\big), \qquad o_j = \mathrm{clip}(k_j\, o^{plan}_j, 0,
              o_{max})

    at decision ``j``, with ``e_j`` the largest contour error over the decision before
    (observation 1, as a multiple of the tolerance ``epsilon``; 0 at the start),
    ``o^plan_j`` the planner's override, ``k_{-1} = fent`` and ``rho_j = 1`` where the
    error is above the reference, ``rise`` where below. Feedback on what the table does,
    where the planner alone cannot know the episode's axes (their inertias vary) nor the
    override's handling (a machine's delay and rate limits). Unlike a force in turning,
    the contour error is near zero on every straight and peaks at the corners: a
    symmetric integral would speed up on each straight and arrive at the next corner too
    fast. So an error above the reference slows the rest of the path at once, and the
    factor recovers slowly (``rise`` of the gain) while the path is cut within it. It
    reads nothing hidden.

    The defaults (reference 0.7, gain 0.2, rise 0.01, fmax 1.2, fent 0.9) were chosen on
    ``train`` episodes of the shop-floor machine; ``TUNABLE`` has the planner's three and
    the feedback's ``reference``, ``gain`` and ``rise``.

    Parameters
    ----------
    override_max : float
        The env's largest override (action +1).
    reference : float
        The contour error held, as a share of the tolerance, in (0, 2].
    gain : float
        Change of the factor per decision per unit of relative error, in (0, 2].
    rise : float
        The share of ``gain`` while the error is below the reference, in (0, 1].
    fmin, fmax : float
        Bounds of the factor: ``fmin`` in [0.05, 1], ``fmax`` in [1, 5].
    fent : float
        The factor at the path's start, in [0.05, 1].
    centripetal_mm_s2, tangential_mm_s2, override_cap : float
        The planner's (:class:`LookAheadFeed`).
    """

    state_size = 1  # the factor k
    obs_dim = 16
    #: The settings after ``override_max``: the feedback's (default, accepted range, search
    #: range), then the planner's.
    SETTINGS = {
        "reference": Setting(0.7, hi=2.0, search=(0.3, 1.0, False)),
        "gain": Setting(0.2, hi=2.0, search=(0.01, 1.0, True)),
        "rise": Setting(0.01, hi=1.0, search=(0.002, 0.5, True)),
        "fmin": Setting(0.2, lo=0.05, hi=1.0, lo_open=False),
        "fmax": Setting(1.2, lo=1.0, hi=5.0, lo_open=False),
        "fent": Setting(0.9, lo=0.05, hi=1.0, lo_open=False),
        **LookAheadFeed.SETTINGS,
    }
    #: Free parameters and their search ranges for tuning: the planner's, the feedback's.
    TUNABLE = {**LookAheadFeed.TUNABLE, **tunable(SETTINGS)}

    def __init__(self, override_max: float, *args, **kwargs):
        self.configure(args, kwargs)
        planner = {k: getattr(self, k) for k in LookAheadFeed.SETTINGS}
        self.planner = LookAheadFeed(override_max, **planner)
        self.override_max = self.planner.override_max
        self.override_cap = self.planner.override_cap
        self.name = f"contour AFC ref {self.reference:.2g}"

    @classmethod
    def from_env(cls, env, **kwargs) -> ContourAFC:
        """The controller for a ContouringFeed-v0 env (its override range); ``kwargs``: the
        settings above and the planner's."""
        base = unwrap_as(env, ContouringFeedEnv, "ContourAFC")
        return cls(base.override_max, **kwargs)

    def initial_state(self, n, obs):
        return np.full((n, self.state_size), self.fent)

    def _act(self, obs, state):
        k = state[:, 0]
        e = obs[:, 1].astype(np.float64)  # largest contour error of the decision / tolerance
        rel = 1.0 - e / self.reference
        k = np.clip(k + self.gain * np.where(rel > 0, self.rise, 1.0) * rel, self.fmin, self.fmax)
        state[:, 0] = k
        plan = 0.5 * (self.planner._act(obs, state[:, :0])[:, 0] + 1.0) * self.override_max
        override = np.clip(k * plan, 0.0, self.override_max)
        return (2.0 * override / self.override_max - 1.0)[:, None]


if __name__ == "__main__":  # pragma: no cover - regenerates BASELINE_OVERRIDE
    for servo in ("pi", "hinf"):
        print(servo, calibrate_constant_override({"servo": servo}, verbose=True))
