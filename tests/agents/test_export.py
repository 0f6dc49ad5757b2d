"""ONNX export of a learned policy: onnxruntime gives SB3's actions, normalisation and
action increment folded in."""

from __future__ import annotations

import shutil

import gymnasium as gym
import numpy as np
import pytest

from agents.bench.cli import main
from agents.rl.policy import PRETRAINED_DIR, load_policy

ort = pytest.importorskip("onnxruntime")


@pytest.fixture
def end_milling_run(tmp_path):
    """A copy of the shipped EndMilling policy (normalised, incremental, action hidden)."""
    src = PRETRAINED_DIR / "end_milling_ppo"
    for name in ("best_model.zip", "best_vecnormalize.json", "config.json"):
        shutil.copy(src / name, tmp_path / name)
    return tmp_path


def test_export_reproduces_the_policy_on_the_plain_env(end_milling_run, capsys):
    model = end_milling_run / "best_model.zip"
    assert main(["export", "--onnx", "--model", str(model)]) == 0
    text = capsys.readouterr().out
    assert "reproduces the SB3 actions" in text and "control period (100 ms)" in text
    path = end_milling_run / "best_model.onnx"
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    agent = load_policy(model)
    # A closed-loop episode driven by the ONNX graph alone: the SB3 agent agrees every step.
    env = gym.make("machining_envs/EndMilling-v0")
    obs, _ = env.reset(seed=5, options={"scenario": "paper_step"})
    worst = 0.0
    for _ in range(300):
        action = session.run(None, {"observation": obs[None, :].astype(np.float32)})[0][0]
        worst = max(worst, float(np.max(np.abs(action - agent.predict(obs)[0]))))
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    assert worst <= 1e-5


def test_export_refuses_what_it_cannot_check(end_milling_run, capsys):
    model = end_milling_run / "best_model.zip"
    (end_milling_run / "config.json").unlink()
    assert main(["export", "--onnx", "--model", str(model)]) == 2
    assert "algo" in capsys.readouterr().err
    assert main(["export", "--onnx", "--model", str(model), "--algo", "ppo"]) == 2
    assert "env id" in capsys.readouterr().err
    assert main(["export", "--onnx", "--model", str(end_milling_run / "no.zip")]) == 2
