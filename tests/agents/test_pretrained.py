"""Shipped policies: one folder per env (one policy per training seed), small, regenerable,
selected without the test split, loaded by the benchmark."""

import json
import re
import zipfile
from pathlib import PurePosixPath

import pytest

import machining_envs
from agents.bench.declarations import BENCHMARKS
from agents.rl import GATE_FAILED, PRETRAINED_DIR, SUPERSEDED, pretrained, pretrained_seeds
from machining_envs.core.splits import HELD_OUT

FOLDERS = sorted(p for p in PRETRAINED_DIR.iterdir() if p.is_dir())


def _records(folder) -> list[dict]:
    """The run record (``config.json``) of every policy in the folder, one per seed."""
    return [
        json.loads((model.parent / "config.json").read_text())
        for _, model in pretrained_seeds(folder.name)
    ]


def test_every_env_has_a_pretrained_policy_in_the_benchmark():
    listed = {name for spec in BENCHMARKS for name in spec.learned}
    envs_with_row = {_records(PRETRAINED_DIR / name)[0]["env_id"] for name in listed}
    assert envs_with_row == set(machining_envs.ENV_IDS)
    # every shipped folder is a benchmark row or a formulation kept for the record
    kept = set(GATE_FAILED) | set(SUPERSEDED)
    assert listed | kept == {f.name for f in FOLDERS}
    assert not listed & kept and not set(GATE_FAILED) & set(SUPERSEDED)
    for old, new in SUPERSEDED.items():  # replaced by a row of its own env
        assert new in listed
        assert (
            _records(PRETRAINED_DIR / old)[0]["env_id"]
            == _records(PRETRAINED_DIR / new)[0]["env_id"]
        )
    for spec in BENCHMARKS:
        for name in spec.learned:
            assert {r["env_id"] for r in _records(PRETRAINED_DIR / name)} == {spec.env_id}, name


def test_an_unknown_pretrained_name_is_refused_at_once_naming_the_shipped_ones():
    # It gave a factory that failed only when called ("no model at ...").
    with pytest.raises(ValueError, match=r"pretrained name must be one of \[.*'turning_ppo'"):
        pretrained("turning_pp")
    assert pretrained("turning_ppo").learned


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_each_pretrained_policy_has_its_regeneration_command_and_is_small(folder):
    readme = (folder / "README.md").read_text()
    env_id = _records(folder)[0]["env_id"]
    size = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())
    assert size < 5 * 2**20, folder
    seeds = [seed for seed, _ in pretrained_seeds(folder.name)]
    assert len(seeds) >= 5, folder
    if f"machining-bench sweep --env {env_id}" in readme:  # all seeds by one sweep
        assert f"--seeds {' '.join(str(s) for s in seeds)}" in readme, folder
    else:
        assert f"machining-bench train --env {env_id}" in readme
        for seed in seeds:
            assert f"--seed {seed}" in readme, (folder, seed)
    for _, model in pretrained_seeds(folder.name):
        assert (model.parent / "best_vecnormalize.json").is_file(), model


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_each_pretrained_policys_record_names_the_command_and_config_that_made_it(folder):
    """Each seed's ``config.json`` names the command of its README that trained it and
    the shipped config file by its place in the repository, nothing of the machine that
    ran it (a sweep's trial records the sweep's command, not its Ray worker's)."""
    readme = _without_out((folder / "README.md").read_text())
    for record in _records(folder):
        command = record["command"]
        assert command.startswith(f"machining-bench train --env {record['env_id']} ") or (
            command.startswith(f"machining-bench sweep --env {record['env_id']} ")
        ), (folder, command[:80])
        assert _without_out(command) in readme, (folder, command[:80])
        assert record["config"]["source"].startswith("agents/rl/configs/"), folder


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_each_pretrained_model_file_names_no_folder_of_a_machine(folder):
    """A shipped ``.zip`` holds no TensorBoard folder (a model loaded to train further
    would log there) nor any other absolute path among its saved attributes."""
    for _, model in pretrained_seeds(folder.name):
        with zipfile.ZipFile(model) as z:
            data = json.loads(z.read("data"))
        assert "tensorboard_log" not in data, model
        paths = [
            k for k, v in data.items() if isinstance(v, str) and PurePosixPath(v).is_absolute()
        ]
        assert not paths, (model, paths)


