"""``machining-bench sweep``: training trials on a local Ray instance (tiny budgets)."""

import csv
import json
import shlex

import pytest

pytest.importorskip("ray.tune", reason="the ray extra is not installed")
pytest.importorskip("stable_baselines3")

from agents.bench.cli import main  # noqa: E402
from agents.rl.sweep import SEARCH_SPACES, SweepSettings, sweep  # noqa: E402
from agents.rl.train import evaluate_policy_file  # noqa: E402
from machining_envs.core.splits import split_seeds  # noqa: E402
from tests.helpers import TURNING  # noqa: E402

STEPS = 1024  # one PPO rollout (4 envs x 256 steps) per trial


def _rows(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


def test_a_search_runs_two_optuna_trials_and_keeps_the_best_policy(tmp_path, capsys):
    out = tmp_path / "search"
    argv = ["sweep", "--env", TURNING, "--out", str(out), "--search", "2"]
    argv += ["--timesteps", str(STEPS), "--workers", "2"]
    assert main(argv) == 0
    command = shlex.join(["machining-bench", *argv])  # what every record names, not Ray's
    assert json.loads((out / "sweep.json").read_text())["command"] == command
    captured = capsys.readouterr()
    printed = captured.out
    assert "2 trials in" in printed and "trials/min" in printed
    assert "sweep: 100%" in captured.err and "2/2" in captured.err  # the trials' progress bar

    rows = _rows(out / "results.csv")
    assert len(rows) == 2
    keys = sorted(SEARCH_SPACES["ppo"])
    assert [r[k] for k in keys for r in rows[:1]] != [r[k] for k in keys for r in rows[1:]]
    assert float(rows[0]["best_score"]) <= float(rows[1]["best_score"])
    for r in rows:  # each trial trained with its own drawn hyperparameters
        meta = json.loads((out / "trials" / r["trial"] / "config.json").read_text())
        assert meta["overrides"]["learning_rate"] == pytest.approx(float(r["learning_rate"]))
        assert meta["config"]["hyperparams"]["n_steps"] == int(r["n_steps"])
        assert meta["command"] == command
    curves = _rows(out / "curves.csv")
    assert {c["trial"] for c in curves} == {r["trial"] for r in rows}
    assert all(int(c["timesteps"]) >= STEPS for c in curves)

    # best/ is the best trial's model; reloaded, it scores what the sweep recorded
    n = 10  # the shipped config's validation episodes
    _, score, _ = evaluate_policy_file(
        out / "best" / "best_model.zip", TURNING, ["validation"], n, split_seeds("validation", n)[0]
    )
    assert score["score"] == pytest.approx(float(rows[0]["best_score"]), rel=1e-12)


def test_a_seed_sweep_trains_each_seed_and_resumes_without_retraining(tmp_path):
    out = tmp_path / "seeds"
    settings = SweepSettings(TURNING, "ppo", seeds=[0, 1], n_timesteps=STEPS, workers=2)
    sweep(settings, out, verbose=False)
    rows = _rows(out / "results.csv")
    assert sorted(int(r["seed"]) for r in rows) == [0, 1]
    before = {r["trial"]: (out / "trials" / r["trial"] / "eval.csv").read_text() for r in rows}

    sweep(settings, out, resume=True, verbose=False)  # finished: nothing runs again
    after = {r["trial"]: (out / "trials" / r["trial"] / "eval.csv").read_text() for r in rows}
    assert after == before and len(_rows(out / "results.csv")) == 2

    other = SweepSettings(TURNING, "ppo", seeds=[0, 2], n_timesteps=STEPS, workers=2)
    with pytest.raises(ValueError, match="settings differ"):
        sweep(other, out, resume=True, verbose=False)
    with pytest.raises(FileExistsError, match="not empty"):
        sweep(settings, out, verbose=False)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"n_search": 2, "seeds": [0, 1]}, "one seed"),
        ({"seeds": [0, 0]}, "seeds must differ"),
        ({"seeds": [-1]}, "seeds must be integers >= 0"),
        ({"workers": 0}, "workers must be an integer >= 1"),
        ({"n_search": -1}, "n_search must be"),
        ({"algo": "dqn"}, "algo must be one of"),
    ],
)
def test_bad_settings_are_refused_before_ray_starts(tmp_path, kwargs, match):
    import ray

    with pytest.raises(ValueError, match=match):
        sweep(SweepSettings(TURNING, **kwargs), tmp_path / "x", verbose=False)
    assert not ray.is_initialized()
    assert not (tmp_path / "x").exists()


def test_the_cli_reports_a_bad_config_in_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.yml"
    bad.write_text(f"{TURNING}:\n  gamma: 5.0\n  policy: MlpPolicy\n")
    code = main(["sweep", "--env", TURNING, "--out", str(tmp_path / "o"), "--config", str(bad)])
    assert code == 2
    err = capsys.readouterr().err
    assert "machining-bench sweep:" in err and "gamma" in err
