"""``machining-bench`` checks its arguments and output paths before doing any work: a bad
one fails in one line on stderr, exit status 2, with nothing left behind."""

from __future__ import annotations

import json
import shlex
import shutil
import socket
import time
from pathlib import Path

import pytest

from agents.bench.cli import main
from agents.rl.policy import PRETRAINED_DIR

TURNING = "machining_envs/Turning-v0"
ENDMILLING = "machining_envs/EndMilling-v0"
#: A folder nobody may write in, whoever runs the tests (root included).
UNWRITABLE = Path("/sys/machining_bench_out")


def _one_line(capsys, *words) -> str:
    captured = capsys.readouterr()
    err = captured.err
    assert err.count("\n") == 1 and err.startswith("machining-bench "), err
    for w in words:
        assert w in err, (w, err)
    return err


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.stat().st_mtime_ns for p in folder.rglob("*")}


@pytest.fixture
def blocker(tmp_path):
    """A file where a folder would go."""
    path = tmp_path / "file"
    path.write_text("not a folder\n")
    return path


@pytest.fixture
def run(tmp_path):
    """A copy of the shipped Turning policy's run folder."""
    src, dst = PRETRAINED_DIR / "turning_ppo", tmp_path / "run"
    dst.mkdir()
    for name in ("best_model.zip", "best_vecnormalize.json", "config.json"):
        shutil.copy(src / name, dst / name)
    return dst


# ---- tune --------------------------------------------------------------------------------------
def test_tune_refuses_a_json_list_as_out(tmp_path, capsys):
    out = tmp_path / "list.json"
    out.write_text("[1, 2]\n")
    assert main(["tune", "--env", TURNING, "--trials", "1", "--out", str(out)]) == 2
    _one_line(capsys, "not a tuned-settings file")
    assert out.read_text() == "[1, 2]\n"


def test_tune_refuses_an_out_under_a_file_or_a_folder(tmp_path, blocker, capsys):
    before = _snapshot(tmp_path)
    assert main(["tune", "--trials", "1", "--out", str(blocker / "t.json")]) == 2
    _one_line(capsys, "is under", "a file")
    assert main(["tune", "--trials", "1", "--out", str(tmp_path)]) == 2
    _one_line(capsys, "is a folder, not a file")
    assert main(["tune", "--trials", "1", "--out", str(UNWRITABLE / "t.json")]) == 2
    _one_line(capsys, "cannot write")
    with pytest.raises(SystemExit) as exit_:  # argparse's own error, exit 2
        main(["tune", "--trials", "0", "--out", str(tmp_path / "t.json")])
    assert exit_.value.code == 2
    assert "--trials: must be >= 1" in capsys.readouterr().err
    assert _snapshot(tmp_path) == before


def test_tune_shows_a_progress_bar_and_writes_a_new_out(tmp_path, capsys):
    pytest.importorskip("optuna")
    out = tmp_path / "tuned.json"
    assert (
        main(["tune", "--env", TURNING, "--trials", "2", "--episodes", "1", "--out", str(out)]) == 0
    )
    err = capsys.readouterr().err
    assert "2/2" in err and "Best value" in err  # Optuna's bar, one an agent
    assert set(json.loads(out.read_text())["envs"]) == {TURNING}


# ---- sweep -------------------------------------------------------------------------------------
def test_sweep_refuses_an_out_under_a_file(tmp_path, blocker, capsys):
    pytest.importorskip("ray")
    before = _snapshot(tmp_path)
    assert main(["sweep", "--env", TURNING, "--out", str(blocker / "s")]) == 2
    _one_line(capsys, "is under", "a file")
    assert main(["sweep", "--env", TURNING, "--out", str(UNWRITABLE)]) == 2
    _one_line(capsys, "cannot write")
    assert main(["sweep", "--env", "nope/Nope-v0", "--out", str(tmp_path / "s")]) == 2
    _one_line(capsys, "unknown env id")
    assert _snapshot(tmp_path) == before


def test_sweep_fails_at_once_where_no_ray_cluster_listens(tmp_path, capsys):
    pytest.importorskip("ray")
    import ray

    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "sweep"
    t0 = time.perf_counter()
    for address in (f"127.0.0.1:{port}", f"ray://127.0.0.1:{port}", "nonsense"):
        assert main(["sweep", "--env", TURNING, "--out", str(out), "--address", address]) == 2
        _one_line(capsys, "--address")
    assert time.perf_counter() - t0 < 30
    assert not out.exists() and not ray.is_initialized()


