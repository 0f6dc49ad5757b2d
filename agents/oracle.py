"""MPC oracles: the best that control with perfect knowledge achieves, the row every other
agent is read against.

**An oracle reads the hidden truth.** Unlike every other agent of the library, which
reads only the observation, an oracle is built from the env it runs in and reads that env's
true plant (the cut's real force law), its true state and the whole workpiece ahead. No
controller on a machine could; that is the point: it shows how far the task can be pushed.

:class:`TurningMPCOracle` (Turning-v0) solves, every sample, a nonlinear program with
CasADi and IPOPT over the next ``horizon`` samples: the commands that carry the tool
furthest along the workpiece while the force at every sample instant stays at or below
``margin`` x the limit. The model is the plant's own exact sampled linear part
(``machining_envs.turning.plant.sampled_model``: servo, gear train and the feed per
revolution as the moving integral of the feed velocity) with the cut's true force law
``F = Kf f^p a(x)`` and the previewed depth ``a(x)``; what it leaves out is the force
between sample instants (only the breakage check reads it, at 3x the limit). The force
constraint is kept as ``f <= f*(x) = (margin L / (Kf a(x)))^(1/p)``, with ``f*`` tabulated
along the workpiece on a 0.02 mm grid, each node taking the deepest cut within a node of it
(so a depth step is never underestimated), and softened by a slack variable with a large
cost so that IPOPT always returns a command.

:class:`MillingMPCOracle` (EndMilling-v0) does the same on the milling plant's exact
sampled servo (the feed velocity and position at the 10 sub-steps of a sample), the cut's
true torque law ``T = c d(x)^l f_t^e`` at those sub-steps and the process lag (eq. 10)
over them, constraining the lagged torque at every sample instant (what ``info["cost"]``
reads); ``c d^l`` is tabulated along the workpiece the same way.

Both run one episode at a time on a single env (``evaluate(..., batched=False)``); under
SB3's ``evaluate_policy``, build it from the env inside the ``DummyVecEnv``
(``TurningMPCOracle.from_env(vec_env.envs[0])``). Needs CasADi (the ``bench`` extra).
"""

from __future__ import annotations

import numpy as np

from agents.base import Agent, check_positive, unwrap_as
from machining_envs.milling.env import EndMillingEnv
from machining_envs.turning.env import TurningEnv
from machining_envs.turning.plant import sampled_model

__all__ = ["TurningMPCOracle", "MillingMPCOracle"]

#: Grid of the tabulated feed limit along the workpiece, mm.
GRID_MM = 0.02
#: Feed per revolution that stands for "no limit" (in air), mm/rev: above any the servo
#: reaches (5.8 mm/s at 200 rpm is 1.7 mm/rev).
FREE_FEED = 5.0


