"""rl-zoo3 both ways: its trainer runs our shipped configs unmodified, our trainer reads its
value syntax, and a policy of ours opens with its ``enjoy`` (the same actions as ours)."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

from agents.bench.cli import main
from agents.rl import ConfigError, load_config, load_policy
from agents.rl.config import CONFIG_DIR
from agents.rl.policy import PRETRAINED_DIR
from tests.helpers import TURNING

pytest.importorskip("rl_zoo3")

ENDMILLING = "machining_envs/EndMilling-v0"


def _run_module(args: list[str], timeout: int) -> subprocess.CompletedProcess:
    """``python -m args...`` in a fresh interpreter, which must succeed (its stderr's tail
    is the failure message)."""
    out = subprocess.run(
        [sys.executable, "-m", *args], capture_output=True, text=True, timeout=timeout
    )
    assert out.returncode == 0, out.stderr[-3000:]
    return out


@pytest.mark.parametrize("env_id", [TURNING, ENDMILLING])
def test_rl_zoo3_trains_on_our_shipped_config(tmp_path, env_id):
    """``python -m rl_zoo3.train --conf-file agents/rl/configs/ppo.yml`` as it is: the env
    keywords, the IncrementalAction wrapper (EndMilling) and our ValidationCallback run
    under rl-zoo3 (a short run: the rollout shortened on the command line, not in the file)."""
    out = _run_module(
        [
            "rl_zoo3.train",
            "--algo",
            "ppo",
            "--env",
            env_id,
            "--gym-packages",
            "machining_envs",
            "--conf-file",
            str(CONFIG_DIR / "ppo.yml"),
            "-n",
            "256",
            "--eval-freq",
            "-1",
            "--log-folder",
            str(tmp_path),
            "--seed",
            "0",
            "--vec-env",
            "dummy",
            "-params",
            "n_steps:64",
            "batch_size:64",
            "n_epochs:1",
        ],
        timeout=600,
    )
    assert out.stdout.count("validation at 256 steps: score") == 1  # once, at the end
    name = env_id.replace("/", "-")
    assert (tmp_path / "ppo" / f"{name}_1" / f"{name}.zip").is_file()
    if env_id == ENDMILLING:
        assert "IncrementalAction" in out.stdout  # rl-zoo3 prints the wrapper it applies


def test_our_trainer_reads_rl_zoo3_python_values(tmp_path):
    """rl-zoo3 writes ``policy_kwargs`` and ``normalize`` as Python source, which it
    evaluates; here it is parsed as literals, and anything else is refused."""
    base = (CONFIG_DIR / "ppo.yml").read_text()
    entry = base[base.index(f"{TURNING}:") : base.index("machining_envs/EndMilling-v0:")]
    text = entry.replace(
        "  normalize: {norm_obs: true, norm_reward: true}\n",
        '  normalize: "dict(norm_obs=True, norm_reward=False)"\n',
    ).replace(
        "  policy_kwargs:\n    net_arch: [64, 64]\n",
        '  policy_kwargs: "dict(net_arch=dict(pi=[32], vf=[32]), activation_fn=nn.ReLU)"\n',
    )
    path = tmp_path / "zoo.yml"
    path.write_text(text)
    cfg = load_config(TURNING, "ppo", path)
    import torch

    assert cfg.normalize == {"norm_obs": True, "norm_reward": False}
    assert cfg.hyperparams["policy_kwargs"] == {
        "net_arch": {"pi": [32], "vf": [32]},
        "activation_fn": torch.nn.ReLU,
    }
    for bad in ("\"__import__('os').system('true')\"", "\"dict(x=open('f'))\"", '"os.sep"'):
        path.write_text(text.replace('"dict(norm_obs=True, norm_reward=False)"', bad))
        with pytest.raises(ConfigError, match="normalize"):
            load_config(TURNING, "ppo", path)


def test_callback_and_wrapper_entries_are_checked(tmp_path):
    base = (CONFIG_DIR / "ppo.yml").read_text()
    entry = base[base.index(f"{ENDMILLING}:") : base.index("machining_envs/MicroDrilling-v0:")]
    cases = [
        ("n_episodes: 20", "n_episode: 20", "unknown keywords .*n_episode"),
        ("scenarios: [validation]", "scenarios: [test]", "test"),
        ("eval_freq: 100000", "eval_freq: -5", "eval_freq must be an integer >= 1"),
        (
            "machining_envs.wrappers.IncrementalAction",
            "gymnasium.wrappers.ClipAction",
            "applies machining_envs.wrappers.IncrementalAction or agents.rl.residual.SetpointResidual",
        ),
        ("agents.rl.callbacks.ValidationCallback", "agents.rl.callbacks.Nope", "cannot import"),
        ("agents.rl.callbacks.ValidationCallback", "numpy.ndarray", "not an SB3 callback"),
    ]
    for old, new, message in cases:
        path = tmp_path / "bad.yml"
        path.write_text(entry.replace(old, new, 1))
        with pytest.raises(ConfigError, match=message):
            load_config(ENDMILLING, "ppo", path)
    cfg = load_config(ENDMILLING, "ppo")
    assert (cfg.action_increment, cfg.hide_action) == (0.3, True)
    assert (cfg.eval_freq, cfg.eval_episodes, cfg.eval_scenarios) == (100000, 20, ["validation"])


def test_a_policy_of_ours_opens_with_rl_zoo3_enjoy(tmp_path, capsys):
    """``machining-bench export --zoo`` writes rl-zoo3's layout; rl-zoo3's own loading
    (``create_test_env`` with the saved hyperparameters and statistics) then drives the env
    through the states our PolicyAgent drives it through (to the float32 rounding of the
    actions); ``rl_zoo3.enjoy`` runs."""
    from rl_zoo3.utils import create_test_env, get_saved_hyperparams
    from stable_baselines3 import PPO

    model = PRETRAINED_DIR / "end_milling_ppo" / "best_model.zip"
    assert main(["export", "--zoo", "--model", str(model), "--out", str(tmp_path)]) == 0
    assert "rl_zoo3.enjoy" in capsys.readouterr().out
    exp = tmp_path / "ppo" / "machining_envs-EndMilling-v0_1"
    name = "machining_envs-EndMilling-v0"
    hyper, stats = get_saved_hyperparams(str(exp / name), test_mode=True)
    env_kwargs = hyper.pop("env_kwargs")
    # should_render=False, as enjoy's --no-render: rl-zoo3 would otherwise open the env in
    # "human" mode and draw every step (a third of a second each, two minutes in all)
    zoo_env = create_test_env(
        ENDMILLING,
        n_envs=1,
        stats_path=stats,
        seed=7,
        should_render=False,
        hyperparams=hyper,
        env_kwargs=env_kwargs,
    )
    zoo_model = PPO.load(exp / "best_model.zip", device="cpu")
    obs = zoo_env.reset()
    ours = gym.make(ENDMILLING, **env_kwargs)
    raw, _ = ours.reset(seed=7)
    agent = load_policy(model)
    for _ in range(300):
        action, _ = zoo_model.predict(obs, deterministic=True)
        obs, _, done, infos = zoo_env.step(action)
        mine, _ = agent.predict(raw)
        raw, _, terminated, truncated, info = ours.step(mine)
        # Our policy acts in float64 (agents.rl.policy.ExactActor), SB3 in float32: the
        # same states to the float32 rounding of the actions.
        assert infos[0]["torque_Nmm"] == pytest.approx(info["torque_Nmm"], rel=1e-4, abs=1e-6)
        assert done[0] == (terminated or truncated)
        if done[0]:
            break
    out = _run_module(
        [
            "rl_zoo3.enjoy",
            "--algo",
            "ppo",
            "--env",
            ENDMILLING,
            "-f",
            str(tmp_path),
            "--gym-packages",
            "machining_envs",
            "--exp-id",
            "1",
            "--load-best",
            "--no-render",
            "-n",
            "200",
        ],
        timeout=300,
    )
    assert "Loading running average" in out.stdout
    assert np.isfinite(info["torque_Nmm"])
