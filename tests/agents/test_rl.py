"""SB3 training: config validation, save/reload exactness, resume, seeded reproducibility."""

import json
import shlex

import gymnasium as gym
import numpy as np
import pytest

from agents.bench.cli import main
from agents.eval import evaluate
from agents.rl import ConfigError, load_config, load_policy, primary_score, train
from tests.helpers import MILLING, TURNING, refuses_config, train_quietly

TINY = """
machining_envs/Turning-v0:
  n_timesteps: 256
  n_envs: 2
  normalize: true
  env_kwargs: {scenario: train}
  eval_freq: 128
  eval_episodes: 1
  eval_scenarios: [paper_700]
  checkpoint_freq: 128
  n_steps: 64
  batch_size: 64
  n_epochs: 1
"""


@pytest.fixture
def tiny(tmp_path):
    path = tmp_path / "tiny.yml"
    path.write_text(TINY)
    return path


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_shipped_configs_load(algo):
    cfg = load_config(TURNING, algo)
    assert cfg.n_timesteps > 0 and cfg.env_kwargs["scenario"] == "train"
    # named as in the repository, not by where this machine installed the package
    assert cfg.source == f"agents/rl/configs/{algo}.yml"


def test_a_config_outside_the_package_is_named_by_its_path(tmp_path, monkeypatch):
    (tmp_path / "sub").mkdir()
    path = tmp_path / "sub" / "mine.yml"
    path.write_text(TINY)
    assert load_config(TURNING, "ppo", path).source == str(path.resolve())
    monkeypatch.chdir(tmp_path)  # below the working directory: relative to it
    assert load_config(TURNING, "ppo", "sub/mine.yml").source == "sub/mine.yml"


@pytest.mark.parametrize(
    "text, message",
    [
        (TINY.replace("n_epochs: 1", "n_epoch: 1"), "unknown key 'n_epoch'.*n_epochs"),
        (TINY.replace("n_envs: 2", "n_envs: two"), "n_envs must be int"),
        (TINY.replace("n_envs: 2", "n_envs: 0"), "n_envs must be >= 1"),
        (TINY.replace("batch_size: 64", "batch_size: 6.4"), "batch_size must be an integer"),
        (TINY.replace("n_epochs: 1", "n_epochs: -1"), r"n_epochs must be an integer in \[1, "),
        (TINY.replace("n_epochs: 1", "n_epochs: 1\n  gamma: 5.0"), r"gamma must be .* \(0, 1\]"),
        (
            TINY.replace("normalize: true", "normalize: {norm_obs: true, gamma: x}"),
            "normalize.gamma must be a number",
        ),
        (TINY.replace("batch_size: 64", "batch_size: 512"), "batch_size must be <= n_steps"),
        (TINY.replace("[paper_700]", "[bogus]"), "eval_scenarios: .*bogus"),
        (TINY.replace("{scenario: train}", "{scenario: train, nope: 1}"), "env_kwargs"),
        (TINY.replace("n_epochs: 1", "n_epochs: 1\n  learning_rate: fast"), "learning_rate"),
        (
            TINY.replace("normalize: true", "normalize: {norm_obs: true, clipobs: 5}"),
            "normalize keys",
        ),
        ("machining_envs/Other-v0: {}\n", "no entry"),
        ("machining_envs/Turning-v0: [1, 2\n", "not valid YAML"),
    ],
)
def test_bad_configs_fail_before_training(tmp_path, text, message):
    refuses_config(tmp_path, text, message)


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_shipped_residual_configs_of_the_off_policy_algorithms_load(algo):
    """The residual formulation's configs of SAC and TD3 share the wrapper and reward of PPO
    over the adaptive PI (the equal-budget comparison); TD3 explores with rl-zoo3's Gaussian
    action noise."""
    from agents.rl.config import CONFIG_DIR

    cfg = load_config(TURNING, algo, CONFIG_DIR / f"{algo}_residual.yml")
    ppo = load_config(TURNING, "ppo", CONFIG_DIR / "ppo_residual_pi.yml")
    assert cfg.residual == ppo.residual and cfg.env_kwargs == ppo.env_kwargs
    assert cfg.noise_type == ("normal" if algo == "td3" else None)


