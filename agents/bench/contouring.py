"""Paper reproduction for contouring (Choi et al., seed 004, Fig. 4-8): PI vs H-infinity 2-DOF.

Each experiment runs ``PIPosition`` and ``HInf2DOF`` on ``Contouring-v0`` with the paper's
scenario and compares one measured quantity with the paper's statement:

- Fig. 4, unit step (``paper_step``): the H-infinity loop settles (2 %) faster than the
  PI loop; neither overshoots by more than 2 %;
- Fig. 5, step with a load-torque step (``paper_step_load``): after the load steps on, the
  H-infinity output deviates at most a fifth as far from its set point as the PI output
  (the paper: "PI shows overshoot and degraded performance; H-infinity is robust" - its
  plot shows a visible PI excursion and a flat H-infinity trace);
- Fig. 6-8, corner, circle, involute: the H-infinity loop's largest contour error is at
  least ``CONTOUR_RATIO`` (5) times smaller than the PI loop's ("much smaller contour
  errors"); on the circle the PI loop also shows a radius reduction (the circle shrinks)
  and an ellipse at least five times the H-infinity loop's ("radius reduction and
  ellipse with PI, corrected by the feedforward").
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from agents.bench.figures import reproduction_figure, save_figure
from agents.bench.spec import BenchmarkSpec, Process
from agents.contouring import ConstantOverride, ContourAFC, HInf2DOF, LookAheadFeed, PIPosition
from agents.eval import rollout
from machining_envs.contouring.metrics import contouring_metrics
from machining_envs.contouring.paths import Path
from machining_envs.contouring.scenarios import PAPER_LOAD_TIME_S, PAPER_STEP_MM
from machining_envs.contouring.servo import HINF_MODEL_POLE

__all__ = [
    "ContouringExperiment",
    "CONTOURING_EXPERIMENTS",
    "CONTOUR_RATIO",
    "LOAD_RATIO",
    "step_metrics",
    "reproduce_contouring",
]

#: H-infinity's largest contour error must be at least this many times smaller than PI's.
CONTOUR_RATIO = 5.0
#: ... and its deviation under the load step at least this many times smaller.
LOAD_RATIO = 5.0

_ENV = "machining_envs/Contouring-v0"


@dataclass(frozen=True)
class ContouringExperiment:
    figure: str
    scenario: str
    test: str
    paper: str


CONTOURING_EXPERIMENTS = (
    ContouringExperiment(
        "Fig. 4", "paper_step", "unit step (X)", "H-inf 2-DOF follows the step faster"
    ),
    ContouringExperiment(
        "Fig. 5",
        "paper_step_load",
        "load-torque step 1 N m",
        "PI is disturbed (overshoot); H-inf is robust",
    ),
    ContouringExperiment(
        "Fig. 6", "paper_corner", "corner, 5 mm/s", "H-inf: much smaller corner error"
    ),
    ContouringExperiment(
        "Fig. 7",
        "paper_circle",
        "circle R10, 50 mm/s",
        "PI: radius reduction and ellipse; H-inf corrects them",
    ),
    ContouringExperiment(
        "Fig. 8", "paper_involute", "involute R50, 50 mm/s", "H-inf: much smaller error"
    ),
)


def step_metrics(t, x, step: float) -> dict:
    """Overshoot, 10-90 % rise time and 2 % settling time of a step response ``x(t)``."""
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(x, dtype=np.float64) / step
    over = float(max(0.0, y.max() - 1.0))
    rise = float(t[np.argmax(y >= 0.9)] - t[np.argmax(y >= 0.1)])
    bad = np.flatnonzero(np.abs(y - 1.0) > 0.02)
    settle = float(t[bad[-1] + 1]) if bad.size and bad[-1] + 1 < t.size else float(t[-1])
    return {"overshoot": over, "rise_time_s": rise, "settling_time_s": settle}


def _model_step_metrics(dt: float) -> dict:
    t = np.arange(0.0, 0.05, dt)
    return step_metrics(t, 1.0 - np.exp(-HINF_MODEL_POLE * t), 1.0)


def _load_deviation(traj) -> float:
    t = np.asarray(traj["t_s"])
    after = t >= PAPER_LOAD_TIME_S
    x = np.asarray(traj["x_mm"])[after]
    y = np.asarray(traj["y_mm"])[after]
    return float(np.max(np.hypot(x - PAPER_STEP_MM, y)))


def reproduce_contouring(out_dir=None, seed: int = 0, verbose: bool = True):
    """Run Fig. 4-8 with both controllers; print paper vs ours; save the figure if ``out_dir``.

    Returns a list of dicts, one per experiment, with the experiment, both controllers'
    numbers (``"pi"``, ``"hinf"``), the ratio and whether it shows the paper's behaviour
    (``"match"``); the H-infinity designs' gammas are in every entry's ``"gammas"``.
    """
    env = gym.make(_ENV)
    dt = env.unwrapped.params.sample_time_s
    try:
        agents = {"pi": PIPosition.from_env(env), "hinf": HInf2DOF.from_env(env)}
        results = []
        for exp in CONTOURING_EXPERIMENTS:
            trajs = {k: rollout(a, env, exp.scenario, seed) for k, a in agents.items()}
            nums = {k: contouring_metrics(tr) for k, tr in trajs.items()}
            if exp.scenario == "paper_step":
                for k, tr in trajs.items():
                    nums[k].update(step_metrics(tr["t_s"], tr["x_mm"], PAPER_STEP_MM))
                ratio = nums["pi"]["settling_time_s"] / nums["hinf"]["settling_time_s"]
                match = (
                    nums["hinf"]["settling_time_s"] < nums["pi"]["settling_time_s"]
                    and nums["hinf"]["overshoot"] <= 0.02
                    and nums["pi"]["overshoot"] <= 0.02
                )
            elif exp.scenario == "paper_step_load":
                for k, tr in trajs.items():
                    nums[k]["load_deviation_mm"] = _load_deviation(tr)
                ratio = nums["pi"]["load_deviation_mm"] / nums["hinf"]["load_deviation_mm"]
                match = ratio >= LOAD_RATIO
            else:
                ratio = nums["pi"]["max_contour_error_mm"] / nums["hinf"]["max_contour_error_mm"]
                match = ratio >= CONTOUR_RATIO
                if exp.scenario == "paper_circle":
                    match = (
                        match
                        and nums["pi"]["radius_reduction_mm"] > 0.0
                        and nums["pi"]["ellipse_mm"] >= CONTOUR_RATIO * nums["hinf"]["ellipse_mm"]
                    )
            results.append(
                {
                    "experiment": exp,
                    "pi": nums["pi"],
                    "hinf": nums["hinf"],
                    "ratio": float(ratio),
                    "match": bool(match),
                    "traj": trajs,
                    "gammas": agents["hinf"].gammas,
                }
            )
    finally:
        env.close()
    if verbose:
        _print(results, dt)
    reproduction_figure(
        out_dir,
        "reproduce_contouring.png",
        lambda path: plot_contouring_reproduction(results, path),
        verbose,
    )
    return results


def _um(v: float) -> str:
    return f"{1000.0 * v:.3g} µm"


def _print(results, dt: float) -> None:
    g = results[0]["gammas"]
    m0 = _model_step_metrics(dt)
    print(
        f"H-inf 2-DOF design (M0 = 500/(s+500), W = 1e6/(s+1e-3), rho = 1): "
        f"gamma X = {g[0]:.3f}, Y = {g[1]:.3f}"
    )
    print(
        f"Reference model M0: rise {1000 * m0['rise_time_s']:.1f} ms, "
        f"settling (2 %) {1000 * m0['settling_time_s']:.1f} ms\n"
    )
    head = (
        f"{'figure':7s} {'test':24s} {'paper':52s} {'PI':>24s} {'H-inf':>24s} {'ratio':>7s} match"
    )
    print(head)
    print("-" * len(head))
    for r in results:
        e, p, h = r["experiment"], r["pi"], r["hinf"]
        if e.scenario == "paper_step":
            fp = f"settle {1000 * p['settling_time_s']:.1f} ms, os {100 * p['overshoot']:.1f}%"
            fh = f"settle {1000 * h['settling_time_s']:.1f} ms, os {100 * h['overshoot']:.1f}%"
        elif e.scenario == "paper_step_load":
            fp = f"deviation {_um(p['load_deviation_mm'])}"
            fh = f"deviation {_um(h['load_deviation_mm'])}"
        else:
            fp = f"max eps {_um(p['max_contour_error_mm'])}"
            fh = f"max eps {_um(h['max_contour_error_mm'])}"
        print(
            f"{e.figure:7s} {e.test:24s} {e.paper:52s} {fp:>24s} {fh:>24s} "
            f"{r['ratio']:7.1f} {'yes' if r['match'] else 'NO'}"
        )
    circ = next(r for r in results if r["experiment"].scenario == "paper_circle")
    print(
        f"\ncircle: radius reduction PI {_um(circ['pi']['radius_reduction_mm'])}, H-inf "
        f"{_um(circ['hinf']['radius_reduction_mm'])}; ellipse (half axis difference) PI "
        f"{_um(circ['pi']['ellipse_mm'])}, H-inf {_um(circ['hinf']['ellipse_mm'])}"
    )
    n = sum(r["match"] for r in results)
    print(
        f"\n{n}/{len(results)} experiments show the paper's behaviour "
        f"(contour errors: H-inf at least {CONTOUR_RATIO:g}x smaller; load: at least "
        f"{LOAD_RATIO:g}x smaller deviation)"
    )


def _plot_both(ax, r: dict, style: dict, xy, lw: float = 1.2, plot: str = "plot") -> None:
    """One curve per controller of the experiment's result ``r``: ``xy(trajectory)``
    gives its x and y, drawn by ``ax.<plot>`` in the controller's ``style`` (colour,
    label)."""
    for k, (c, label) in style.items():
        x, y = xy(r["traj"][k])
        getattr(ax, plot)(x, y, color=c, lw=lw, label=label)


def _label_panel(ax, xlabel: str, ylabel: str, title: str) -> None:
    """A reproduction panel's axis labels, title and legend."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8)


