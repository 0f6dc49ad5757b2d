"""The Stable-Baselines3 algorithms the library trains and loads."""

from __future__ import annotations

__all__ = ["ALGOS", "algorithm_classes"]

#: The algorithm names a config file, a run and a shipped policy may name.
ALGOS = ("ppo", "sac", "td3")


def algorithm_classes() -> dict:
    """Name -> SB3 class (imported on first use: torch loads only when a policy does)."""
    from stable_baselines3 import PPO, SAC, TD3

    return {"ppo": PPO, "sac": SAC, "td3": TD3}
