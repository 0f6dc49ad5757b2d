"""Shipped policies: one folder per env (one policy per training seed), small, regenerable,
selected without the test split, loaded by the benchmark."""

import json

import pytest

import machining_envs
from agents.bench.declarations import BENCHMARKS
from agents.rl import PRETRAINED_DIR, pretrained_seeds
from machining_envs.core.splits import HELD_OUT

FOLDERS = sorted(p for p in PRETRAINED_DIR.iterdir() if p.is_dir())


def test_every_env_has_a_pretrained_policy_in_the_benchmark():
    envs_with_policy = {json.loads((f / "config.json").read_text())["env_id"] for f in FOLDERS}
    assert envs_with_policy == set(machining_envs.ENV_IDS)
    listed = {name for spec in BENCHMARKS for name in spec.learned}
    assert listed == {f.name for f in FOLDERS}
    for spec in BENCHMARKS:
        for name in spec.learned:
            cfg = json.loads((PRETRAINED_DIR / name / "config.json").read_text())
            assert cfg["env_id"] == spec.env_id, name


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_each_pretrained_policy_has_its_regeneration_command_and_is_small(folder):
    readme = (folder / "README.md").read_text()
    cfg = json.loads((folder / "config.json").read_text())
    assert f"machining-bench train --env {cfg['env_id']}" in readme
    size = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())
    assert size < 5 * 2**20, folder
    for seed, model in pretrained_seeds(folder.name):
        assert f"--seed {seed}" in readme, (folder, seed)
        assert (model.parent / "best_vecnormalize.json").is_file(), model


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_pretrained_policy_was_selected_without_the_test_split(folder):
    """Model selection used ``validation``: the recorded configuration names no held-out
    split for evaluation or training."""
    for cfg_path in [folder / "config.json", *folder.glob("seed_*/config.json")]:
        cfg = json.loads(cfg_path.read_text())["config"]
        assert not set(cfg["eval_scenarios"]) & set(HELD_OUT), cfg_path
        assert cfg["env_kwargs"].get("scenario", "train") not in HELD_OUT, cfg_path


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_recorded_configuration_is_the_shipped_config_entry(folder):
    """The regeneration command trains with ``agents/rl/configs/<algo>.yml``: its entry must
    still be the configuration the shipped policy was trained with."""
    from dataclasses import MISSING, asdict, fields

    from agents.rl import TrainConfig, load_config

    rec = json.loads((folder / "config.json").read_text())
    now = asdict(load_config(rec["env_id"], rec["algo"]))
    recorded = rec["config"]
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
