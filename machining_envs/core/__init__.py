"""What every process shares: exact discretisation of linear dynamics (``lti``), the
action map, input checks and rendering helpers of the envs (``env``), depth profiles of
workpieces (``workpieces``), the regulation metrics (``metrics``) and the primary score
of a task (``score``). Nothing here knows any one process."""
