"""Using the envs from another project: ids with the module prefix, overrides, own ids, SB3."""

import gymnasium as gym
from stable_baselines3.common.env_util import make_vec_env

from machining_envs import TurningEnv, TurningParams
from tests.helpers import TURNING, run_python


def test_register_own_id_with_own_machine():
    """A user registers their identified lathe under their own id."""
    mine = TurningParams(force_coefficient=2100.0, feed_exponent=0.8, sensor_gain=12.0)
    gym.register(
        id="mylab/MyLathe-v0",
        entry_point=TurningEnv,
        kwargs={"params": mine, "scenario": "paper_405"},
        max_episode_steps=500,
    )
    try:
        env = gym.make("mylab/MyLathe-v0")
        env.reset(seed=0)
        assert env.unwrapped.params.force_coefficient == 2100.0
        assert env.spec.max_episode_steps == 500
        # Overrides still work on top of the registered kwargs.
        env = gym.make("mylab/MyLathe-v0", sensor_gain=14.0)
        params = env.unwrapped.params
        assert params.sensor_gain == 14.0 and params.feed_exponent == 0.8
    finally:  # the registry as the test found it
        gym.registry.pop("mylab/MyLathe-v0", None)


def test_module_prefix_and_make_vec_env_in_a_fresh_interpreter():
    code = (
        "import gymnasium as gym\n"
        "from stable_baselines3.common.env_util import make_vec_env\n"
        "venv = make_vec_env('machining_envs:machining_envs/Turning-v0', n_envs=2, seed=0,\n"
        "                    env_kwargs={'spindle_rpm': 245})\n"
        "obs = venv.reset()\n"
        "print(obs.shape, venv.get_attr('spindle_rpm_override')[0])\n"
    )
    assert run_python(code) == "(2, 7) 245.0"


def test_make_vec_env_on_our_id():
    venv = make_vec_env(TURNING, n_envs=3, seed=1)
    obs = venv.reset()
    assert obs.shape == (3, 7)
    venv.close()