@pytest.mark.parametrize(
    "entry, message",
    [
        ({"noise_type": "pink"}, "noise_type must be one of"),
        ({"noise_type": "normal", "noise_std": 0.0}, r"noise_std must be a number in \(0, 10\]"),
    ],
)
def test_bad_exploration_noise_is_refused_naming_it(entry, message):
    from agents.rl.config import CONFIG_DIR

    with pytest.raises(ConfigError, match=message):
        load_config(TURNING, "td3", CONFIG_DIR / "td3_residual.yml", entry)
    with pytest.raises(ConfigError, match="noise_type is for SAC and TD3"):
        load_config(TURNING, "ppo", CONFIG_DIR / "ppo_residual.yml", {"noise_type": "normal"})


def test_rl_zoo3_value_syntax_is_read(tmp_path):
    """rl-zoo3 writes counts as ``!!float 1e6`` and schedules as ``lin_<x>``."""
    path = tmp_path / "zoo.yml"
    path.write_text(
        TINY.replace("n_timesteps: 256", "n_timesteps: !!float 2.56e2").replace(
            "n_epochs: 1", "n_epochs: 1\n  learning_rate: lin_3e-4"
        )
    )
    cfg = load_config(TURNING, "ppo", path)
    assert cfg.n_timesteps == 256 and isinstance(cfg.n_timesteps, int)
    schedule = cfg.hyperparams["learning_rate"]
    assert schedule(1.0) == pytest.approx(3e-4) and schedule(0.5) == pytest.approx(1.5e-4)


def test_missing_config_file_and_bad_algo(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(TURNING, "ppo", tmp_path / "nope.yml")
    with pytest.raises(ConfigError, match="algo"):
        load_config(TURNING, "dqn")
    assert (
        main(
            [
                "train",
                "--env",
                TURNING,
                "--out",
                str(tmp_path / "r"),
                "--config",
                str(tmp_path / "nope.yml"),
                "--no-progress",
            ]
        )
        == 2
    )


def test_train_save_reload_resume(tiny, tmp_path):
    run = train_quietly(TURNING, tmp_path / "run", tiny, seed=1)
    for name in (
        "final_model.zip",
        "final_vecnormalize.json",
        "best_model.zip",
        "best_vecnormalize.json",
        "config.json",
        "eval.csv",
    ):
        assert (run / name).is_file(), name
    assert json.loads((run / "config.json").read_text())["seed"] == 1
    # A reloaded model with its statistics reproduces its evaluation exactly.
    ev1 = evaluate(
        load_policy(run / "final_model.zip"), TURNING, ["paper_700"], n_episodes=1, seed=3
    )
    ev2 = evaluate(
        load_policy(run / "final_model.zip"), TURNING, ["paper_700"], n_episodes=1, seed=3
    )
    assert ev1.rows == ev2.rows
    # The statistics matter: without them the policy acts differently.
    agent = load_policy(run / "final_model.zip")
    assert agent.obs_rms is not None and np.any(agent.obs_rms.var != 1.0)
    # A run folder is never overwritten; --resume continues it to a new total.
    from stable_baselines3 import PPO

    with pytest.raises(FileExistsError):
        train_quietly(TURNING, run, tiny)

    def resumed_to(n_timesteps: int) -> int:
        """The steps of the final model after ``--resume`` to ``n_timesteps`` in all."""
        train_quietly(TURNING, run, tiny, n_timesteps=n_timesteps, resume=True)
        return PPO.load(run / "final_model.zip").num_timesteps

    assert resumed_to(512) >= 512
    # The model files name no folder of the machine that trained them: the run's TensorBoard
    # folder is given again when a run resumes, and both sessions logged there.
    for name in ("final_model.zip", "best_model.zip"):
        assert PPO.load(run / name).tensorboard_log is None, name
    assert len(list((run / "tb").rglob("events.out.tfevents.*"))) == 2
    suffixes = {p.suffix for p in (run / "checkpoints").iterdir()}
    assert suffixes == {".json", ".zip"}  # each checkpoint with its statistics
    assert not list(run.rglob("*.pkl")), "statistics are written as JSON only"
    # Without checkpoints, --resume continues from the final model.
    import shutil

    shutil.rmtree(run / "checkpoints")
    assert resumed_to(768) >= 768


def test_statistics_are_never_unpickled(tmp_path):
    """A pickled VecNormalize beside a model is refused (reading it could run code); a
    malformed JSON statistics file is refused with the field named."""
    import shutil

    from agents.rl.policy import PRETRAINED_DIR
    from agents.rl.stats import read_stats

    src = PRETRAINED_DIR / "turning_ppo"
    for name in ("best_model.zip", "config.json"):
        shutil.copy(src / name, tmp_path / name)
    (tmp_path / "best_vecnormalize.pkl").write_bytes(b"not read")
    with pytest.raises(ValueError, match="pickle"):
        load_policy(tmp_path / "best_model.zip")
    data = json.loads((src / "best_vecnormalize.json").read_text())
    data["obs_var"][2] = -1.0
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"obs_var must be > 0, got obs_var\[2\] = -1.0"):
        read_stats(bad)
    data["obs_var"][2] = "nan"
    bad.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"obs_var\[2\] must be a finite number"):
        load_policy(tmp_path / "best_model.zip", stats=bad)
    agent = load_policy(tmp_path / "best_model.zip", stats=src / "best_vecnormalize.json")
    assert agent.obs_rms is not None


