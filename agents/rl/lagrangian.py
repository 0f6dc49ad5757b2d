"""Constrained training: the Lagrangian relaxation of PPO (PPO-Lagrangian) as one SB3 callback.

The machining envs report a per-step constraint cost, ``info["cost"]`` (1.0 on a step whose
regulated signal is above the process limit, Safety-Gymnasium's convention). The benchmark
counts a workpiece only if few of its steps had a cost, so a policy should treat the limit as
a constraint, not as one more reward term whose weight was guessed:

.. math::

    \\max_\\pi \\; J_r(\\pi) \\quad \\text{s.t.} \\quad J_c(\\pi) \\le b,

with :math:`J_c` the mean cost per step and :math:`b` the budget (a share of steps). Its
Lagrangian :math:`J_r - \\lambda (J_c - b)` is optimised by PPO on the reward
:math:`r_t - \\lambda c_t`, and the multiplier follows the constraint by projected dual
ascent after each rollout:

.. math::

    \\lambda \\leftarrow \\min(\\lambda_{\\max}, \\max(0, \\lambda + \\eta (\\bar c - b))),

where :math:`\\bar c` is the rollout's mean cost. A rollout over budget raises the price of a
cost, one under it lowers it, down to zero where the constraint is slack.

:class:`LagrangianCallback` does this inside Stable-Baselines3's own PPO (or A2C): it reads
each step's cost from the env's infos, and at the end of a rollout subtracts
:math:`\\lambda c_t` from the rollout buffer's rewards, recomputes the returns and advantages
(GAE) from the values PPO already holds, and then updates :math:`\\lambda`. The env, the
policy and what a trained policy replays are unchanged, so a run trains with
``machining-bench train`` and with ``python -m rl_zoo3.train`` from the same configuration
entry (``callback: - agents.rl.lagrangian.LagrangianCallback: {budget: 0.005}``). When the
rewards are normalised (``VecNormalize``), the penalty is in the normalised reward's units;
the multiplier finds its own scale.
"""

from __future__ import annotations

import math

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from machining_envs.core.checks import is_real

__all__ = ["LagrangianCallback"]


def _check(name: str, value, lo: float, hi: float, lo_open: bool = False) -> float:
    ok = is_real(value) and math.isfinite(value) and (value > lo if lo_open else value >= lo)
    if not ok or value > hi:
        bounds = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
        raise ValueError(f"LagrangianCallback: {name} must be a number in {bounds}, got {value!r}")
    return float(value)


class LagrangianCallback(BaseCallback):
    """PPO-Lagrangian: the per-step cost as a constraint with a budget, by dual ascent.

    Parameters
    ----------
    budget : float
        The allowed mean cost per step, in [0, 1]; with ``info["cost"]`` the over-limit
        indicator, the share of steps allowed over the limit (0.005: half a percent, well
        inside the benchmark's allowances).
    multiplier_lr : float
        The dual step :math:`\\eta` > 0: how much the multiplier moves per unit of the
        rollout's cost rate above the budget.
    initial_multiplier : float
        :math:`\\lambda` at the start, >= 0.
    max_multiplier : float
        The ceiling of :math:`\\lambda`, > 0 (it keeps one bad rollout from wiping out the
        reward).
    cost_key : str
        The info entry that holds the per-step cost.
    """

    def __init__(
        self,
        budget: float = 0.005,
        multiplier_lr: float = 20.0,
        initial_multiplier: float = 0.0,
        max_multiplier: float = 100.0,
        cost_key: str = "cost",
        verbose: int = 0,
    ):
        super().__init__(verbose)
        self.budget = _check("budget", budget, 0.0, 1.0)
        self.multiplier_lr = _check("multiplier_lr", multiplier_lr, 0.0, math.inf, lo_open=True)
        self.max_multiplier = _check("max_multiplier", max_multiplier, 0.0, math.inf, True)
        self.multiplier = _check("initial_multiplier", initial_multiplier, 0.0, self.max_multiplier)
        if not isinstance(cost_key, str) or not cost_key:
            raise ValueError(f"LagrangianCallback: cost_key must be a name, got {cost_key!r}")
        self.cost_key = cost_key
        #: One row per rollout: (timesteps, cost rate, multiplier used, multiplier after).
        self.history: list[tuple[int, float, float, float]] = []
        self._costs: list[np.ndarray] = []

    def _init_callback(self) -> None:
        from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

        if not isinstance(self.model, OnPolicyAlgorithm):
            raise TypeError(
                "LagrangianCallback works on on-policy algorithms (PPO, A2C), whose rollout "
                f"it re-weights; got {type(self.model).__name__}"
            )

    def _on_rollout_start(self) -> None:
        self._costs = []

    def _on_step(self) -> bool:
        infos = self.locals["infos"]
        try:
            cost = [float(info[self.cost_key]) for info in infos]
        except KeyError:
            have = sorted(k for k in infos[0] if not k.startswith("_")) if infos else []
            raise ValueError(
                f"LagrangianCallback: the env's info has no {self.cost_key!r} (it has {have}); "
                "a native vector env must pass its info to SB3 (train with a callback "
                "configured keeps every key)"
            ) from None
        costs = np.asarray(cost, dtype=np.float64)
        if not np.all(np.isfinite(costs)):
            raise ValueError(f"LagrangianCallback: non-finite {self.cost_key!r} in the info")
        self._costs.append(costs)
        return True

    def _on_rollout_end(self) -> None:
        buffer = self.model.rollout_buffer
        if len(self._costs) != buffer.buffer_size:
            raise RuntimeError(
                f"LagrangianCallback: {len(self._costs)} steps of cost for a rollout of "
                f"{buffer.buffer_size}"
            )
        costs = np.stack(self._costs).astype(buffer.rewards.dtype)
        used = self.multiplier
        if used > 0.0:
            buffer.rewards -= used * costs
            buffer.compute_returns_and_advantage(
                last_values=self.locals["values"], dones=self.locals["dones"]
            )
        rate = float(costs.mean())
        self.multiplier = min(
            self.max_multiplier, max(0.0, used + self.multiplier_lr * (rate - self.budget))
        )
        self.history.append((int(self.num_timesteps), rate, used, self.multiplier))
        self.logger.record("lagrangian/cost_rate", rate)
        self.logger.record("lagrangian/multiplier", self.multiplier)
        if self.verbose:
            print(
                f"lagrangian: cost rate {rate:.4f} (budget {self.budget}), "
                f"multiplier {used:.3f} -> {self.multiplier:.3f}"
            )
