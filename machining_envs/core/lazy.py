"""Names a package exports without importing them until they are used (PEP 562).

``import machining_envs`` only registers the env ids (string entry points); the env
classes, plants and their compiled kernels (numba, scipy) load when first used, by
``gym.make`` or by ``from machining_envs import TurningEnv``. So a worker process that
only needs the ids pays little for the import.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable

__all__ = ["lazy_exports"]


def lazy_exports(package: str, names: dict[str, str]) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` for the module ``package`` that import ``names[attr]``
    (a module path) on first access of ``attr`` and return its attribute ``attr``."""

    def __getattr__(attr: str):
        module = names.get(attr)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {attr!r}")
        value = getattr(importlib.import_module(module), attr)
        setattr(sys.modules[package], attr, value)  # later lookups skip this function
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(names))

    return __getattr__, __dir__
