"""Where the benchmark's figures go: one resolution, the folder made on the way."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

#: Resolution of every figure the benchmark writes, dots per inch.
DPI = 90


def save_figure(fig, path) -> Path:
    """Write the matplotlib figure ``fig`` to ``path`` (its folder made if missing)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    return path


def reproduction_figure(out_dir, name: str, draw: Callable[[Path], None], verbose: bool) -> None:
    """A paper reproduction's figure: ``draw(out_dir / name)`` where ``out_dir`` is given
    (None: no figure), and its path printed when ``verbose``."""
    if out_dir is None:
        return
    path = Path(out_dir) / name
    draw(path)
    if verbose:
        print(f"figure: {path}")