def plot_contouring_reproduction(results, path) -> None:
    """Six panels: Fig. 4-8 for both controllers and the largest contour errors."""
    from matplotlib.figure import Figure

    by = {r["experiment"].scenario: r for r in results}
    style = {"pi": ("C1", "PI"), "hinf": ("C0", "H-inf 2-DOF")}
    fig = Figure(figsize=(14, 8.5))
    axes = fig.subplots(2, 3)
    ax = axes[0, 0]
    r = by["paper_step"]
    _plot_both(ax, r, style, lambda tr: (1000 * tr["t_s"], tr["x_mm"] / PAPER_STEP_MM))
    t = r["traj"]["pi"]["t_s"]
    ax.plot(1000 * t, 1 - np.exp(-HINF_MODEL_POLE * t), "k--", lw=0.8, label="M0")
    ax.set_xlim(0, 100)
    _label_panel(ax, "time (ms)", "x / step", "Fig. 4: unit step (normalised)")

    ax = axes[0, 1]
    _plot_both(
        ax,
        by["paper_step_load"],
        style,
        lambda tr: (1000 * tr["t_s"], 1000 * (tr["x_mm"] - PAPER_STEP_MM)),
    )
    ax.axvline(1000 * PAPER_LOAD_TIME_S, color="0.5", ls=":", lw=0.8)
    ax.set_xlim(1000 * PAPER_LOAD_TIME_S - 20, None)
    ax.set_ylim(-20, 20)
    _label_panel(ax, "time (ms)", "x - set point (µm)", "Fig. 5: load torque 1 N m from 0.15 s")

    ax = axes[0, 2]
    corner = Path.paper_corner()
    cx, cy = corner.segments[0].end
    s = np.linspace(0.0, corner.length, 4001)
    px, py = corner.points(s)
    ax.plot(px, py, "k--", lw=0.8, label="path")

    def near_corner(tr):
        near = np.hypot(tr["x_mm"] - cx, tr["y_mm"] - cy) < 0.5
        return tr["x_mm"][near], tr["y_mm"][near]

    _plot_both(ax, by["paper_corner"], style, near_corner)
    ax.set_xlim(cx - 0.3, cx + 0.3)
    ax.set_ylim(cy - 0.35, cy + 0.05)
    ax.set_aspect("equal")
    _label_panel(ax, "X (mm)", "Y (mm)", "Fig. 6: corner at 5 mm/s (zoom)")

    ax = axes[1, 0]

    def radius_error(tr):
        ang = np.degrees(np.unwrap(np.arctan2(tr["y_mm"], tr["x_mm"])))
        return ang, 1000 * (np.hypot(tr["x_mm"], tr["y_mm"]) - 10.0)

    _plot_both(ax, by["paper_circle"], style, radius_error)
    ax.axhline(0.0, color="k", ls="--", lw=0.8)
    _label_panel(
        ax, "angle on the circle (deg)", "radius - R (µm)", "Fig. 7: circle R 10 mm at 50 mm/s"
    )

    ax = axes[1, 1]
    _plot_both(
        ax,
        by["paper_involute"],
        style,
        lambda tr: (tr["path_s_mm"][1:], 1000 * np.maximum(tr["contour_error_mm"][1:], 1e-6)),
        lw=1.0,
        plot="semilogy",
    )
    _label_panel(
        ax,
        "set point along the involute (mm)",
        "contour error (µm)",
        "Fig. 8: involute R 50 mm at 50 mm/s",
    )

    ax = axes[1, 2]
    names = ["paper_corner", "paper_circle", "paper_involute"]
    xs = np.arange(len(names))
    for i, (k, (c, label)) in enumerate(style.items()):
        vals = [1000 * by[n][k]["max_contour_error_mm"] for n in names]
        ax.bar(xs + (i - 0.5) * 0.38, vals, width=0.38, color=c, label=label)
    ax.set_yscale("log")
    ax.set_xticks(xs, ["corner", "circle", "involute"])
    ax.set_ylabel("largest contour error (µm)")
    ax.set_title("largest contour errors", fontsize=10)
    ax.legend(fontsize=8)
    g = results[0]["gammas"]
    fig.suptitle(
        f"Contouring reproduction (Choi et al.): PI vs H-inf 2-DOF (gamma X {g[0]:.2f}, "
        f"Y {g[1]:.2f})",
        fontsize=11,
    )
    fig.tight_layout()
    save_figure(fig, path)


