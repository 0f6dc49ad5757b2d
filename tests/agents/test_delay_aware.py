"""The delay-aware turning regulator (Smith predictor) and the delay margin."""

import math

import gymnasium as gym
import numpy as np
import pytest

from agents.eval.margins import OperatingPoint, delay_margin, loop_margins, margins_of
from agents.turning import DelayAwarePI, VariableGainPI, delay_aware_gain


def test_delay_margin_matches_the_delay_that_destabilises():
    """L(z) = 0.3 / (z - 1): phase margin 90 - w/2 degrees at w = 2 asin(0.15), a delay
    margin of 4.73 samples; 4 extra samples of delay keep the loop stable, 5 do not."""
    import control

    loop = control.tf([0.3], [1.0, -1.0], 1.0)
    m = margins_of(loop)
    w = 2.0 * math.asin(0.15)
    assert m.delay_margin_s == pytest.approx(math.radians(90.0 - math.degrees(w) / 2) / w, rel=1e-4)
    assert 4.0 < m.delay_margin_s < 5.0

    def stable(extra: int) -> bool:
        delayed = loop * control.tf([1.0], [1.0] + [0.0] * extra, 1.0)
        poles = control.poles(control.feedback(delayed, 1))
        return bool(np.all(np.abs(poles) < 1.0))

    assert stable(4) and not stable(5)


def test_delay_margin_edge_cases():
    assert delay_margin(float("inf"), float("nan")) == math.inf
    assert delay_margin(-10.0, 1.0) == 0.0


def test_without_delay_and_at_the_papers_gain_it_is_the_adaptive_pi():
    """With no delay and a phase margin the paper's K = 0.5 meets, the design is K = 0.5 or
    above (capped at the stable range's 0.8): the adaptive PI's law with that gain."""
    env = gym.make("machining_envs/Turning-v0", scenario="validation")
    design = DelayAwarePI.from_env(env, delay_steps=0, phase_margin_deg=30.0)
    obs, _ = env.reset(seed=3)
    k = design.gain_at(1000.0 * float(obs[3]))
    assert k >= 0.5
    pi = VariableGainPI.from_env(env, k=k)
    s1 = s2 = None
    for _ in range(60):
        a1, s1 = design.predict(obs, s1)
        a2, s2 = pi.predict(obs, s2)
        assert a1 == a2
        obs, _, term, trunc, _ = env.step(a1)
        if term or trunc:
            break


def test_delay_taken_from_the_env_and_checked():
    env = gym.make("machining_envs/Turning-v0", actuation={"delay_steps": 3})
    assert DelayAwarePI.from_env(env).delay_steps == 3
    assert DelayAwarePI.from_env(gym.make("machining_envs/Turning-v0")).delay_steps == 0
    with pytest.raises(ValueError, match="delay_steps"):
        DelayAwarePI.from_env(env, delay_steps=-1)
    with pytest.raises(ValueError, match="phase_margin_deg"):
        DelayAwarePI.from_env(env, phase_margin_deg=95.0)


def test_gain_falls_with_the_delay():
    env = gym.make("machining_envs/Turning-v0")
    p = env.unwrapped.params
    ks = [delay_aware_gain(p, 405.0, 1.9, d, 45.0) for d in (0, 1, 2, 4)]
    assert all(a > b for a, b in zip(ks, ks[1:], strict=False))


def test_design_margin_holds_on_the_delayed_machine():
    """At an operating point on a machine with two periods of delay, the linearised loop
    (python-control, delay in the plant) has the phase margin the design asked for, and a
    delay margin beside it; the paper's K = 0.5, designed without the delay, breaks the
    tool there before it settles."""
    env = gym.make("machining_envs/Turning-v0")
    point = OperatingPoint(405.0, 2.0)
    design = DelayAwarePI.from_env(env, delay_steps=2, phase_margin_deg=50.0)
    m = loop_margins(design, point, delay_steps=2)
    assert m.phase_margin_deg == pytest.approx(50.0, abs=3.0)
    assert 0.0 < m.delay_margin_s < math.inf
    assert m.delay_margin_s == pytest.approx(
        math.radians(m.phase_margin_deg) / _crossover(design, point), rel=1e-6
    )
    with pytest.raises(ValueError, match="ended before settling"):
        loop_margins(VariableGainPI.from_env(env), point, delay_steps=2)


def _crossover(agent, point):
    """The gain-crossover frequency of the loop loop_margins reads, rad/s."""
    import control

    from agents.eval.margins import controller_ss, plant_tf, settle

    env, obs, state, action = settle(agent, point, delay_steps=2)
    ts = env.params.sample_time_s
    loop = -controller_ss(agent, obs, state, action, ts) * plant_tf(env, point, action)
    loop = loop * control.tf([1.0], [1.0, 0.0, 0.0], ts)
    return control.stability_margins(loop)[4]


def test_report_prints_the_delay_margin_beside_gain_and_phase():
    from agents.bench.declarations import benchmark_spec
    from agents.bench.report import _margin_table
    from agents.bench.run import EnvRun

    run = EnvRun(benchmark_spec("machining_envs/Turning-v0"))
    run.kind = {"adaptive PI": "paper"}
    run.factory = {"adaptive PI": VariableGainPI.from_env}
    lines = _margin_table(run)
    assert "delay margin" in lines[0]
    row = lines[-2]
    cells = [c.strip() for c in row.strip("|").split("|")[1:]]
    assert len(cells) == 3
    for cell in cells:
        gm, pm, dm, ms = cell.split(" / ")
        assert gm.endswith("dB") and pm.endswith("°") and dm.endswith(" s")
        assert float(dm[:-2]) > 0
