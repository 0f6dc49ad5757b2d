"""``machining-bench``: the quick benchmark writes its report; bad arguments are refused."""

import subprocess
import sys

import pytest

from agents.bench.cli import main


def test_cli_benchmark_quick_writes_report(tmp_path):
    """``make demo``'s run, with its envs two at a time (``--jobs 2``): the suite's longest
    test, 196 s with one env at a time on a slow 2-core machine, 143 s so."""
    cmd = ["benchmark", "--quick", "--jobs", "2", "--out", str(tmp_path)]
    out = subprocess.run(
        [sys.executable, "-m", "agents.bench.cli", *cmd],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "| agent | kind |" in out.stdout
    assert "| physical bound | bound |" in out.stdout
    assert "| tuned |" in out.stdout and "| reference |" in out.stdout  # the verdict column
    assert "Δ at 0.5 %" in out.stdout and "| worse |" in out.stdout
    assert "time: " in out.stdout and "total" in out.stdout  # the run prints its times
    for env in ("Turning-v0", "EndMilling-v0", "MicroDrilling-v0", "ContouringFeed-v0"):
        assert f"{env}: 100%" in out.stderr, env  # a progress bar per env, run to its end
    for name in (
        "benchmark.csv",
        "report.md",
        "Turning-v0_scores.png",
        "Turning-v0_profiles.png",
        "Turning-v0_trajectories.png",
        "reproduce_turning.png",
    ):
        assert (tmp_path / name).stat().st_size > 0, name


def test_cli_rejects_bad_arguments():
    with pytest.raises(SystemExit):
        main(["reproduce", "grinding"])
    with pytest.raises(SystemExit):
        main(["reproduce", "turning", "--sensor-gain", "-3"])


@pytest.mark.parametrize(
    "command",
    [
        ["benchmark", "--quick"],
        ["reproduce", "turning"],
        ["train", "--env", "x", "--out", "y"],
        ["evaluate", "--model", "m", "--env", "x"],
    ],
)
def test_a_negative_seed_is_refused_before_anything_runs(command, capsys):
    # The benchmark ran its first env and then failed in numpy ("Seed must be between 0
    # and 2**32 - 1"); reproduce failed in gymnasium.
    with pytest.raises(SystemExit) as exit_:
        main([*command, "--seed", "-1"])
    assert exit_.value.code == 2
    assert "--seed: must be in [0, 2**32), got -1" in capsys.readouterr().err


def test_cli_help_shows_defaults_and_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.startswith("machining-bench ")
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    text = capsys.readouterr().out
    assert (
        "(default: ['validation'])" in text
        and "(default: None)" not in text
        and "--force" in text
        and "--stats" in text
    )
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    assert "``" not in text and "convert-stats" in text


def test_cli_user_errors_are_one_line_with_exit_2(tmp_path, capsys):
    model = "agents/rl/pretrained/turning_ppo/best_model.zip"
    # A model evaluated on another env than it was trained on, without --force.
    assert main(["evaluate", "--model", model, "--env", "machining_envs/EndMilling-v0"]) == 2
    err = capsys.readouterr().err
    assert "trained on machining_envs/Turning-v0" in err and "--force" in err
    assert err.count("\n") == 1
    assert main(["evaluate", "--model", str(tmp_path / "no.zip"), "--env", "x"]) == 2
    assert "no model" in capsys.readouterr().err
    assert main(["evaluate", "--model", model, "--env", "machining_envs/Nope-v0"]) == 2
    assert "unknown env id" in capsys.readouterr().err
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["benchmark", "--quick", "--out", str(blocker)]) == 2
    assert "machining-bench benchmark:" in capsys.readouterr().err
    # An id the benchmark does not know (it ran nothing and then failed on an empty table).
    out = tmp_path / "bench"
    assert main(["benchmark", "--quick", "--env", "nope", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "envs (--env) must be ids among" in err and "['nope']" in err
    assert err.count("\n") == 1 and not out.exists()
    from agents.bench.benchmark import run_benchmark

    with pytest.raises(ValueError, match=r"seed must be an integer in \[0, 2\*\*32\)"):
        run_benchmark(out, quick=True, seed=-1)
    assert not out.exists()
    assert main(["convert-stats", str(blocker)]) == 2
    assert "convert-stats" in capsys.readouterr().err


def test_cli_evaluates_a_model_trained_elsewhere(tmp_path, capsys):
    """A model without its run folder: --algo and --stats give what config.json would."""
    import shutil

    src = "agents/rl/pretrained/turning_ppo"
    shutil.copy(f"{src}/best_model.zip", tmp_path / "policy.zip")
    shutil.copy(f"{src}/best_vecnormalize.json", tmp_path / "norm.json")
    args = ["evaluate", "--model", str(tmp_path / "policy.zip"), "--env"]
    args += ["machining_envs/Turning-v0", "--scenarios", "paper_700", "--episodes", "1"]
    assert main(args) == 2  # no config.json, no algorithm in the file name
    assert "algo" in capsys.readouterr().err
    assert main([*args, "--algo", "ppo", "--stats", str(tmp_path / "norm.json")]) == 0
    assert "primary score" in capsys.readouterr().out


def test_plots_and_renders_leave_the_users_matplotlib_backend_alone(tmp_path):
    """The library draws on its own Agg canvases: a notebook's backend (here svg) is not
    switched, and no pyplot figure is left open."""
    code = f"""
import matplotlib
matplotlib.use("svg")
import gymnasium as gym
import machining_envs
from agents.bench.benchmark import run_benchmark
env = gym.make("machining_envs/Turning-v0", render_mode="rgb_array")
env.reset(seed=0)
env.step(env.action_space.sample())
assert env.render().ndim == 3
run_benchmark({str(tmp_path)!r}, quick=True, envs=["machining_envs/Turning-v0"],
              reproductions=False, verbose=False)
import matplotlib.pyplot as plt
assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
assert plt.get_fignums() == []
"""
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    assert (tmp_path / "Turning-v0_trajectories.png").stat().st_size > 0
    # The quick report: the allowance columns, the verdict column, each learned row's worst
    # seed, the oracle beside the bound on its own episodes; results.md one number a cell.
    report = (tmp_path / "report.md").read_text()
    for text in (
        "Δ at 0.5 %",
        "Δ at 1 %",
        "Δ at 2 %",
        "verdict vs",
        "worst seed counts",
        "physical bound, on the oracle's 1 ep.",
        "| reference |",
    ):
        assert text in report, text
    assert (tmp_path / "Turning-v0_allowances.png").stat().st_size > 0
    assert "| verdict |" in (tmp_path / "results.md").read_text()


def test_evaluate_force_runs_a_model_on_another_env_of_the_same_spaces(capsys):
    """--force is passed down to the loader (which refuses a model of another env without it)."""
    model = "agents/rl/pretrained/turning_ppo/best_model.zip"
    args = [
        "evaluate",
        "--model",
        model,
        "--env",
        "machining_envs/EndMilling-v0",
        "--force",
        "--episodes",
        "1",
    ]
    assert main(args) == 0
    assert "primary score" in capsys.readouterr().out
