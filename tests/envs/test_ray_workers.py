"""The ids in Ray RLlib's remote env runners: processes that never imported the package.

Gymnasium 1.x loads no plugins, so a worker resolves ``machining_envs/Turning-v0`` only once
something imported ``machining_envs`` there. The two documented ways: the module prefix
(``machining_envs:machining_envs/Turning-v0``, which gymnasium imports before the lookup), and
an env creator that imports the package itself. Each test trains one PPO iteration whose
samples come from one remote runner, and checks that runner's process and env.
"""

import os

import gymnasium as gym
import pytest

rllib = pytest.importorskip("ray.rllib", reason="the ray extra is not installed")
import ray  # noqa: E402
from ray.rllib.algorithms.ppo import PPOConfig  # noqa: E402
from ray.tune.registry import register_env  # noqa: E402

BATCH = 100


@pytest.fixture(scope="module")
def ray_session():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def _one_iteration(env, env_config: dict) -> tuple[dict, list]:
    config = (
        PPOConfig()
        .environment(env, env_config=env_config)
        .env_runners(num_env_runners=1, num_envs_per_env_runner=1, rollout_fragment_length=50)
        .training(train_batch_size_per_learner=BATCH, minibatch_size=50, num_epochs=1)
        .debugging(seed=0)
    )
    algo = config.build_algo()
    try:
        result = algo.train()
        remote = algo.env_runner_group.foreach_env_runner(
            lambda runner: (
                os.getpid(),
                type(runner.env.unwrapped.envs[0].unwrapped).__name__,
                runner.env.unwrapped.envs[0].unwrapped.scenario.name,
            ),
            local_env_runner=False,
        )
    finally:
        algo.stop()
    return result, remote


def _check(result: dict, remote: list, env_class: str) -> None:
    assert len(remote) == 1
    pid, name, scenario = remote[0]
    assert pid != os.getpid()  # the samples came from another process
    assert name == env_class
    assert scenario == "train"  # env_config reached the env's constructor
    assert result["env_runners"]["num_env_steps_sampled"] == BATCH


def test_the_module_prefix_resolves_the_id_in_a_remote_runner(ray_session):
    result, remote = _one_iteration(
        "machining_envs:machining_envs/Turning-v0", {"scenario": "train"}
    )
    _check(result, remote, "TurningEnv")


def test_an_env_creator_that_imports_the_package_works_in_a_remote_runner(ray_session):
    def creator(env_config):
        import machining_envs  # noqa: F401  (registers the ids in this process)

        return gym.make("machining_envs/EndMilling-v0", **env_config)

    register_env("end_milling_from_creator", creator)
    result, remote = _one_iteration("end_milling_from_creator", {"scenario": "train"})
    _check(result, remote, "EndMillingEnv")
