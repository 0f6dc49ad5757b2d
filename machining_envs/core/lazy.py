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

__all__ = ["lazy_exports", "by_module", "env_entry_points", "process_package"]


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


def by_module(package: str, **modules: tuple[str, ...]) -> dict[str, str]:
    """:func:`lazy_exports`'s ``names`` from the names each module of ``package`` exports:
    ``by_module("machining_envs.turning", plant=("TurningParams",))`` is
    ``{"TurningParams": "machining_envs.turning.plant"}``."""
    return {name: f"{package}.{module}" for module, names in modules.items() for name in names}


def env_entry_points(package: str, envs: dict[str, tuple]) -> tuple[dict, dict]:
    """``(ENTRY_POINTS, VECTOR_ENTRY_POINTS)`` of a process package (what ``machining_envs``
    registers): ``envs`` maps each env name (``"Turning-v0"``, registered as
    ``machining_envs/Turning-v0``) to its module in ``package`` and the names of its single
    and its native vector env classes (``gym.make_vec(id, num_envs=N)``; None for an env
    without one, which ``gym.make_vec`` then vectorises itself)."""
    single, vector = {}, {}
    for env, (module, single_cls, vector_cls) in envs.items():
        single[f"machining_envs/{env}"] = f"{package}.{module}:{single_cls}"
        if vector_cls is not None:
            vector[f"machining_envs/{env}"] = f"{package}.{module}:{vector_cls}"
    return single, vector


def process_package(
    package: str, envs: dict[str, tuple], **modules: tuple[str, ...]
) -> tuple[list[str], Callable, Callable, dict, dict]:
    """What a process package's ``__init__`` declares, from its exports and its env ids:
    ``(__all__, __getattr__, __dir__, ENTRY_POINTS, VECTOR_ENTRY_POINTS)``, the names each
    module of ``package`` exports (``modules`` as for :func:`by_module`), loaded on first use
    (:func:`lazy_exports`), and the ids ``envs`` (as for :func:`env_entry_points`)::

        __all__, __getattr__, __dir__, ENTRY_POINTS, VECTOR_ENTRY_POINTS = process_package(
            __name__,
            {"Turning-v0": ("env", "TurningEnv", "TurningVectorEnv")},
            env=("TurningEnv", "TurningVectorEnv"),
            plant=("TurningParams",),
        )
    """
    exports = by_module(package, **modules)
    single, vector = env_entry_points(package, envs)
    getattr_, dir_ = lazy_exports(package, exports)
    return [*exports, "ENTRY_POINTS", "VECTOR_ENTRY_POINTS"], getattr_, dir_, single, vector
