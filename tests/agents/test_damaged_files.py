"""Every file the library reads for a policy is checked against what it is read for, and a
damaged one is refused by a ``ValueError`` (or ``FileNotFoundError``) naming it: the model
archive, the run's ``config.json``, the normalisation statistics (against the model's
observations), the env the policy is loaded for. Training refuses a policy it cannot
build, and a run it cannot resume, before it writes anything."""

from __future__ import annotations

import functools
import json
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from agents.eval import evaluate
from agents.rl import ConfigError, evaluate_policy_file, load_policy, pretrained
from agents.rl.policy import PRETRAINED_DIR, pretrained_seeds, read_run_config
from agents.rl.stats import read_stats
from agents.turning import ConstantFeed
from tests.agents.test_rl import TINY
from tests.helpers import CONTOURING, MILLING, TURNING, refuses_config, train_quietly

SHIPPED = PRETRAINED_DIR / "turning_ppo"


@pytest.fixture
def run(tmp_path) -> Path:
    """A copy of the shipped Turning-v0 policy's run folder (model, statistics, record)."""
    for name in ("best_model.zip", "best_vecnormalize.json", "config.json"):
        shutil.copy(SHIPPED / name, tmp_path / name)
    return tmp_path


def _stats(run: Path) -> dict:
    return json.loads((run / "best_vecnormalize.json").read_text())