def test_fixed_seed_reproduces_the_run(tiny, tmp_path):
    from stable_baselines3 import PPO

    params = []
    for k in range(2):
        run = train_quietly(TURNING, tmp_path / f"r{k}", tiny, seed=7)
        params.append(PPO.load(run / "final_model.zip").policy.state_dict())
    for key in params[0]:
        assert np.array_equal(params[0][key].numpy(), params[1][key].numpy()), key


def test_cli_evaluate(tiny, tmp_path, capsys):
    run = train_quietly(TURNING, tmp_path / "run", tiny, seed=2)
    assert (
        main(
            [
                "evaluate",
                "--model",
                str(run / "best_model.zip"),
                "--env",
                TURNING,
                "--scenarios",
                "paper_700",
                "--episodes",
                "1",
            ]
        )
        == 0
    )
    assert "primary score" in capsys.readouterr().out


def test_the_cli_records_its_own_command_line(tiny, tmp_path):
    argv = ["train", "--env", TURNING, "--out", str(tmp_path / "run"), "--config", str(tiny)]
    argv += ["--timesteps", "256", "--no-progress"]
    assert main(argv) == 0
    meta = json.loads((tmp_path / "run" / "config.json").read_text())
    assert meta["command"] == shlex.join(["machining-bench", *argv])


def test_primary_score_charges_episodes_that_do_not_count():
    base = {
        "breakage": 0.0,
        "time_over_limit": 0.0,
        "finished": 1.0,
        "machining_time_s": 30.0,
        "itae": 1.0,
    }
    assert primary_score([base])["score"] == 30.0
    broke = dict(base, breakage=1.0, machining_time_s=5.0)
    over = dict(base, time_over_limit=0.05, machining_time_s=10.0)
    s = primary_score([base, broke, over], failed_time_s=200.0)
    assert s["score"] == pytest.approx((30.0 + 200.0 + 200.0) / 3)
    assert s["valid"] == pytest.approx(1 / 3)


def test_training_evaluates_with_the_envs_own_metrics(tmp_path):
    """End milling reports torque, not force: the validation evaluation uses its metrics."""
    text = TINY.replace("machining_envs/Turning-v0", "machining_envs/EndMilling-v0").replace(
        "paper_700", "paper_step"
    )
    path = tmp_path / "mill.yml"
    path.write_text(text)
    run = train_quietly(MILLING, tmp_path / "run", path)
    rows = (run / "eval.csv").read_text().splitlines()
    assert len(rows) >= 2 and rows[0].startswith("timesteps,")


