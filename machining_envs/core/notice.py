"""A one-line notice on stderr while numba compiles this package's kernels.

The first use of an env on a machine (or after an upgrade) compiles its kernels, about
30 s an env; numba then caches them in the package's ``__pycache__`` and every later
process loads them in a fraction of a second. Without a word, those 30 s look like a hang,
so :func:`announce_compiling` (installed by :mod:`machining_envs.core.kernels`, which every
env imports) listens to numba's ``numba:compile`` events, which fire only where the cache
has nothing, and prints one line the first time each part of the package (a process, or
the shared ``core``) compiles in a process. ``machining-bench warmup`` compiles every
env's kernels ahead.

This module imports numba only when installed; it knows nothing of gymnasium.
"""

from __future__ import annotations

import sys

__all__ = ["announce_compiling"]

_installed = False
_announced: set[str] = set()


def _notice(module: str) -> str | None:
    """The line for a compile of a function of ``module``; None where there is none to
    print (another package's function, or a part already announced)."""
    parts = module.split(".")
    if parts[0] != "machining_envs" or len(parts) < 2:
        return None
    part = parts[1]
    if part in _announced:
        return None
    _announced.add(part)
    what = "the shared" if part == "core" else f"the {part}"
    return (
        f"machining_envs: compiling {what} kernels (numba, first use on this machine: up to "
        "a minute; cached afterwards; `machining-bench warmup` compiles every env ahead)"
    )


def announce_compiling() -> None:
    """Install the listener (once a process)."""
    global _installed
    if _installed:
        return
    from numba.core import event

    class _Listener(event.Listener):
        def on_start(self, ev):
            dispatcher = (ev.data or {}).get("dispatcher")
            func = getattr(dispatcher, "py_func", None)
            line = _notice(getattr(func, "__module__", None) or "")
            if line is not None:
                print(line, file=sys.stderr, flush=True)

        def on_end(self, ev):
            pass

    event.register("numba:compile", _Listener())
    _installed = True