# ---- statistics ---------------------------------------------------------------------------
@pytest.mark.parametrize("length", [1, 5, 10])
def test_statistics_of_another_length_than_the_observation_are_refused(run, length):
    data = _stats(run)
    data["obs_mean"] = [0.5] * length
    data["obs_var"] = [2.0] * length
    (run / "best_vecnormalize.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match=rf"best_vecnormalize.json: .*shape \({length},\).*\(7,\)"):
        load_policy(run / "best_model.zip")


def test_a_variance_of_zero_is_refused(run):
    data = _stats(run)
    data["obs_var"][3] = 0.0
    (run / "best_vecnormalize.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"best_vecnormalize.json: obs_var must be > 0.*\[3\]"):
        load_policy(run / "best_model.zip")


def test_binary_statistics_are_refused_naming_the_file(run):
    (run / "best_vecnormalize.json").write_bytes(bytes(range(128, 256)) * 4)
    with pytest.raises(ValueError, match="best_vecnormalize.json: not a statistics file"):
        read_stats(run / "best_vecnormalize.json")
    with pytest.raises(ValueError, match="best_vecnormalize.json: not a statistics file"):
        load_policy(run / "best_model.zip")


def test_missing_statistics_of_a_run_that_normalises_are_an_error(run):
    (run / "best_vecnormalize.json").unlink()
    with pytest.raises(FileNotFoundError, match="best_vecnormalize.json.*normalised"):
        load_policy(run / "best_model.zip")
    # A run that says it did not normalise loads without them ...
    meta = json.loads((run / "config.json").read_text())
    meta["config"]["normalize"] = False
    (run / "config.json").write_text(json.dumps(meta))
    assert load_policy(run / "best_model.zip").obs_rms is None
    # ... and refuses statistics that would normalise what it saw raw.
    shutil.copy(SHIPPED / "best_vecnormalize.json", run / "best_vecnormalize.json")
    with pytest.raises(ValueError, match="did not normalise"):
        load_policy(run / "best_model.zip")


# ---- the model archive ----------------------------------------------------------------------
def _rewrite(path: Path, drop: str | None = None, replace: dict | None = None) -> None:
    with zipfile.ZipFile(path) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    members.pop(drop, None)
    members.update(replace or {})
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[:2000])


@pytest.mark.parametrize(
    "damage,message",
    [
        pytest.param(_truncate, "BadZipFile", id="truncated"),
        pytest.param(functools.partial(_rewrite, drop="data"), "no data", id="no data"),
        pytest.param(
            functools.partial(_rewrite, replace={"data": b'{"policy_class": '}),
            "not JSON",
            id="data not JSON",
        ),
        pytest.param(
            functools.partial(_rewrite, replace={"data": bytes(range(128, 256))}),
            "not JSON",
            id="data binary",
        ),
        pytest.param(
            functools.partial(_rewrite, replace={"data": b"[1, 2]"}),
            "does not name",
            id="data a list",
        ),
        pytest.param(
            functools.partial(_rewrite, drop="policy.pth"), "no policy.pth", id="no policy"
        ),
        pytest.param(
            functools.partial(_rewrite, replace={"policy.pth": b"\x00garbage" * 50}),
            "",
            id="policy garbage",
        ),
    ],
)
def test_a_damaged_model_archive_is_refused_naming_the_file(run, damage, message):
    model = run / "best_model.zip"
    damage(model)
    with pytest.raises(ValueError, match=f"best_model.zip: not a PPO model.*{message}"):
        load_policy(model)


def test_a_model_without_data_is_refused_under_python_O(run):
    """SB3 checks the archive's data with ``assert``, which ``python -O`` skips."""
    _rewrite(run / "best_model.zip", drop="data")
    code = (
        "from agents.rl import load_policy\n"
        f"try:\n    load_policy({str(run / 'best_model.zip')!r})\n"
        "except ValueError as e:\n    print('refused:', e)\n"
    )
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run(
        [sys.executable, "-O", "-c", code], capture_output=True, text=True, cwd=root, check=True
    ).stdout
    assert "refused:" in out and "best_model.zip" in out and "no data" in out


# ---- the run's record -------------------------------------------------------------------------
@pytest.mark.parametrize(
    "text,message",
    [
        (b'{"env_id": ', "not a run record"),
        (bytes(range(128, 256)), "not a run record.*UTF-8"),
        (b"[1, 2]", "not a run record.*JSON object"),
        (b'{"env_id": 3}', "env_id must be str"),
        (b'{"algo": "dqn"}', "algo must be one of"),
        (b'{"seed": "one"}', "seed must be int"),
        (b'{"action_increment": {"max_step": 9, "prev_action_index": 0}}', "action_increment"),
        (b'{"residual": {"base": "nowhere.Nothing"}}', "residual: base: cannot import"),
    ],
)
def test_a_damaged_run_record_is_refused_naming_the_file(run, text, message):
    (run / "config.json").write_bytes(text)
    with pytest.raises(ValueError, match=f"config.json: .*{message}"):
        load_policy(run / "best_model.zip", algo="ppo")
    with pytest.raises(ValueError, match="config.json"):
        read_run_config(run / "config.json")


def test_pretrained_seeds_read_the_record_checked(tmp_path):
    folder = tmp_path / "p"
    shutil.copytree(SHIPPED, folder)
    (folder / "config.json").write_text('{"seed": 1.5}')
    with pytest.raises(ValueError, match="config.json: seed must be int"):
        pretrained_seeds("p", root=tmp_path)


# ---- the env a policy is loaded for ---------------------------------------------------------
def test_a_policy_is_checked_against_the_env_it_is_loaded_for(run):
    model = run / "best_model.zip"
    assert load_policy(model, env=TURNING).obs_rms is not None
    with pytest.raises(ValueError, match="trained on machining_envs/Turning-v0, not .*EndMilling"):
        load_policy(model, env=MILLING)
    # force: another env with the same spaces (EndMilling-v0's observation has 7 entries too)
    load_policy(model, env=MILLING, force=True)
    with pytest.raises(ValueError, match=r"observations of shape \(7,\).*\(14,\)"):
        load_policy(model, env=CONTOURING, force=True)
    # Without a record, the shapes are still checked.
    (run / "config.json").unlink()
    with pytest.raises(ValueError, match=r"observations of shape \(7,\)"):
        load_policy(model, algo="ppo", env=gym.make(CONTOURING))
    with pytest.raises(ValueError, match="registered env id"):
        load_policy(model, env="machining_envs/Nothing-v0")


def test_a_shipped_policy_refuses_another_env():
    with pytest.raises(ValueError, match="trained on machining_envs/Turning-v0"):
        pretrained("turning_ppo")(gym.make(MILLING))
    assert pretrained("turning_ppo")(gym.make(TURNING)).obs_rms is not None


def test_evaluate_policy_file_refuses_another_env_unless_forced(run):
    with pytest.raises(ValueError, match="trained on machining_envs/Turning-v0"):
        evaluate_policy_file(run / "best_model.zip", MILLING, ["validation"], 1, 0)


# ---- the residual agent ---------------------------------------------------------------------
def test_a_residual_agents_errors_name_itself_not_its_regulator():
    _, path = pretrained_seeds("turning_ppo_residual")[0]
    agent = load_policy(path)
    obs, _ = gym.make(TURNING).reset(seed=0)
    bad = obs.copy()
    bad[2] = np.nan
    with pytest.raises(ValueError, match=r"observation\[2\]") as err:
        agent.predict(bad)
    assert str(err.value).startswith(f"{agent.name}:")
    assert agent.base.name not in str(err.value)
    with pytest.raises(ValueError, match=f"^{re.escape(agent.name)}: state"):
        agent.predict(obs, np.zeros((1, 3)))


# ---- evaluate's arguments -------------------------------------------------------------------
def test_evaluate_refuses_scenarios_none_and_labels_the_default_by_its_name():
    """``scenarios=None`` ran the default split under the label 'None'; ``[None]`` (the
    env's default, asked for) is labelled by the scenario it ran."""
    with pytest.raises(ValueError, match=r"scenarios must be .*\[None\] for the env's default"):
        evaluate(ConstantFeed.from_env, TURNING, None)
    ev = evaluate(ConstantFeed.from_env, TURNING, [None, "validation"], batched=False)
    assert [r["scenario"] for r in ev.rows] == ["train", "validation"]
    ev = evaluate(ConstantFeed.from_env, TURNING, [None], env_kwargs={"scenario": "paper_405"})
    assert [r["scenario"] for r in ev.rows] == ["paper_405"]


def test_evaluate_checks_its_other_arguments_first():
    with pytest.raises(ValueError, match="env_id must be a registered env id"):
        evaluate(ConstantFeed.from_env, "machining_envs/Nothing-v0", ["validation"])
    with pytest.raises(TypeError, match="agent must have SB3's predict"):
        evaluate(None, TURNING, ["validation"])
    with pytest.raises(TypeError, match="progress must be True or False"):
        evaluate(ConstantFeed.from_env, TURNING, ["validation"], progress="yes")
    with pytest.raises(TypeError, match="metrics_fn"):
        evaluate(ConstantFeed.from_env, TURNING, ["validation"], metrics_fn=3)
    with pytest.raises(TypeError, match="factory returned"):
        evaluate(lambda env: None, TURNING, ["validation"])


# ---- training -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "extra,message",
    [
        ("policy: FooPolicy", "policy must be one of"),
        ("policy: CnnPolicy", "cannot build the policy 'CnnPolicy'"),
        ("policy_kwargs: {nonsense: 1}", "cannot build the policy.*nonsense"),
        ('policy_kwargs: "dict(net_arch=[-5])"', "cannot build the policy.*net_arch"),
        ('policy_kwargs: {net_arch: "wide"}', "cannot build the policy"),
        ("policy_kwargs: {1: 2}", "policy_kwargs keys must be names"),
    ],
)
def test_a_policy_that_cannot_be_built_is_refused_leaving_no_run_folder(tmp_path, extra, message):
    refuses_config(tmp_path, TINY + f"  {extra}\n", message)