def test_a_policy_trained_on_increments_runs_on_the_plain_env(tmp_path):
    """``action_increment`` trains on IncrementalAction; the saved policy applies the same
    map itself, so the benchmark runs it on the plain env and gets the wrapped env's run."""
    import gymnasium as gym

    from machining_envs.wrappers import IncrementalAction

    path = tmp_path / "inc.yml"
    path.write_text(TINY + "  action_increment: 0.3\n")
    run = train_quietly(TURNING, tmp_path / "run", path)
    meta = json.loads((run / "config.json").read_text())
    assert meta["action_increment"] == {
        "max_step": 0.3,
        "prev_action_index": 2,
        "hide_action": False,
        "hidden": [],
    }
    agent = load_policy(run / "final_model.zip")
    assert agent.increment == (0.3, 2, False, ())
    plain = gym.make(TURNING)
    wrapped = IncrementalAction(gym.make(TURNING), max_step=0.3)
    op, _ = plain.reset(seed=5, options={"scenario": "paper_700"})
    ow, _ = wrapped.reset(seed=5, options={"scenario": "paper_700"})
    for _ in range(40):
        a, _ = agent.predict(op)
        delta, _ = agent.model.predict(agent.normalize(ow), deterministic=True)
        op, rp, *_ = plain.step(a)
        ow, rw, *_ = wrapped.step(delta)
        np.testing.assert_array_equal(op, ow)
        assert rp == rw


def test_a_policy_that_hides_fields_ignores_them_outside_the_wrapper(tmp_path):
    """``hide_fields`` is recorded with the run, and the loaded policy applies it itself: on
    the plain env, what it does cannot depend on the hidden fields."""
    path = tmp_path / "hide.yml"
    path.write_text(
        TINY
        + "  env_wrapper:\n    - machining_envs.wrappers.IncrementalAction:\n"
        + "        max_step: 0.3\n        hide_fields: [limit, spindle]\n"
    )
    run = train_quietly(TURNING, tmp_path / "run", path, vec="dummy")
    meta = json.loads((run / "config.json").read_text())
    assert meta["action_increment"]["hidden"] == [1, 3]
    agent = load_policy(run / "final_model.zip")
    assert agent.increment.hidden == (1, 3)
    env = gym.make(TURNING)
    env.reset(seed=2, options={"scenario": "paper_405"})
    for _ in range(5):  # mid-range feed, where the output is not clipped at the box
        obs, *_ = env.step(np.zeros(1, dtype=np.float32))
    moved = obs.copy()
    moved[[1, 3]] += 0.7
    np.testing.assert_array_equal(agent.predict(obs)[0], agent.predict(moved)[0])
    moved[0] += 0.3  # a field it sees does move it
    assert not np.array_equal(agent.predict(obs)[0], agent.predict(moved)[0])


@pytest.mark.parametrize(
    "line, message",
    [
        ("  action_increment: 0.0\n", r"action_increment must be in \(0, 2\]"),
        ("  action_increment: 3.0\n", r"action_increment must be in \(0, 2\]"),
        ("  action_increment: big\n", "action_increment must be float or int"),
    ],
)
def test_bad_action_increment_fails_before_training(tmp_path, line, message):
    refuses_config(tmp_path, TINY + line, message)


def _final_parameters(run) -> list:
    from stable_baselines3 import PPO

    model = PPO.load(run / "final_model.zip", device="cpu")
    return [p.detach().numpy().copy() for p in model.policy.parameters()]


