"""What the envs' ``render()`` share: the signals an episode records (:class:`EpisodeLog`),
stacked plots of them as an RGB array (:func:`render_signals`), and the render-mode checks."""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np

__all__ = [
    "EpisodeLog",
    "render_signals",
    "present_frame",
    "check_render_mode",
    "ready_to_render",
    "record_step",
]


def render_signals(
    t: Sequence[float],
    panels: Sequence[tuple[str, Sequence[tuple[str, Sequence[float], str]]]],
    title: str,
) -> np.ndarray:
    """Plot stacked panels of signals against time and return the image as an RGB array.

    ``panels`` is a list of ``(y label, [(legend, values, style), ...])``.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - matplotlib is a dependency
        raise ImportError("rendering needs matplotlib: pip install matplotlib") from exc
    fig = Figure(figsize=(7, 2.0 * len(panels) + 0.6), dpi=80)
    canvas = FigureCanvasAgg(fig)
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (ylabel, lines) in zip(axes, panels, strict=True):
        for label, values, style in lines:
            ax.plot(t, values, style, label=label, lw=1.2)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        if len(lines) > 1:
            ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title, fontsize=10)
    fig.tight_layout()
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def present_frame(img: np.ndarray, render_mode: str, window: str):
    """What ``render()`` returns: the image for ``"rgb_array"``; for ``"human"`` the image is
    shown in a matplotlib window named ``window`` and ``None`` is returned."""
    if render_mode != "human":
        return img
    import matplotlib.pyplot as plt

    plt.figure(window)
    plt.clf()
    plt.imshow(img)
    plt.axis("off")
    plt.pause(0.001)
    return None


def check_render_mode(render_mode, modes) -> str | None:
    """``render_mode`` if it is None or one of ``modes``, else ``ValueError``."""
    if render_mode is not None and render_mode not in modes:
        raise ValueError(f"render_mode must be None or one of {modes}, got {render_mode!r}")
    return render_mode


class EpisodeLog:
    """The signals an env keeps for ``render()``: a list per name, each fed by one ``info`` key.

    Parameters
    ----------
    fields : dict of str to str
        Name of each signal -> the ``info`` key it is read from.

    >>> log = EpisodeLog({"t": "t_s", "force": "force_N"})
    >>> log.record({"t_s": 0.1, "force_N": 950.0, "scenario": "train"})
    >>> log["t"], log["force"]
    ([0.1], [950.0])
    """

    def __init__(self, fields: dict[str, str]) -> None:
        self.fields = dict(fields)
        self._signals: dict[str, list] = {name: [] for name in self.fields}

    def record(self, info: dict) -> None:
        """Append this step's value of every signal from its ``info``."""
        signals = self._signals
        for name, key in self.fields.items():
            signals[name].append(info[key])

    def __getitem__(self, name: str) -> list:
        return self._signals[name]


def record_step(env, log: EpisodeLog, info: dict) -> None:
    """The end of every env's ``step``: with a render mode, ``info`` goes into ``log``, and in
    ``"human"`` mode the window is drawn again."""
    if env.render_mode is not None:
        log.record(info)
        if env.render_mode == "human":
            env.render()


def ready_to_render(env) -> bool:
    """False (with a warning) without a render mode; ``RuntimeError`` before the first reset."""
    owner = type(env).__name__
    if env.render_mode is None:
        gym.logger.warn(
            f"{owner}.render() called without a render_mode; pass render_mode='rgb_array'"
        )
        return False
    if not env._started:
        raise RuntimeError(f"{owner}: call reset() before render()")
    return True