def test_a_run_folder_under_a_file_is_refused_before_any_work(tmp_path):
    config = tmp_path / "c.yml"
    config.write_text(TINY)
    (tmp_path / "f").write_text("x")
    for out in (tmp_path / "f", tmp_path / "f" / "r"):
        with pytest.raises(FileExistsError, match="is a file"):
            train_quietly(TURNING, out, config)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yml", "f"]


def test_a_run_that_cannot_be_resumed_is_refused_naming_the_file(run, tmp_path):
    config = tmp_path / "c.yml"
    config.write_text(TINY)
    folder = tmp_path / "resumed"
    folder.mkdir()
    shutil.copy(run / "best_model.zip", folder / "final_model.zip")
    # The run normalises: its statistics must be there.
    with pytest.raises(ConfigError, match="final_vecnormalize.json"):
        train_quietly(TURNING, folder, config, resume=True)
    shutil.copy(run / "best_vecnormalize.json", folder / "final_vecnormalize.json")
    (folder / "final_model.zip").write_bytes(b"PK\x03\x04 damaged")
    with pytest.raises(ConfigError, match="final_model.zip: not a PPO model"):
        train_quietly(TURNING, folder, config, resume=True)


# ---- other files read -----------------------------------------------------------------------
def test_a_binary_training_config_is_refused_naming_the_file(tmp_path):
    from agents.rl import load_config

    config = tmp_path / "c.yml"
    config.write_bytes(bytes(range(128, 256)))
    with pytest.raises(ConfigError, match="c.yml: not a configuration file"):
        load_config(TURNING, "ppo", config)