def test_sweep_gate_trains_the_seeds_under_the_gate(tmp_path, monkeypatch, capsys):
    """``sweep --gate`` hands the sweep's own settings to ``gated_sweep`` (and refuses a
    search or a resume, which a gated sweep does not do)."""
    pytest.importorskip("ray")
    import agents.rl.gate
    from agents.rl.sweep import SweepSettings

    out = tmp_path / "s"
    for extra in (["--search", "3"], ["--resume"]):
        assert main(["sweep", "--env", TURNING, "--out", str(out), "--gate", *extra]) == 2
        _one_line(capsys, "--gate")
    calls = []

    def gated_sweep(settings, folder, **kwargs):
        calls.append((settings, folder, kwargs))
        return {"passed": [0, 1], "failed": [], "replacements": [], "complete": True}

    monkeypatch.setattr(agents.rl.gate, "gated_sweep", gated_sweep)
    argv = ["sweep", "--env", TURNING, "--out", str(out), "--gate", "--seeds", "0", "1"]
    argv += ["--timesteps", "512", "--workers", "1", "--vec", "dummy", "--no-progress"]
    assert main(argv) == 0
    settings = SweepSettings(TURNING, seeds=[0, 1], n_timesteps=512, workers=1, vec="dummy")
    assert calls == [
        (settings, str(out), {"command": shlex.join(["machining-bench", *argv]), "progress": False})
    ]
    assert "passed [0, 1]" in capsys.readouterr().out
    assert not out.exists()


# ---- export ------------------------------------------------------------------------------------
def test_export_onnx_refuses_an_unknown_env_or_a_wrong_algo(run, capsys):
    pytest.importorskip("onnxruntime")
    model = str(run / "best_model.zip")
    before = _snapshot(run)
    assert main(["export", "--onnx", "--model", model, "--env", "nope/Nope-v0"]) == 2
    _one_line(capsys, "unknown env id", "nope/Nope-v0")
    assert main(["export", "--onnx", "--model", model, "--algo", "sac"]) == 2
    _one_line(capsys, "--algo sac", "is a ppo model")
    (run / "config.json").unlink()  # the zip's policy class tells the algorithm then
    before = _snapshot(run)
    args = ["export", "--onnx", "--model", model, "--env", TURNING, "--algo", "td3"]
    assert main(args) == 2
    _one_line(capsys, "--algo td3", "is a ppo model")
    assert _snapshot(run) == before


def test_export_onnx_refuses_another_env_of_the_same_shape_unless_forced(run, capsys):
    """EndMilling-v0's observations have Turning-v0's shape (7,): the export would run and
    "check" the policy on the wrong plant; as evaluate, it refuses unless --force."""
    pytest.importorskip("onnxruntime")
    model = str(run / "best_model.zip")
    before = _snapshot(run)
    assert main(["export", "--onnx", "--model", model, "--env", ENDMILLING]) == 2
    _one_line(capsys, f"trained on {TURNING}, not {ENDMILLING}", "--force")
    assert _snapshot(run) == before
    args = ["export", "--onnx", "--model", model, "--env", ENDMILLING, "--force"]
    assert main([*args, "--out", str(run / "forced.onnx")]) == 0
    assert (run / "forced.onnx").stat().st_size > 0


def test_export_onnx_refuses_unwritable_outs(run, blocker, capsys):
    pytest.importorskip("onnxruntime")
    model = str(run / "best_model.zip")
    for out, words in (
        (blocker / "p.onnx", ("is under", "a file")),
        (run, ("is a folder, not a file",)),
        (UNWRITABLE / "p.onnx", ("cannot write",)),
    ):
        assert main(["export", "--onnx", "--model", model, "--out", str(out)]) == 2
        _one_line(capsys, *words)


