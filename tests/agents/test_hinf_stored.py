"""The H-infinity designs are stored (machining_envs/contouring/hinf_designs.json): the agents'
actions on a recorded trajectory, and ContouringFeed-v0's servo, are the same whatever
OpenBLAS kernel the machine picks."""

import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import machining_envs  # noqa: F401
from agents.bench.tune import stored_design_rhos
from agents.contouring import HInf2DOF, contouring_params
from agents.eval import rollout
from machining_envs.contouring.servo import stored_hinf_design

ROOT = Path(__file__).resolve().parents[2]
ENV = "machining_envs/Contouring-v0"

_ACT = """
import sys, numpy as np, gymnasium as gym
import machining_envs
from agents.contouring import HInf2DOF
obs = np.load(sys.argv[1])
env = gym.make("machining_envs/Contouring-v0")
out = []
for rho in map(float, sys.argv[3:]):
    agent = HInf2DOF.from_env(env, rho=rho)
    assert agent.stored, rho
    state, start = None, np.ones(1, dtype=bool)
    for o in obs:
        a, state = agent.predict(o[None], state=state, episode_start=start)
        start = np.zeros(1, dtype=bool)
        out.append(np.asarray(a, dtype=np.float64).ravel())
np.save(sys.argv[2], np.array(out))
"""


def test_every_benchmarked_design_is_stored():
    env = gym.make(ENV)
    p = contouring_params(env)
    for rho in stored_design_rhos():
        agent = HInf2DOF.from_env(env, rho=rho)
        assert agent.stored, f"rho {rho}: run `machining-bench synthesize`"
        assert all(np.isfinite(g) and g > 1.0 for g in agent.gammas)
    assert stored_hinf_design(p, "x", 0.77) is None
    assert not HInf2DOF.from_env(env, rho=0.77).stored  # synthesised on the spot


def test_hinf_actions_do_not_depend_on_the_blas_kernel(tmp_path):
    """Observations of a recorded validation run; the paper's and the tuned H-infinity
    agents act on them in a process with OPENBLAS_CORETYPE=Haswell and in one with the
    default kernel: the actions are the same to the bit."""
    env = gym.make(ENV)
    agent = HInf2DOF.from_env(env)
    obs = []

    class Recording:
        def predict(self, o, state=None, episode_start=None, deterministic=True):
            if len(obs) < 400:
                obs.append(np.array(o, dtype=np.float32).reshape(-1))
            return agent.predict(o, state=state, episode_start=episode_start)

    rollout(Recording(), env, "validation", 5000)
    np.save(tmp_path / "obs.npy", np.array(obs))
    rhos = [str(r) for r in stored_design_rhos()]
    runs = {}
    for kernel in ("Haswell", None):
        envvars = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
        if kernel is not None:
            envvars["OPENBLAS_CORETYPE"] = kernel
        envvars["PYTHONPATH"] = str(ROOT) + os.pathsep + envvars.get("PYTHONPATH", "")
        out = tmp_path / f"act_{kernel}.npy"
        subprocess.run(
            [sys.executable, "-c", _ACT, str(tmp_path / "obs.npy"), str(out), *rhos],
            check=True,
            env=envvars,
            cwd=ROOT,
        )
        runs[kernel] = np.load(out)
    assert runs["Haswell"].shape[0] == len(obs) * len(rhos)
    np.testing.assert_array_equal(runs["Haswell"], runs[None])


@pytest.mark.slow
def test_the_stored_designs_are_what_the_synthesis_gives():
    """A fresh synthesis on this machine reaches the stored gamma (within 1e-6: the kernel
    moves the optimum by far less than it moves the matrices' last digits)."""
    from machining_envs.contouring.servo import _hinf, hinf_2dof_design

    env = gym.make(ENV)
    p = contouring_params(env)
    _hinf.cache_clear()
    for ax in ("x", "y"):
        fresh = hinf_2dof_design(p, ax, rho=1.0)
        assert fresh.gamma == pytest.approx(stored_hinf_design(p, ax, 1.0).gamma, rel=1e-6)


def test_contouring_feed_servo_runs_the_stored_design_without_a_synthesis(monkeypatch):
    """ContouringFeed-v0's default servo (servo="hinf") and HInf2DOF at the stored rhos are
    built from the stored file: no hinfsyn runs, so no BLAS kernel can move their digits."""
    import machining_envs.contouring.servo as servo

    def no_synthesis(*args):
        raise AssertionError(f"synthesised {args}: the design should come from the store")

    monkeypatch.setattr(servo, "_hinf", no_synthesis)
    env = gym.make("machining_envs/ContouringFeed-v0")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    p = servo.ContouringParams()
    for ax in ("x", "y"):
        d = servo.hinf_2dof_design(p, ax)
        assert d is not None and not d.a.flags.writeable and d.gamma > 1.0
    for rho in stored_design_rhos():
        assert HInf2DOF.from_env(gym.make(ENV), rho=rho).stored
    with pytest.raises(AssertionError, match="synthesised"):
        servo.hinf_2dof_design(p, "x", rho=0.77)  # not stored: it would synthesise