def _without_out(text: str) -> str:
    """``text`` without the values of its ``--out`` options (a README may name the run
    folder otherwise than the run did)."""
    return re.sub(r"--out \S+", "--out", text)


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_pretrained_policy_was_selected_without_the_test_split(folder):
    """Model selection used ``validation``: the recorded configuration names no held-out
    split for evaluation or training."""
    for record in _records(folder):
        cfg = record["config"]
        assert not set(cfg["eval_scenarios"]) & set(HELD_OUT), folder
        assert cfg["env_kwargs"].get("scenario", "train") not in HELD_OUT, folder


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_recorded_configuration_is_the_shipped_config_entry(folder):
    """The regeneration command trains with the shipped config file
    (``agents/rl/configs/<file>.yml``, recorded as the run's source): its entry must still be
    the configuration the shipped policy was trained with."""
    from dataclasses import MISSING, asdict, fields
    from pathlib import Path

    from agents.rl import CONFIG_DIR, TrainConfig, load_config

    rec = _records(folder)[0]
    recorded = rec["config"]
    source = CONFIG_DIR / Path(recorded["source"]).name
    now = asdict(load_config(rec["env_id"], rec["algo"], source))
    for key in ("source",):
        now.pop(key), recorded.pop(key)
    # Settings added after a policy was trained: its run behaved as their default does.
    defaults = {
        f.name: f.default if f.default_factory is MISSING else f.default_factory()
        for f in fields(TrainConfig)
    }
    for key in set(now) - set(recorded):
        assert now.pop(key) == defaults[key], key
    assert json.loads(json.dumps(now, default=str)) == recorded


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_the_exact_actor_is_sb3s_deterministic_predict_to_float32_rounding(folder):
    """``PolicyAgent`` computes a shipped policy's deterministic action in float64
    (``ExactActor``, batch-independent); it is SB3's ``model.predict(...,
    deterministic=True)`` (float32) to float32 rounding, one observation or a batch."""
    import numpy as np

    from agents.rl import load_policy

    rng = np.random.default_rng(0)
    for _, model in pretrained_seeds(folder.name)[:2]:
        agent = load_policy(model)
        policy = getattr(agent, "policy", agent)  # a residual agent's own policy
        assert policy._fast
        obs = rng.normal(size=(32, *policy.model.observation_space.shape)).astype(np.float32)
        want, _ = policy.model.predict(obs, deterministic=True)
        np.testing.assert_allclose(policy._mean_action(obs), want, rtol=1e-5, atol=2e-6)
        one = policy._mean_action(obs[0])
        assert one.shape == want[0].shape
        np.testing.assert_allclose(one, want[0], rtol=1e-5, atol=2e-6)


@pytest.mark.slow
@pytest.mark.parametrize("name", GATE_FAILED)
def test_the_folders_kept_out_of_the_benchmark_fail_the_seed_gate(name):
    """Their first seed fails the gate (docs/performance.md, "the seed gate on the shipped
    policies"): the reason they are not benchmark rows."""
    pytest.importorskip("stable_baselines3")
    from agents.rl.gate import gate_policy

    seed, model = pretrained_seeds(name)[0]
    env_id = _records(PRETRAINED_DIR / name)[0]["env_id"]
    assert not gate_policy(model, env_id).passed, (name, seed)


def test_a_field_that_never_varied_in_training_is_shown_its_training_value():
    """Turning-v0's force limit is 1000 N on every ``train`` cut, so the shipped turning
    policies' statistics give it a spread of about 1e-4.5: a limit of 1300 N (``ood``)
    reached the network as the clip, 10 standard deviations, for any limit but 1000 N. The
    policy is now shown the value it trained on, and on the training value it acts exactly
    as before."""
    import gymnasium as gym
    import numpy as np

    from agents.rl import load_policy

    (_, model), *_ = pretrained_seeds("turning_ppo_residual")
    policy = load_policy(model).policy
    limit = gym.make("machining_envs/Turning-v0").unwrapped.OBS_INDEX["limit"]
    index, value = policy.held_fields()
    assert index.tolist() == [limit] and value.tolist() == [1.0]
    rng = np.random.default_rng(3)
    obs = np.abs(rng.normal(0.6, 0.2, size=(16, 7))).astype(np.float32)
    obs[:, limit] = 1.0
    raw = (obs - policy.obs_rms.mean) / np.sqrt(policy.obs_rms.var + policy.epsilon)
    np.testing.assert_array_equal(policy.normalize(obs), np.clip(raw, -10, 10).astype(np.float32))
    other = obs.copy()
    other[:, limit] = 1.3
    np.testing.assert_array_equal(policy.predict(other)[0], policy.predict(obs)[0])
    varied = obs.copy()
    varied[:, 0] += 0.2  # a field that varied in training still moves the action
    assert not np.array_equal(policy.predict(varied)[0], policy.predict(obs)[0])