def test_export_zoo_writes_all_or_nothing(run, tmp_path, capsys):
    pytest.importorskip("yaml")
    model = str(run / "best_model.zip")
    (run / "best_vecnormalize.json").write_text("{ damaged")
    out = tmp_path / "zoo"
    assert main(["export", "--zoo", "--model", model, "--out", str(out)]) == 2
    _one_line(capsys, "machining-bench export:")
    assert not out.exists()  # no half-written folder, nor the folders above it
    shutil.copy(PRETRAINED_DIR / "turning_ppo" / "best_vecnormalize.json", run)
    assert main(["export", "--zoo", "--model", model, "--out", str(out)]) == 0
    capsys.readouterr()
    exp = out / "ppo" / "machining_envs-Turning-v0_1"
    assert sorted(p.name for p in exp.iterdir()) == [
        "best_model.zip",
        "machining_envs-Turning-v0",
        "machining_envs-Turning-v0.zip",
    ]
    before = _snapshot(out)
    assert main(["export", "--zoo", "--model", model, "--out", str(out)]) == 2
    _one_line(capsys, "exists already")
    assert _snapshot(out) == before
    assert (
        main(
            ["export", "--zoo", "--model", model, "--out", str(tmp_path / "x"), "--env", ENDMILLING]
        )
        == 2
    )
    _one_line(capsys, "--zoo takes")
    assert main(["export", "--zoo", "--model", model, "--out", str(UNWRITABLE)]) == 2
    _one_line(capsys, "cannot write")


def test_export_zoo_writes_the_files_rl_zoo3_reads(run, tmp_path, capsys):
    """config.yml, args.yml (whose env_kwargs rl_zoo3.enjoy reads), env_kwargs.yml (what
    rl-zoo3's hub pages hold) and the statistics, as the README says."""
    yaml = pytest.importorskip("yaml")
    assert (
        main(
            [
                "export",
                "--zoo",
                "--model",
                str(run / "best_model.zip"),
                "--out",
                str(tmp_path / "zoo"),
            ]
        )
        == 0
    )
    assert "--no-render" in capsys.readouterr().out
    params = tmp_path / "zoo" / "ppo" / "machining_envs-Turning-v0_1" / "machining_envs-Turning-v0"
    names = sorted(p.name for p in params.iterdir())
    assert names == ["args.yml", "config.yml", "env_kwargs.yml", "vecnormalize.pkl"]
    config = json.loads((run / "config.json").read_text())
    args = yaml.safe_load((params / "args.yml").read_text())
    assert args["env"] == TURNING and args["algo"] == "ppo"
    assert args["gym_packages"] == ["machining_envs"]
    kwargs = config["config"].get("env_kwargs", {})
    assert args["env_kwargs"] == (kwargs or None)
    assert yaml.safe_load((params / "env_kwargs.yml").read_text()) == kwargs
    assert yaml.safe_load((params / "config.yml").read_text())["env_kwargs"] == kwargs


# ---- benchmark ---------------------------------------------------------------------------------
def test_benchmark_refuses_an_unwritable_out(tmp_path, blocker, capsys):
    assert main(["benchmark", "--quick", "--out", str(UNWRITABLE)]) == 2
    _one_line(capsys, "cannot write", str(UNWRITABLE))
    assert main(["benchmark", "--quick", "--out", str(blocker / "r")]) == 2
    _one_line(capsys, "is under", "a file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


# ---- evaluate and the rest -----------------------------------------------------------------------
def test_evaluate_and_train_refuse_bad_paths_before_any_work(run, tmp_path, blocker, capsys):
    model = str(run / "best_model.zip")
    assert main(["evaluate", "--model", model, "--env", TURNING, "--algo", "sac"]) == 2
    _one_line(capsys, "is a ppo model")
    assert main(["evaluate", "--model", model, "--env", TURNING, "--stats", "nope.json"]) == 2
    _one_line(capsys, "--stats")
    assert main(["train", "--env", TURNING, "--out", str(blocker / "run")]) == 2
    _one_line(capsys, "is under", "a file")
    assert main(["train", "--env", TURNING, "--out", str(run)]) == 2
    _one_line(capsys, "is not empty", "--resume")
    assert main(["train", "--env", "nope/Nope-v0", "--out", str(tmp_path / "r")]) == 2
    _one_line(capsys, "unknown env id")
    assert main(["reproduce", "milling", "--sensor-gain", "2"]) == 2
    _one_line(capsys, "--sensor-gain applies to 'reproduce turning' only")
    assert main(["synthesize", "--out", str(UNWRITABLE / "designs.json")]) == 2
    _one_line(capsys, "cannot write")
    assert main(["warmup", "--env", "nope/Nope-v0"]) == 2
    _one_line(capsys, "unknown env id")
    assert not (tmp_path / "r").exists()
