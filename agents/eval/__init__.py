"""Evaluation: the harness that runs any agent on any env over the same scenarios, seeds and
metrics (``harness``), and the score tables built from its rows (``tables``).

>>> from agents import VariableGainPI
>>> from agents.eval import evaluate
>>> ev = evaluate(VariableGainPI.from_env, "machining_envs/Turning-v0", ["paper_405"], n_episodes=1)
>>> row = ev.rows[0]
>>> row["agent"], row["scenario"], row["breakage"], row["finished"]
('adaptive PI K=0.5', 'paper_405', 0.0, 1.0)
"""

from agents.eval.harness import Evaluation, agent_name, evaluate, rollout, task_of
from agents.eval.tables import primary_score_table

__all__ = ["Evaluation", "agent_name", "evaluate", "rollout", "task_of", "primary_score_table"]
