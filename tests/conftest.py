"""Every test session registers the env ids first (the shared helpers are in
``tests/helpers.py``; the conventions every env keeps are in ``tests/envs``)."""

import machining_envs  # noqa: F401  (registers the env ids)