@pytest.mark.parametrize("increment", [False, True], ids=["plain", "action_increment"])
def test_native_vector_training_reproduces_a_fixed_seed_run(tmp_path, increment):
    """Training on the native vector env is reproducible with a fixed seed, and it runs the
    very episodes DummyVecEnv runs (lane i is env i with seed + i): the same final policy
    to the last bit, with and without the action-increment wrapper."""
    text = TINY + ("  action_increment: 0.3\n  hide_action: true\n" if increment else "")
    path = tmp_path / "tiny.yml"
    path.write_text(text)
    runs = {}
    for name, vec in (("native_a", "native"), ("native_b", "native"), ("dummy", "dummy")):
        runs[name] = train_quietly(TURNING, tmp_path / name, path, seed=4, vec=vec)
    assert json.loads((runs["native_a"] / "config.json").read_text())["vec"] == "native"
    a, b, d = (_final_parameters(runs[k]) for k in ("native_a", "native_b", "dummy"))
    for pa, pb, pd in zip(a, b, d, strict=True):
        np.testing.assert_array_equal(pa, pb)
        np.testing.assert_array_equal(pa, pd)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"seed": -1}, r"seed must be an integer in \[0, 2\*\*32\), got -1"),
        ({"seed": True}, "seed must be an integer"),
        ({"seed": "a"}, "seed must be an integer"),
        ({"n_timesteps": 2.5}, "n_timesteps must be an integer >= 1, got 2.5"),
    ],
)
def test_bad_seed_and_timesteps_are_refused_before_anything_is_written(
    tiny, tmp_path, kwargs, message
):
    # A seed of -1 failed in SB3 after the run folder was made; 2.5 steps became 2.
    with pytest.raises(ConfigError, match=message):
        train(TURNING, "ppo", tmp_path / "r", config_path=tiny, progress_bar=False, **kwargs)
    assert not (tmp_path / "r").exists()


def test_bad_vec_kind_is_refused_before_training(tiny, tmp_path):
    with pytest.raises(ConfigError, match="vec must be one of"):
        train(TURNING, "ppo", tmp_path / "r", config_path=tiny, progress_bar=False, vec="gpu")
    # Every id of the package has a native vector env: an id registered without one (as a
    # user may register our classes) is refused before training.
    import gymnasium as gym

    plain = "machining_envs_tests/TurningScalar-v0"
    if plain not in gym.registry:
        gym.register(plain, entry_point="machining_envs.turning.env:TurningEnv")
    config = tmp_path / "plain.yml"
    config.write_text(TINY.replace(TURNING, plain))
    with pytest.raises(ConfigError, match="no native vector env"):
        train(plain, "ppo", tmp_path / "r2", config_path=config, vec="native")
    assert not (tmp_path / "r").exists() and not (tmp_path / "r2").exists()


def _infos_until_an_env_ends(venv) -> tuple[list[dict], list[dict]]:
    """(the infos of a step where no env ended, those of the first step where one did)."""
    venv.reset()
    rng = np.random.default_rng(0)
    quiet = None
    for _ in range(2000):
        actions = rng.uniform(-1, 1, size=(venv.num_envs, *venv.action_space.shape))
        venv.step_async(actions.astype(np.float32))
        _, _, dones, infos = venv.step_wait()
        if dones.any():
            return quiet, infos
        quiet = infos
    raise AssertionError("no episode ended")


def test_native_training_copies_the_env_info_only_for_callbacks_that_may_read_it(tmp_path):
    """Training on the native vector env gives SB3 only what it reads (terminal observation,
    TimeLimit.truncated, VecMonitor's episode) unless the configuration names a callback of
    its own, which then gets every info key, as from DummyVecEnv."""
    from agents.rl.train import _make_vec

    path = tmp_path / "tiny.yml"
    path.write_text(TINY)
    cfg = load_config(TURNING, "ppo", path)
    assert not cfg.callbacks
    venv, _ = _make_vec(cfg, seed=1, vec="native")
    quiet, ended = _infos_until_an_env_ends(venv)
    assert all(d == {} for d in quiet)
    i = next(i for i, d in enumerate(ended) if d)
    assert set(ended[i]) == {"terminal_observation", "TimeLimit.truncated", "episode"}
    venv.close()
    named = tmp_path / "named.yml"
    callback = "stable_baselines3.common.callbacks.StopTrainingOnMaxEpisodes"
    named.write_text(TINY + f"  callback:\n    - {callback}:\n        max_episodes: 1000\n")
    cfg = load_config(TURNING, "ppo", named)
    assert cfg.callbacks
    venv, _ = _make_vec(cfg, seed=1, vec="native")
    quiet, ended = _infos_until_an_env_ends(venv)
    assert {"force_N", "cost", "breakage", "TimeLimit.truncated"} <= set(quiet[0])
    i = next(i for i, d in enumerate(ended) if "terminal_observation" in d)
    assert {"force_N", "cost", "terminal_observation", "episode"} <= set(ended[i])
    venv.close()