# --- The declaration: what the benchmark, the CLI and the docs know of contouring -------------

#: The trajectory plot's context of both envs: where along the path the set point is.
_PATH_CONTEXT = ("path_s_mm", "set point along the path (mm)")

POSITION_BENCHMARK = BenchmarkSpec(
    _ENV,
    (PIPosition.from_env, HInf2DOF.from_env),
    ("paper_circle", "paper_involute"),
    "paper_circle",
    tuned=(PIPosition, HInf2DOF),
    learned=("contouring_ppo_residual",),
    rows_seconds=500.0,
    table_metrics=(
        "max_contour_error_mm",
        "rms_contour_error_mm",
        "max_tracking_error_mm",
        "radius_reduction_mm",
        "ellipse_mm",
        "cycle_time_s",
        "effort_rms_Nm",
        "finished",
        "diverged",
    ),
    plot_main=("contour_error_mm", None, "contour error (mm)"),
    plot_lower=("tracking_error_mm", "tracking error (mm)"),
    plot_context=_PATH_CONTEXT,
)

FEED_BENCHMARK = BenchmarkSpec(
    "machining_envs/ContouringFeed-v0",
    (ConstantOverride.from_env, functools.partial(ConstantOverride.from_env, override=1.0)),
    ("paper_circle", "paper_involute"),
    "paper_involute",
    tuned=(ConstantOverride, LookAheadFeed),
    machine_tuned=(ConstantOverride, LookAheadFeed, ContourAFC),
    machine_reference=ConstantOverride,
    learned=("contouring_feed_ppo_residual",),
    extra_splits=("shopfloor",),
    table_metrics=(
        "cycle_time_s",
        "max_contour_error_mm",
        "rms_contour_error_mm",
        "time_over_tolerance",
        "effort_rms_Nm",
        "finished",
        "diverged",
    ),
    plot_main=("peak_contour_error_mm", "contour_tolerance_mm", "contour error (mm)"),
    plot_lower=("feed_override", "feed override"),
    plot_context=_PATH_CONTEXT,
)

PROCESS = Process("contouring", (POSITION_BENCHMARK, FEED_BENCHMARK), reproduce_contouring)
