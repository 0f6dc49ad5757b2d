"""The benchmark, the paper reproductions and the command line (``machining-bench``).

``spec`` defines what a process declares (:class:`~agents.bench.spec.Process`);
``turning``, ``milling``, ``drilling`` and ``contouring`` each hold one process's
reproduction and declaration; ``declarations`` lists them; ``benchmark`` runs every
declared benchmark; ``cli`` is the command line. This layer uses ``agents.rl`` (pretrained
policies) and ``agents.eval`` (the harness); nothing below imports it.
"""
