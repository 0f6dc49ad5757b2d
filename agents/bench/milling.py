"""End-milling reproduction (Park & Yoon 1986): Table 1, and the stability trend of Fig. 5.

Table 1 runs the paper's two workpieces (step 1-2-3 mm and taper 0-3 mm radial depth,
L = 40 mm, 400 rpm) with the integral ACC (Koren-Masory estimator, Kc = 0.2 at the start,
Kn = 0.02, C1 = C2 = 0.001) and without AC at the constant feeds Table 1 implies, and sets
machining time (eq. 20) and metal removal rate beside the paper's. A row matches when:

- **without AC**: time and MRR within ``TABLE_TOLERANCE`` (2 %) of the paper's;
- **with AC**: the machining time is within ``AC_TIME_TOLERANCE`` (5 %) of the paper's
  with-AC time and at least ``MIN_TIME_GAIN`` (70 %) below our without-AC run of the same
  workpiece, nothing breaks, and on every segment of the workpiece the torque enters the
  ``HOLD_BAND`` (10 %) around the reference within ``TRANSIENT_S`` (10 s) of the
  segment's start and stays there to its end. The taper row does not match: ours holds
  the reference and is 26 % faster than the paper's with-AC time (3.132 min); what slowed
  the paper's cut on the shallow start of the taper is not in the paper (our feed drive's
  top speed, ``MillingParams.command_max``, is a choice, not a paper value).

Fig. 5 (the stability trend) runs the fixed-gain integral controller at Kc = 0.2 on the
step workpiece with Kn = 0.02 and 0.025: the paper reports the larger servo gain faster but
unstable as the radial depth grows. A plateau counts as **unstable** when the torque
oscillates by more than ``UNSTABLE_OSCILLATION`` (10 % of the reference, half
peak-to-peak after removing the 1 s moving mean, over the plateau's second half) or the tool
breaks. The linear analysis beside it gives, per depth, the servo gain at which the
sampled loop (exact ZOH of servo and process lag, torque law linearised at the reference)
loses stability.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np

from agents.afc import AdaptiveFeedControl
from agents.bench.figures import reproduction_figure, save_figure
from agents.bench.spec import (
    BenchmarkSpec,
    ConstantDepthCut,
    DeferredAgent,
    Process,
    Robustness,
)
from agents.eval import rollout
from agents.milling import FixedGainIntegral, IntegralACC, MillingConstantFeed
from machining_envs.core.lti import critical_gain
from machining_envs.core.metrics import OSC_WINDOW_S, oscillation_amplitude, segment_bounds
from machining_envs.milling.metrics import milling_metrics
from machining_envs.milling.plant import MillingParams
from machining_envs.milling.scenarios import PAPER_LENGTH_MM, MillingScenario

__all__ = [
    "PAPER_TABLE_1",
    "reproduce_milling",
    "hold_check",
    "plateau_oscillation",
    "critical_loop_gain",
    "critical_servo_gain",
    "critical_controller_gain",
    "TABLE_TOLERANCE",
    "MIN_TIME_GAIN",
    "HOLD_BAND",
    "TRANSIENT_S",
    "UNSTABLE_OSCILLATION",
]

ENV_ID = "machining_envs/EndMilling-v0"

#: Park & Yoon (1986) Table 1: machining time (min) and MRR (mm³/min), with and without AC.
PAPER_TABLE_1 = {
    "paper_step": {"time_ac": 3.117, "time_no_ac": 11.797, "mrr_ac": 821.3, "mrr_no_ac": 217.0},
    "paper_taper": {
        "time_ac": 3.132,
        "time_no_ac": 15.914,
        "mrr_ac": 613.0,
        "mrr_no_ac": 120.65,
    },
}
TABLE_TOLERANCE = 0.02
#: How far our with-AC machining time may be from the paper's: the limit torque was chosen
#: to give the step workpiece's with-AC time (``MillingParams.torque_limit_Nmm``; rounding
#: 3613 to 3600 N·mm moves it 0.9 %), and the start-up transient and the paper's unstated
#: details move it a few per cent more; 5 % separates that from a different behaviour.
AC_TIME_TOLERANCE = 0.05
MIN_TIME_GAIN = 0.70
HOLD_BAND = 0.10
TRANSIENT_S = 10.0
UNSTABLE_OSCILLATION = 0.10


def hold_check(traj: dict, band: float = HOLD_BAND) -> dict:
    """Per workpiece segment: when the torque enters ``band`` for good, and how far it strays.

    Returns ``{"transient_s": [...], "worst_after": [...], "held": bool}``: for each segment
    cut, the time from its start until the torque stays within ``band`` of the reference to
    the segment's end (``inf`` if it never does), the largest ``|T/Tr - 1|`` after that, and
    whether every segment settled within ``TRANSIENT_S``.
    """
    depth = np.asarray(traj["depth_mm"])[1:]
    cutting = depth > 0
    t = np.asarray(traj["t_s"])[1:][cutting]
    e = np.abs(np.asarray(traj["torque_Nmm"])[1:] / np.asarray(traj["torque_limit_Nmm"])[1:] - 1.0)
    e = e[cutting]
    seg = np.asarray(traj["segment"])[1:][cutting]
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    transients, worst = [], []
    for a, b in segment_bounds(seg):
        es = e[a:b]
        bad = np.flatnonzero(es > band)
        if bad.size and bad[-1] == es.size - 1:
            transients.append(math.inf)
            worst.append(float(es.max()))
            continue
        k = bad[-1] + 1 if bad.size else 0
        transients.append(float(k * dt))
        worst.append(float(es[k:].max()))
    return {
        "transient_s": transients,
        "worst_after": worst,
        "held": bool(transients) and all(x <= TRANSIENT_S for x in transients),
    }


def plateau_oscillation(traj: dict) -> dict[float, float]:
    """Oscillation of ``T/Tr - 1`` on each plateau (see ``metrics.oscillation_amplitude``)."""
    depth = np.asarray(traj["depth_mm"])[1:]
    cutting = depth > 0
    t = np.asarray(traj["t_s"])[1:][cutting]
    e = np.asarray(traj["torque_Nmm"])[1:] / np.asarray(traj["torque_limit_Nmm"])[1:] - 1.0
    e, depth = e[cutting], depth[cutting]
    seg = np.asarray(traj["segment"])[1:][cutting]
    window = max(1, int(round(OSC_WINDOW_S / float(np.median(np.diff(t))))))
    out = {}
    for a, b in segment_bounds(seg):
        out[round(float(depth[a]), 3)] = oscillation_amplitude(e[a:b], window)
    return out


# ---- linear analysis of the sampled loop ----------------------------------------------------
def critical_loop_gain(params: MillingParams | None = None) -> float:
    """Critical per-sample loop gain ``g = Kc Ts dTc/dU`` of the integral loop.

    The loop is ``g G(z) / (1 - z^-1)`` with ``G`` the ZOH discretisation of the unit-gain
    servo and process lag (``MillingParams.discrete_open_loop``); stable for ``g`` below
    the returned value.
    """
    p = params or MillingParams()
    numd, dend = p.discrete_open_loop()
    return critical_gain(numd, np.convolve([1.0, -1.0], dend))


def _loop_gain(p: MillingParams, kc: float, depth_mm: float) -> float:
    """``Kc Ts dTc/dU`` at the reference torque: ``dTc/dU = e Tc/U`` (e the feed exponent)."""
    return kc * p.sample_time_s * p.torque_feed_exponent * float(p.process_gain(depth_mm))


def critical_servo_gain(depth_mm: float, kc: float = 0.2, params: MillingParams | None = None):
    """Servo gain Kn at which the fixed-gain integral loop (gain ``kc``) goes unstable at
    ``depth_mm``, linearised at the reference torque (the loop gain is proportional to Kn)."""
    p = params or MillingParams()
    return p.servo_gain * critical_loop_gain(p) / _loop_gain(p, kc, depth_mm)


def critical_controller_gain(depth_mm: float, params: MillingParams | None = None) -> float:
    """Controller gain Kc at which the fixed-gain integral loop goes unstable at ``depth_mm``."""
    p = params or MillingParams()
    return critical_loop_gain(p) / _loop_gain(p, 1.0, depth_mm)


# ---- the reproduction ------------------------------------------------------------------------
def _run(agent_factory, scenario: str, seed: int, **env_kwargs):
    env = gym.make(ENV_ID, scenario=scenario, **env_kwargs)
    try:
        agent = agent_factory(env)
        traj = rollout(agent, env, seed=seed)
    finally:
        env.close()
    return agent, traj


def _acc_gains(traj: dict, env_kwargs: dict, seed: int, scenario: str) -> np.ndarray:
    """Km and Kc of the ACC along a run (replayed from the recorded observations)."""
    env = gym.make(ENV_ID, scenario=scenario, **env_kwargs)
    try:
        agent = IntegralACC.from_env(env)
        obs, _ = env.reset(seed=seed)
        state, gains, done = None, [], False
        while not done:
            act, state = agent.predict(obs, state)
            gains.append(state[0, 1:3].copy())
            obs, _, term, trunc, _ = env.step(act)
            done = term or trunc
    finally:
        env.close()
    return np.array(gains)


def reproduce_milling(out_dir=None, seed: int = 0, verbose: bool = True) -> list[dict]:
    """Run Table 1 and the Fig. 5 pair; print paper vs ours; save the figure if ``out_dir``.

    Returns a list of dicts, one per row, each with a boolean ``"match"`` and the run's
    trajectory (``"traj"``).
    """
    results: list[dict] = []
    runs: dict[str, dict] = {}
    for wp in ("paper_step", "paper_taper"):
        paper = PAPER_TABLE_1[wp]
        _, tr_no = _run(lambda env, wp=wp: MillingConstantFeed.paper(env, wp), wp, seed)
        agent, tr_ac = _run(IntegralACC.from_env, wp, seed)
        m_no, m_ac = milling_metrics(tr_no), milling_metrics(tr_ac)
        d_time = abs(m_no["machining_time_min"] / paper["time_no_ac"] - 1.0)
        d_mrr = abs(m_no["mrr_mm3_per_min"] / paper["mrr_no_ac"] - 1.0)
        results.append(
            {
                "row": f"{wp[6:]} without AC",
                "paper_time_min": paper["time_no_ac"],
                "paper_mrr": paper["mrr_no_ac"],
                "time_min": m_no["machining_time_min"],
                "mrr": m_no["mrr_mm3_per_min"],
                "note": f"time {d_time:+.2%}, MRR {d_mrr:+.2%} off",
                "match": bool(d_time <= TABLE_TOLERANCE and d_mrr <= TABLE_TOLERANCE),
                "traj": tr_no,
            }
        )
        gain = 1.0 - m_ac["machining_time_min"] / m_no["machining_time_min"]
        d_ac = m_ac["machining_time_min"] / paper["time_ac"] - 1.0
        hold = hold_check(tr_ac)
        broke = bool(m_ac["breakage"])
        results.append(
            {
                "row": f"{wp[6:]} with AC",
                "paper_time_min": paper["time_ac"],
                "paper_mrr": paper["mrr_ac"],
                "time_min": m_ac["machining_time_min"],
                "mrr": m_ac["mrr_mm3_per_min"],
                "time_gain": gain,
                "paper_time_gain": 1.0 - paper["time_ac"] / paper["time_no_ac"],
                "hold": hold,
                "note": (
                    f"{d_ac:+.1%} vs paper; "
                    f"time -{gain:.1%} (paper -{1.0 - paper['time_ac'] / paper['time_no_ac']:.1%}); "
                    f"within 10 % after {max(hold['transient_s']):.1f} s"
                    + ("; BROKE" if broke else "")
                ),
                "match": bool(
                    abs(d_ac) <= AC_TIME_TOLERANCE
                    and gain >= MIN_TIME_GAIN
                    and hold["held"]
                    and not broke
                ),
                "agent": agent.name,
                "traj": tr_ac,
            }
        )
        runs[wp] = {"ac": tr_ac, "no_ac": tr_no}

    # Fig. 5: fixed Kc = 0.2, the two servo gains of the paper.
    fig5 = {}
    for kn, expect in ((0.02, "stable"), (0.025, "unstable at 3 mm")):
        _, tr = _run(
            lambda env: FixedGainIntegral.from_env(env, kc=0.2), "paper_step", seed, servo_gain=kn
        )
        osc = plateau_oscillation(tr)
        broke = bool(np.any(tr["breakage"]))
        unstable = [d for d, v in osc.items() if v > UNSTABLE_OSCILLATION] + (
            [max(osc)] if broke else []
        )
        first = min(unstable) if unstable else None
        if expect == "stable":
            match = first is None
        else:  # stable on the 1 mm step, unstable by the 3 mm one
            match = first is not None and 1.0 < first <= 3.0
        results.append(
            {
                "row": f"Fig. 5 fixed Kc=0.2, Kn={kn:g}",
                "expected": expect,
                "oscillation_by_depth": osc,
                "unstable_from_mm": first,
                "critical_kn_by_depth": {d: critical_servo_gain(d, 0.2) for d in (1.0, 2.0, 3.0)},
                "note": "oscillation 1/2/3 mm: " + "/".join(f"{v:.2f}" for v in osc.values()),
                "match": bool(match),
                "traj": tr,
            }
        )
        fig5[kn] = tr
    # The adaptive loop at the larger servo gain (the paper's Fig. 13-14 runs).
    _, tr = _run(IntegralACC.from_env, "paper_step", seed, servo_gain=0.025)
    osc = plateau_oscillation(tr)
    results.append(
        {
            "row": "Fig. 13-14 ACC, Kn=0.025",
            "expected": "stable",
            "oscillation_by_depth": osc,
            "note": "oscillation 1/2/3 mm: " + "/".join(f"{v:.2f}" for v in osc.values()),
            "match": bool(max(osc.values()) <= UNSTABLE_OSCILLATION and not np.any(tr["breakage"])),
            "traj": tr,
        }
    )
    fig5["acc_0.025"] = tr

    if verbose:
        _print(results)

    def draw(path):
        gains = {wp: _acc_gains(runs[wp]["ac"], {}, seed, wp) for wp in runs}
        plot_milling_reproduction(runs, fig5, gains, path)

    reproduction_figure(out_dir, "reproduce_milling.png", draw, verbose)
    return results


def _print(results: list[dict]) -> None:
    print("Park & Yoon (1986) Table 1: machining time (eq. 20) and metal removal rate")
    head = (
        f"{'workpiece':22s} {'time paper':>10s} {'ours':>8s} {'MRR paper':>10s} {'ours':>8s}"
        f"  {'':50s} match"
    )
    print(head)
    print("-" * len(head))
    for r in results:
        if "paper_time_min" not in r:
            continue
        print(
            f"{r['row']:22s} {r['paper_time_min']:9.3f}m {r['time_min']:7.3f}m "
            f"{r['paper_mrr']:10.1f} {r['mrr']:8.1f}  {r['note']:50s} "
            f"{'yes' if r['match'] else 'NO'}"
        )
    print()
    kc_line = ", ".join(f"{d:g} mm: {critical_servo_gain(d, 0.2):.4f}" for d in (1.0, 2.0, 3.0))
    print(f"Fig. 5 stability (fixed-gain integral): critical Kn at Kc = 0.2 - {kc_line}")
    for r in results:
        if "expected" not in r:
            continue
        print(
            f"{r['row']:28s} paper: {r['expected']:18s} ours: {r['note']:36s} "
            f"{'yes' if r['match'] else 'NO'}"
        )
    n = sum(r["match"] for r in results)
    print(f"\n{n}/{len(results)} rows show the paper's result")


def plot_milling_reproduction(runs: dict, fig5: dict, gains: dict, path) -> None:
    """Torque, feed and the adapted gains against sample number (paper Fig. 5-12)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(14, 8.5))
    axes = fig.subplots(3, 3, squeeze=False)
    for col, wp in enumerate(("paper_step", "paper_taper")):
        tr_ac, tr_no = runs[wp]["ac"], runs[wp]["no_ac"]
        n_ac = np.arange(tr_ac["t_s"].size)
        tr_ref = tr_ac["torque_limit_Nmm"][0]
        ax = axes[0, col]
        ax.plot(n_ac, tr_ac["torque_Nmm"] / 1000.0, "C0-", lw=1, label="with AC (integral ACC)")
        n_no = np.arange(tr_no["t_s"].size)
        ax.plot(
            n_no,
            tr_no["torque_Nmm"] / 1000.0,
            "C7-",
            lw=0.8,
            label=f"without AC (runs on to sample {n_no[-1]})",
        )
        ax.axhline(tr_ref / 1000.0, color="k", ls="--", lw=0.8)
        ax.set_xlim(0, n_ac[-1] * 1.05)
        ax.set_ylabel("torque (N·m)")
        ax.set_title(f"{wp}: torque vs sample (Fig. {5 if col == 0 else 6})", fontsize=9)
        ax.legend(fontsize=7, loc="lower right")
        ax2 = ax.twinx()
        ax2.plot(n_ac, tr_ac["depth_mm"], "C3-", lw=0.7)
        ax2.set_ylim(0, 4)
        ax2.set_ylabel("radial depth (mm)", color="C3")
        ax = axes[1, col]
        ax.plot(n_ac, tr_ac["feed_mm_per_rev"], "C0-", lw=1, label="with AC")
        ax.plot(n_no, tr_no["feed_mm_per_rev"], "C7-", lw=0.8, label="without AC")
        ax.set_xlim(0, n_ac[-1] * 1.05)
        ax.set_ylabel("feed (mm/rev)")
        ax.set_title(f"{wp}: feed vs sample (Fig. {12 if col == 0 else 11})", fontsize=9)
        ax = axes[2, col]
        g = gains[wp]
        ax.plot(np.arange(g.shape[0]), g[:, 0], "C2-", lw=1, label="Km (counts/count)")
        ax.set_ylabel("Km", color="C2")
        ax.set_xlabel("sample number (Ts = 0.1 s)")
        ax.set_title(
            f"{wp}: variable gains (Fig. {8 if col == 0 else 7}, {10 if col == 0 else 9})",
            fontsize=9,
        )
        ax2 = ax.twinx()
        ax2.plot(np.arange(g.shape[0]), g[:, 1], "C4-", lw=1)
        ax2.set_ylabel("Kc", color="C4")
    for row, (key, label) in enumerate(
        (
            (0.02, "fixed Kc=0.2, Kn=0.02"),
            (0.025, "fixed Kc=0.2, Kn=0.025"),
            ("acc_0.025", "integral ACC, Kn=0.025"),
        )
    ):
        ax = axes[row, 2]
        tr = fig5[key]
        n = np.arange(tr["t_s"].size)
        ax.plot(n, tr["torque_Nmm"] / 1000.0, "C1-" if key == 0.025 else "C0-", lw=0.8)
        ax.axhline(tr["torque_limit_Nmm"][0] / 1000.0, color="k", ls="--", lw=0.8)
        ax.set_ylabel("torque (N·m)")
        ax.set_title(f"step, {label} (Fig. 5 trend)", fontsize=9)
        ax2 = ax.twinx()
        ax2.plot(n, tr["depth_mm"], "C3-", lw=0.7)
        ax2.set_ylim(0, 4)
    axes[2, 2].set_xlabel("sample number (Ts = 0.1 s)")
    fig.tight_layout()
    save_figure(fig, path)


