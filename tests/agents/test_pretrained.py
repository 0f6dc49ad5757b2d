"""Shipped policies: one per env, small, regenerable, loaded by the benchmark; the regulation
ones win the primary score on the benchmark's held-out episodes."""

import json
import math

import gymnasium as gym
import pytest

import machining_envs
from agents.bench.declarations import BENCHMARKS
from agents.eval import evaluate
from agents.rl import PRETRAINED_DIR

FOLDERS = sorted(p for p in PRETRAINED_DIR.iterdir() if p.is_dir())


def _pretrained_factory(spec):
    return next(f for f in spec.agents if getattr(f, "__name__", "").startswith("pretrained_"))


def test_every_env_has_a_pretrained_policy_in_the_benchmark():
    envs_with_policy = {json.loads((f / "config.json").read_text())["env_id"] for f in FOLDERS}
    assert envs_with_policy == set(machining_envs.ENV_IDS)
    listed = {_pretrained_factory(spec).__name__.removeprefix("pretrained_") for spec in BENCHMARKS}
    assert listed == {f.name for f in FOLDERS}


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_each_pretrained_policy_has_its_regeneration_command_and_is_small(folder):
    readme = (folder / "README.md").read_text()
    cfg = json.loads((folder / "config.json").read_text())
    assert f"machining-bench train --env {cfg['env_id']}" in readme
    assert f"--seed {cfg['seed']}" in readme
    size = sum(p.stat().st_size for p in folder.iterdir())
    assert size < 5 * 2**20, folder
    assert (folder / "best_model.zip").is_file() and (folder / "best_vecnormalize.json").is_file()


def _scores(spec, n_episodes=20):
    """Primary score of every agent of ``spec`` on its held-out episodes (seeds 1000...)."""
    failed = spec.task.score.failed_value(gym.make(spec.env_id))
    out = {}
    for factory in spec.agents:
        ev = evaluate(
            factory,
            spec.env_id,
            [spec.heldout_scenario],
            n_episodes=n_episodes,
            seed=1000,
            metrics_fn=spec.metrics_fn,
        )
        out[ev.rows[0]["agent"]] = (spec.task.score(ev.rows, failed), ev.rows)
    return out


@pytest.mark.parametrize(
    "env_id",
    ["machining_envs/Turning-v0", "machining_envs/EndMilling-v0"],
    ids=str,
)
def test_pretrained_policy_beats_the_best_classical_agent(env_id):
    """Primary score on the benchmark's 20 held-out episodes (seeds 1000-1019)."""
    spec = next(s for s in BENCHMARKS if s.env_id == env_id)
    scores = _scores(spec)
    rl_name = next(k for k in scores if "pretrained" in k)
    rl, rl_rows = scores.pop(rl_name)
    best_name = min(scores, key=lambda k: scores[k][0]["score"])
    best = scores[best_name][0]
    assert rl["score"] < best["score"], (rl, best_name, best)
    assert all(r["breakage"] == 0.0 for r in rl_rows)
    assert math.isfinite(rl["itae"])


@pytest.mark.parametrize("folder", FOLDERS, ids=lambda p: p.name)
def test_recorded_configuration_is_the_shipped_config_entry(folder):
    """The regeneration command trains with ``agents/rl/configs/<algo>.yml``: its entry must
    still be the configuration the shipped policy was trained with."""
    from dataclasses import asdict, fields

    from agents.rl import TrainConfig, load_config

    rec = json.loads((folder / "config.json").read_text())
    now = asdict(load_config(rec["env_id"], rec["algo"]))
    recorded = rec["config"]
    for key in ("source",):
        now.pop(key), recorded.pop(key)
    # Settings added after a policy was trained: its run behaved as their default does.
    defaults = {f.name: f.default for f in fields(TrainConfig)}
    for key in set(now) - set(recorded):
        assert now.pop(key) == defaults[key], key
    assert json.loads(json.dumps(now, default=str)) == recorded