@pytest.mark.parametrize(
    "content,message",
    [
        (b'{"envs": ', "tuned.json: not a tuned settings file"),
        (bytes(range(128, 256)), "tuned.json: not a tuned settings file .not UTF-8"),
        (b"[]", "tuned.json: not a tuned settings file .a JSON object"),
        (b'{"envs": {"machining_envs/Turning-v0": {"VariableGainPI": {}}}}', "params must be"),
        (b'{"envs": {"machining_envs/Turning-v0": {"VariableGainPI": 3}}}', "params must be"),
        (b'{"envs": []}', "has no VariableGainPI entry"),
    ],
)
def test_a_damaged_tuned_file_is_refused_by_the_residual_spec(
    tmp_path, monkeypatch, content, message
):
    from agents.rl import residual

    path = tmp_path / "tuned.json"
    path.write_bytes(content)
    monkeypatch.setattr(residual, "TUNED_FILE", path)
    spec = residual.ResidualSpec("agents.turning.VariableGainPI")
    with pytest.raises(ValueError, match=message):
        spec.settings(TURNING)


# ---- wrappers: a refused step leaves the regulator's state as it was ------------------------
def _residual_env(**kwargs):
    from agents.rl.residual import SetpointResidual

    params = {"k": 0.3, "kgh": 1.9, "setpoint": 0.8}
    return SetpointResidual(gym.make(TURNING, **kwargs), "agents.turning.VariableGainPI", params)


def test_a_refused_residual_step_keeps_the_regulators_state():
    env = _residual_env(max_episode_time_s=0.5)
    env.reset(seed=0)
    env.step(np.array([0.1], dtype=np.float32))
    kept = env._state.copy()
    for bad in ([0.1, 0.2], np.array([np.nan]), "0.3", [True]):
        with pytest.raises(ValueError, match="SetpointResidual: action"):
            env.step(bad)
        np.testing.assert_array_equal(env._state, kept)
    done = False
    while not done:
        _, _, term, trunc, _ = env.step(np.array([0.0], dtype=np.float32))
        done = term or trunc
    kept = env._state.copy()
    with pytest.raises(RuntimeError, match="reset"):  # the env refuses: the episode ended
        env.step(np.array([0.0], dtype=np.float32))
    np.testing.assert_array_equal(env._state, kept)


def test_a_refused_vector_residual_step_keeps_the_regulators_state():
    from stable_baselines3.common.env_util import make_vec_env

    from agents.rl.residual import ResidualSpec, VecSetpointResidual

    spec = ResidualSpec("agents.turning.VariableGainPI", {"k": 0.3, "kgh": 1.9, "setpoint": 0.8})
    venv = make_vec_env(TURNING, n_envs=2, seed=0)
    base = spec.make_base(gym.make(TURNING), TURNING)
    wrapped = VecSetpointResidual(venv, spec, base)
    wrapped.reset()
    wrapped.step(np.zeros((2, 1), dtype=np.float32))
    kept = wrapped._state.copy()
    for bad in (np.zeros((2, 2)), np.array([[np.nan], [0.0]]), np.zeros(3), [["a"], ["b"]]):
        with pytest.raises(ValueError, match="VecSetpointResidual: action"):
            wrapped.step_async(bad)
        np.testing.assert_array_equal(wrapped._state, kept)
    wrapped.step(np.zeros((2, 1), dtype=np.float32))
    assert not np.array_equal(wrapped._state, kept)