# --- The declaration: what the benchmark, the CLI and the docs know of milling -------------


BENCHMARK = BenchmarkSpec(
    ENV_ID,
    (MillingConstantFeed.from_env, FixedGainIntegral.from_env, IntegralACC.from_env),
    ("paper_step", "paper_taper"),
    "paper_step",
    tuned=(MillingConstantFeed, FixedGainIntegral, IntegralACC),
    machine_tuned=(
        MillingConstantFeed,
        FixedGainIntegral,
        IntegralACC,
        AdaptiveFeedControl,
    ),
    machine_reference=MillingConstantFeed,
    learned=("end_milling_ppo_load_only",),
    oracle=DeferredAgent("agents.oracle.MillingMPCOracle"),
    oracle_episodes=20,
    oracle_in_quick=False,  # a cut of some 2000 samples: about 16 s
    oracle_seconds=16.0,
    rows_seconds=250.0,
    extra_splits=("wear", "shopfloor"),
    robustness=Robustness(
        "spindle speed (x nominal)",
        (0.6, 0.8, 1.0, 1.3, 1.8),  # the ood split's speeds and depths
        "radial depth (mm)",
        (0.5, 1.0, 2.0, 4.0),
        ConstantDepthCut(MillingScenario, PAPER_LENGTH_MM),
    ),
    table_metrics=(
        "machining_time_min",
        "mrr_mm3_per_min",
        "iae",
        "max_overshoot",
        "settling_time_s",
        "oscillation",
        "time_over_limit",
        "breakage",
        "finished",
    ),
    plot_main=("torque_Nmm", "torque_limit_Nmm", "torque (N·mm)"),
    plot_lower=("feed_mm_per_rev", "feed (mm/rev)"),
    plot_context=("depth_mm", "radial depth (mm)"),
)

PROCESS = Process("milling", (BENCHMARK,), reproduce_milling)
