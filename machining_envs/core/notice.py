"""A one-line notice on stderr while numba compiles this package's kernels.

The first use of an env on a machine (or after an upgrade) compiles its kernels, about
30 s an env; numba then caches them in the package's ``__pycache__`` and every later
process loads them in a fraction of a second. Without a word, those 30 s look like a hang,
so :func:`announce_compiling` (installed by :mod:`machining_envs.core.compiled.kernels`, which every
env imports) listens to numba's ``numba:compile`` events, which fire only where the cache
has nothing, and prints one line the first time a function of the package compiles in a
process (later ones compile without a word: the line has said what the wait is).
``machining-bench warmup`` compiles every env's kernels ahead.

This module imports numba only when installed; it knows nothing of gymnasium.
"""

from __future__ import annotations

import sys

__all__ = ["announce_compiling"]

_installed = False
_announced = False


def _notice(module: str) -> str | None:
    """The line for a compile of a function of ``module``; None where there is none to
    print (another package's function, or one said already)."""
    global _announced
    if _announced or module.split(".")[0] != "machining_envs":
        return None
    _announced = True
    return (
        "machining_envs: compiling the numba kernels on first use (up to a minute an env; "
        "cached afterwards; `machining-bench warmup` compiles every env ahead)"
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