def _deepest_depth(profile, end_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """The preview table: a ``GRID_MM`` grid from 1 mm before the workpiece to ``end_mm``
    + 1 mm, and at each node the deepest cut within one node of it (so that linear
    interpolation between nodes never underestimates a depth step)."""
    grid = np.arange(-1.0, end_mm + 1.0, GRID_MM)
    depth = np.asarray(profile(grid), dtype=float)
    return grid, np.maximum.reduce([depth, np.roll(depth, 1), np.roll(depth, -1)])


def _casadi():
    try:
        import casadi
    except ImportError as e:  # pragma: no cover - exercised without the extra
        raise ImportError("the MPC oracle needs CasADi: pip install 'machining-envs[bench]'") from e
    return casadi


class TurningMPCOracle(Agent):
    """MPC with the true plant and the workpiece previewed (see the module docstring).

    Parameters
    ----------
    env
        The Turning-v0 env (any wrapper of it) the oracle acts in; it reads its truth.
    horizon : int
        Samples predicted (default 15: 1.5 s, three times the servo's settling time, and
        up to 8 mm of workpiece at the top feed).
    margin : float
        Share of the limit the predicted force may reach (default 0.99: one per cent for
        IPOPT's tolerances and the tabulated preview; the count rule charges every sample
        over the limit itself).
    """

    state_size = 0
    obs_dim = 7

    def __init__(self, env, horizon: int = 15, margin: float = 0.99, base=None):
        self.env = base if base is not None else unwrap_as(env, TurningEnv, "TurningMPCOracle")
        if isinstance(horizon, bool) or not isinstance(horizon, int) or not 2 <= horizon <= 100:
            raise ValueError(f"horizon must be an integer in [2, 100], got {horizon!r}")
        self.horizon = horizon
        self.margin = check_positive("margin", margin, 1.0)
        self.name = "MPC oracle"
        self._episode = None
        self._u_prev = None

    @classmethod
    def from_env(cls, env, horizon: int = 15, margin: float = 0.99) -> TurningMPCOracle:
        return cls(env, horizon, margin)

    # ---- the NLP, built once per episode ---------------------------------------------------
    def _build(self, scenario) -> None:
        ca = _casadi()
        base = self.env
        truth = scenario.true_params(base.params)
        big, m = sampled_model(truth, scenario.spindle_rpm)
        c = int(base.plant.cols[0])
        rows = big.reshape(2 * m + 3, -1)[:, :c]
        pick = rows[[m - 1, 2 * m - 1, 2 * m, 2 * m + 1, 2 * m + 2]]  # position, feed, state
        kf, p = truth.force_coefficient, truth.feed_exponent
        limit = self.margin * scenario.force_limit_N
        prof = scenario.profile
        length = prof.length_mm
        reach = truth.max_feed_velocity_mm_s * truth.sample_time_s * (self.horizon + 2)
        grid, deepest = _deepest_depth(prof, length + reach)
        with np.errstate(divide="ignore"):
            fstar = np.where(deepest > 0, (limit / (kf * deepest)) ** (1.0 / p), FREE_FEED)
        fstar = np.minimum(fstar, FREE_FEED)
        f_of_x = ca.interpolant("fstar", "linear", [grid], fstar)

        opti = ca.Opti()
        u = opti.variable(self.horizon)
        slack = opti.variable(self.horizon)
        z0 = opti.parameter(c)
        b = ca.DM(pick)
        z = ca.vertcat(z0[0:3], u[0], z0[4:c])
        cost = 0
        pos = None
        for k in range(self.horizon):
            y = ca.mtimes(b, z)
            pos, feed = y[0], y[1]
            opti.subject_to(feed <= f_of_x(pos) + slack[k])
            cost += 1e3 * slack[k]
            if k + 1 < self.horizon:
                z = ca.vertcat(y[2:5], u[k + 1], z[0 : c - 4])
        self._c = c
        self._finish(opti, u, slack, z0, -pos + cost, truth.command_max)

    def _finish(self, opti, u, slack, values, objective, umax: float) -> None:
        """Objective (with a tiny penalty on command changes), bounds and IPOPT on the
        built NLP, made one CasADi function for the episode's solves: ``(plant memory,
        initial commands, initial slacks, initial multipliers) -> (commands, slacks,
        multipliers)``. Each solve starts from the last one's solution shifted by a sample
        and its constraint multipliers (IPOPT's warm start), to a tolerance of 1e-6."""
        ca = _casadi()
        opti.minimize(objective + 1e-9 * ca.sumsqr(ca.diff(u)))
        opti.subject_to(opti.bounded(0.0, u, umax))
        opti.subject_to(slack >= 0)
        ipopt = {
            "print_level": 0,
            "sb": "yes",
            "max_iter": 200,
            "tol": 1e-6,
            "warm_start_init_point": "yes",
            "mu_init": 1e-4,
            "warm_start_bound_push": 1e-6,
            "warm_start_mult_bound_push": 1e-6,
        }
        # IPOPT's last iterate where it does not converge (no exception): _solve checks it.
        opti.solver("ipopt", {"print_time": False, "error_on_fail": False}, ipopt)
        self._fn = opti.to_function("mpc", [values, u, slack, opti.lam_g], [u, slack, opti.lam_g])
        self._lam = np.zeros(opti.ng)
        self._umax = umax
        self._u_prev = np.zeros(self.horizon)

    def _solve(self, z: np.ndarray) -> float:
        guess = np.append(self._u_prev[1:], self._u_prev[-1])
        u, _, lam = self._fn(z, guess, np.zeros(self.horizon), self._lam)
        u = np.asarray(u, dtype=float).reshape(-1)
        lam = np.asarray(lam, dtype=float).reshape(-1)
        if not np.all(np.isfinite(u)):
            u, lam = guess, np.zeros_like(lam)
        self._lam = lam
        u = np.clip(u, 0.0, self._umax)
        self._u_prev = u
        return float(u[0])

    def _nlp_values(self) -> np.ndarray:
        """The parameters of the NLP now: the plant's memory ``z``."""
        return self.env.plant.z[0, : self._c].copy()

    def _clock(self) -> float:
        return float(self.env.plant.lane_f[0, 5])

    def _command_to_action(self, command: float) -> np.ndarray:
        return np.array([[2.0 * command / self._umax - 1.0]])

    # ---- the agent protocol ---------------------------------------------------------------
    def _act(self, obs, state):
        who = type(self).__name__
        if obs.shape[0] != 1:
            raise ValueError(f"{who} runs one env at a time (batched=False)")
        base = self.env
        if base.plant is None:
            raise RuntimeError(f"{who}: reset the env before predicting")
        if self._episode is not base.scenario or self._clock() == 0.0:
            self._build(base.scenario)
            self._episode = base.scenario
        return self._command_to_action(self._solve(self._nlp_values()))


class MillingMPCOracle(TurningMPCOracle):
    """MPC with the true plant and the workpiece previewed, for EndMilling-v0 (see the
    module docstring). Parameters as :class:`TurningMPCOracle`, but ``horizon`` 6 by default
    (0.6 s: eight times the process lag and the servo's decay time; 15 samples gave a 0.3 %
    shorter machining time on the paper's step workpiece at six times the cost)."""

    def __init__(self, env, horizon: int = 6, margin: float = 0.99):
        base = unwrap_as(env, EndMillingEnv, "MillingMPCOracle")
        super().__init__(env, horizon, margin, base=base)

    @classmethod
    def from_env(cls, env, horizon: int = 6, margin: float = 0.99) -> MillingMPCOracle:
        return cls(env, horizon, margin)

    def _nlp_values(self) -> np.ndarray:
        lanes = self.env.plant
        return np.concatenate([lanes.z[0, :3], lanes.buf[0, :2]])

    def _clock(self) -> float:
        return self.env.plant.cut_model(0).t_s

    def _build(self, scenario) -> None:
        ca = _casadi()
        lanes = self.env.plant
        m = lanes.m
        cut = lanes.cut_model(0)
        big = lanes.big.reshape(2 * m + 3, 4)
        lag = lanes.lag[0].reshape(m, m + 2)
        ftpv, e = cut.ft_per_vf, cut.feed_exponent
        c, l_exp = cut.torque_gain, cut.depth_exponent
        umax = cut.command_max
        limit = self.margin * float(self.env._core.torque_limit[0])
        prof = scenario.profile
        reach = umax * self.env.params.servo_gain * self.env.params.sample_time_s
        grid, deepest = _deepest_depth(prof, prof.length_mm + reach * (self.horizon + 2))
        gain = ca.interpolant("gain", "linear", [grid], c * deepest**l_exp)

        opti = ca.Opti()
        u = opti.variable(self.horizon)
        slack = opti.variable(self.horizon)
        s0 = opti.parameter(5)  # [Vf, dVf/dt, x, T, u_0]
        b = ca.DM(big)
        lg = ca.DM(lag)
        x3, torque, last = s0[0:3], s0[3], s0[4]
        pos = None
        cost = 0
        for k in range(self.horizon):
            w = ca.mtimes(b, ca.vertcat(x3, u[k]))
            v, xs = w[0:m], w[m : 2 * m]
            static = [gain(xs[j]) * (ftpv * ca.fmax(v[j], 1e-9)) ** e for j in range(m)]
            lagged = ca.mtimes(lg, ca.vertcat(torque, last, *static))
            torque, last = lagged[m - 1], static[-1]
            opti.subject_to(torque <= limit + slack[k])
            cost += slack[k]  # 1 mm of progress per N·mm over: never worth it
            x3 = w[2 * m : 2 * m + 3]
            pos = x3[2]
        self._finish(opti, u, slack, s0, -pos + cost, umax)

    def _command_to_action(self, command: float) -> np.ndarray:
        return np.array([[float(self.env.command_map.command_to_action(command))]])
