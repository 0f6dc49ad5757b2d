"""PPO's whole ``learn()`` on the native vector env against the same run on SB3's
DummyVecEnv (and SubprocVecEnv), env-steps per second, in one process.

The runs use one PPO configuration (``MlpPolicy``, ``n_steps`` 256 per env, batch 256, 4
epochs) and the same seed; on the native env and on DummyVecEnv they see the very same
episodes (lane i is env i with seed + i), so the difference is the cost of stepping the
envs. The validation evaluations of a training run are not part of these runs.

    python benchmarks/train_throughput.py [--env machining_envs/Turning-v0] [--n-envs 16]
        [--steps 32768]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import torch
from stable_baselines3 import PPO

import machining_envs  # noqa: F401
from agents.rl.config import TrainConfig
from agents.rl.train import _make_vec


def learn_rate(env_id: str, vec: str, n_envs: int, steps: int, seed: int) -> float:
    cfg = TrainConfig(env_id=env_id, algo="ppo", n_envs=n_envs, env_kwargs={"scenario": "train"})
    venv, _ = _make_vec(cfg, seed, vec)
    model = PPO("MlpPolicy", venv, n_steps=256, batch_size=256, n_epochs=4, seed=seed, device="cpu")
    t0 = time.perf_counter()
    model.learn(steps)
    rate = model.num_timesteps / (time.perf_counter() - t0)
    venv.close()
    return rate


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", default="machining_envs/Turning-v0")
    ap.add_argument("--n-envs", type=int, default=16)
    ap.add_argument("--steps", type=int, default=32_768)
    ap.add_argument("--subproc", action="store_true", help="also SubprocVecEnv")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    kinds = ["dummy", "native"] + (["subproc"] if args.subproc else [])
    if gym.spec(args.env).vector_entry_point is None:
        kinds.remove("native")
    rates = {k: learn_rate(args.env, k, args.n_envs, args.steps, 0) for k in kinds}
    print(f"PPO learn() on {args.env}, {args.n_envs} envs, {args.steps} steps, torch 1 thread")
    for k, r in rates.items():
        print(f"{k:8s} {r:9.0f} env-steps/s  {r / rates['dummy']:5.2f}x DummyVecEnv")


if __name__ == "__main__":
    main()
