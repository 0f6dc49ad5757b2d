"""Writes the notebooks of this folder from the cell sources below (run it after editing),
and executes them with their outputs stored, so that they read without running.

    python notebooks/make_notebooks.py             # write the notebooks whose cells changed
    python notebooks/make_notebooks.py --execute   # ... and run every notebook, storing outputs
    python notebooks/make_notebooks.py --execute 03_benchmark.ipynb

Keeping the sources here keeps the notebooks reviewable as code; a notebook whose cells are
unchanged keeps its stored outputs. The tests execute the notebooks top to bottom with small
budgets: each reads ``MACHINING_NB_QUICK`` (set by the tests) to shrink them. Executing
needs the ``notebooks`` extra (Jupyter's kernel and ipywidgets).
"""

import argparse
import tempfile
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent
QUICK = (
    "import os\n\n"
    'QUICK = os.environ.get("MACHINING_NB_QUICK") == "1"  # small budgets under the tests'
)

NOTEBOOKS = {
    "01_quickstart.ipynb": [
        new_markdown_cell(
            "# Quickstart\n\nMake the turning env, run the paper's adaptive PI on the stepped bar, "
            "and plot force, feed and depth of cut."
        ),
        new_code_cell(
            "import gymnasium as gym\nimport matplotlib.pyplot as plt\n\n"
            "import machining_envs  # noqa: F401  (registers the env ids)\n"
            "from agents import ConstantFeed, VariableGainPI\nfrom agents.eval import rollout"
        ),
        new_code_cell(
            'env = gym.make("machining_envs/Turning-v0", scenario="paper_405")\n'
            "print(env.observation_space, env.action_space)\n"
            "agents = [VariableGainPI.from_env(env), ConstantFeed.from_env(env)]\n"
            "trajs = {a.name: rollout(a, env, seed=0) for a in agents}\n"
            "for name, tr in trajs.items():\n"
            '    broke = bool(tr["breakage"].any())\n'
            "    print(f\"{name}: cut in {tr['machining_time_s'][-1]:.1f} s, broke: {broke}\")"
        ),
        new_markdown_cell(
            "Force, feed and depth of cut over the bar: the adaptive PI holds the force at its "
            "1000 N reference through every step of depth, where the constant feed, set for the "
            "deepest step, wastes time on the shallow ones."
        ),
        new_code_cell(
            "fig, ax = plt.subplots(3, 1, figsize=(8, 6), sharex=True)\n"
            "for name, tr in trajs.items():\n"
            '    ax[0].plot(tr["t_s"], tr["force_N"], label=name)\n'
            '    ax[1].plot(tr["t_s"], tr["feed_mm_per_rev"])\n'
            '    ax[2].plot(tr["t_s"], tr["depth_mm"])\n'
            'ax[0].axhline(1000, color="k", ls="--")\n'
            'ax[0].set_ylabel("force (N)")\n'
            'ax[1].set_ylabel("feed (mm/rev)")\n'
            'ax[2].set(xlabel="time (s)", ylabel="depth (mm)")\n'
            "ax[0].legend()\n"
            "plt.show()"
        ),
    ],
    "02_train_sb3.ipynb": [
        new_markdown_cell(
            "# Train a feed-rate policy with Stable-Baselines3\n\nPPO with the hyperparameters of "
            "`agents/rl/configs/ppo.yml`, VecNormalize kept with the model, evaluated on the held-out "
            "scenarios by the same harness as the classical controllers.\n\n"
            "**Budget.** This run trains 100 000 steps (a few minutes on one CPU core; 2 000 "
            "under the tests, `MACHINING_NB_QUICK=1`). The shipped policy "
            "(`agents/rl/pretrained/turning_ppo`) trained 400 000 steps a seed: its five seeds' "
            "learning curves are drawn beside this run's."
        ),
        new_code_cell(QUICK),
        new_code_cell(
            "import tempfile\nfrom pathlib import Path\n\n"
            "from agents.rl import train\n\n"
            'out = Path(tempfile.mkdtemp()) / "ppo_turning"\n'
            "run = train(\n"
            '    "machining_envs/Turning-v0",\n'
            '    "ppo",\n'
            "    out,\n"
            "    seed=0,\n"
            "    n_timesteps=2_000 if QUICK else 100_000,\n"
            "    progress_bar=False,\n"
            "    verbose=False,\n"
            ")"
        ),
        new_markdown_cell(
            "## Learning curve\n\nThe run evaluates its policy on 10 `validation` episodes every "
            "25 000 steps (`eval.csv` in the run folder): the env's primary score, the mean "
            "machining time with every episode that breaks the tool, overloads it or does not "
            "finish charged the 200 s time limit (lower is better)."
        ),
        new_code_cell(
            "import csv\n\n"
            "import matplotlib.pyplot as plt\n\n"
            "from agents.rl.policy import PRETRAINED_DIR\n\n\n"
            "def curve(folder):\n"
            '    with open(folder / "eval.csv") as fh:\n'
            "        rows = list(csv.DictReader(fh))\n"
            '    return [int(r["timesteps"]) for r in rows], [float(r["score"]) for r in rows]\n\n\n'
            'shipped = PRETRAINED_DIR / "turning_ppo"\n'
            "fig, ax = plt.subplots(figsize=(8, 4))\n"
            'for k, folder in enumerate([shipped, *sorted(shipped.glob("seed_*"))]):\n'
            '    label = "shipped policy (5 seeds, 400 000 steps)" if k == 0 else None\n'
            '    ax.plot(*curve(folder), color="0.75", lw=1, label=label)\n'
            'ax.plot(*curve(run), "C0o-", label="this run")\n'
            'ax.axhline(200, color="k", ls=":", lw=0.8)\n'
            'ax.set(xlabel="training steps", ylabel="validation score (s)", title="PPO on Turning-v0")\n'
            "ax.legend()\n"
            "plt.show()"
        ),
        new_markdown_cell(
            "## Against the paper's adaptive PI\n\nThe same `validation` episodes for every agent "
            "(`test` is kept for the benchmark's final table)."
        ),
        new_code_cell(
            "from IPython.display import Markdown, display\n\n"
            "from agents import VariableGainPI\n"
            "from agents.eval import Evaluation, evaluate\n"
            "from agents.rl import load_policy, primary_score\n\n"
            "n = 2 if QUICK else 20\n"
            "agents = [\n"
            '    load_policy(run / "best_model.zip", name="PPO (this run)"),\n'
            '    load_policy(shipped / "best_model.zip", name="PPO (shipped, seed 0)"),\n'
            "    VariableGainPI.from_env,\n"
            "]\n"
            "evs = [\n"
            '    evaluate(a, "machining_envs/Turning-v0", ["validation"], n_episodes=n, seed=5000)\n'
            "    for a in agents\n"
            "]\n"
            'lines = ["| agent | score (s) | episodes that count |", "|---|---|---|"]\n'
            "for ev in evs:\n"
            "    s = primary_score(ev.rows)\n"
            "    lines.append(f\"| {ev.rows[0]['agent']} | {s['score']:.1f} | {s['valid']:.0%} |\")\n"
            'display(Markdown("\\n".join(lines)))\n'
            "metrics = [\"machining_time_s\", \"iae\", \"breakage\", \"finished\"]\n"
            "display(Markdown(Evaluation.concat(evs).to_markdown(metrics)))"
        ),
    ],
    "03_benchmark.ipynb": [
        new_markdown_cell(
            "# Benchmark\n\nEvery agent on the same fixed `test` episodes, paired by seed: the physical "
            "bound, the MPC oracle, the papers' controllers, the tuned ones and the shipped policies, "
            "with interquartile means and 95 % intervals (`machining-bench benchmark` does this for "
            "every env). `test` is the final table's split; tuning and training never touch it."
        ),
        new_markdown_cell(
            "The quick benchmark of Turning-v0 (`--quick`: 8 `test` episodes an agent, the "
            "oracle on one) writes its report (`report.md`: the score table, the margins, the "
            "plots); here it is shown as it reads, its tables as tables and its plots inline. "
            "The full run is `machining-bench benchmark`."
        ),
        new_code_cell(
            "import re\n"
            "import tempfile\n"
            "from pathlib import Path\n\n"
            "from IPython.display import Image, Markdown, display\n\n"
            "from agents.bench.benchmark import run_benchmark\n\n"
            "out = Path(tempfile.mkdtemp())\n"
            'ev = run_benchmark(out, quick=True, envs=["machining_envs/Turning-v0"], reproductions=False,\n'
            "                   verbose=False)\n"
            'report = (out / "report.md").read_text()\n'
            "# The report's text as Markdown; each plot it links (![...](file.png)) inline.\n"
            "for part in re.split(r\"!\\[[^\\]]*\\]\\(([^)]+\\.png)\\)\", report):\n"
            '    if part.endswith(".png"):\n'
            "        display(Image(filename=str(out / part)))\n"
            "    elif part.strip():\n"
            "        display(Markdown(part))"
        ),
    ],
    "04_reproduce_papers.ipynb": [
        new_markdown_cell(
            "# Reproducing the papers\n\nThe experiments of each process's source paper on the "
            "simulated plant, the paper's finding beside ours row by row, and the figure "
            "(`machining-bench reproduce <process>` runs one): turning, Noh, Kim & Kim (1992), "
            "Fig. 8-15, fixed-gain PI at three gains and three spindle speeds and the adaptive "
            "PI; then end milling, micro-drilling and two-axis contouring. A row that does not "
            "show the paper's behaviour says NO."
        ),
        new_code_cell(
            "from pathlib import Path\n\nfrom IPython.display import Image, Markdown, display\n\n"
            "from agents.bench.declarations import PROCESSES\n\n"
            'out = Path("results")  # where `machining-bench reproduce` writes its figures too\n'
            "for process in PROCESSES:\n"
            "    results = process.reproduce(out)\n"
            "    matched = sum(bool(r['match']) for r in results)\n"
            '    display(Markdown(f"### {process.name}: {matched}/{len(results)} checks show the paper\'s behaviour"))\n'
            '    display(Image(filename=str(out / f"reproduce_{process.name}.png")))'
        ),
    ],
    "05_identify_your_machine.ipynb": [
        new_markdown_cell(
            "# Identify your machine, then train on it\n\n"
            "Fit the end-milling plant of `machining_envs/EndMilling-v0` to a few test cuts and a "
            "feed-servo step logged on *your* machine, build the env on the fitted constants, run "
            "the classical integral ACC on it as a baseline, and train a PPO policy on it. "
            "Section 5 fits a lathe (`machining_envs/Turning-v0`) from a force log (CSV) and "
            "replays the logged cut on the fitted plant."
        ),
        new_code_cell(QUICK),
        new_markdown_cell(
            "## 1. Your machine's data\n\n"
            "**In real use these arrays come from your machine's log.** Here they are simulated "
            "from a made-up `true` machine whose constants differ from the nominal Park & Yoon "
            "(1986) set, so that the fit can be checked against the truth. Two records:\n\n"
            "- **test cuts**, one row per cut with the same tool, axial depth and spindle speed "
            "as in `MillingParams` (16 mm 4-tooth end mill, 32 mm, 400 rpm by default): radial "
            "depth `d` (mm), feed per tooth `ft` (mm/tooth) and the mean spindle torque over the "
            "cut (N·mm). Span the depths and feeds you will cut at; a grid lets the depth and "
            "feed exponents be fitted independently.\n"
            "- **servo step**: the feed velocity (mm/s), sampled at a constant rate (here "
            "100 Hz) from rest, after the feed command `U` (counts: the unit of the env's "
            "action, `0..command_max`) is stepped from 0 to `STEP` at `t = 0`."
        ),
        new_code_cell(
            "import dataclasses\n\n"
            "import matplotlib.pyplot as plt\n"
            "import numpy as np\n"
            "from scipy import signal\n\n"
            "from machining_envs.milling.plant import MillingParams\n\n"
            "nominal = MillingParams.park_yoon_1986()\n"
            "true = dataclasses.replace(  # your machine: unknown in real use, known here\n"
            "    nominal,\n"
            "    torque_coefficient_kgfmm=140.0,\n"
            "    depth_exponent=0.50,\n"
            "    feed_exponent=0.45,\n"
            "    servo_gain=0.024,\n"
            "    servo_natural_freq_hz=2.2,\n"
            "    servo_damping=0.55,\n"
            ")\n"
            "rng = np.random.default_rng(0)\n\n"
            "# Test cuts: radial depth (mm), feed per tooth (mm) -> mean torque (N·mm), 2 % scatter.\n"
            "d_mm, ft_mm = (g.ravel() for g in np.meshgrid([0.5, 1, 2, 3.5], [0.005, 0.01, 0.02, 0.04]))\n"
            "torque_Nmm = true.steady_torque_Nmm(d_mm, ft_mm) * (1 + 0.02 * rng.standard_normal(16))\n\n"
            "# Servo step: command 0 -> STEP counts at t = 0; feed velocity (mm/s) at 100 Hz, noisy.\n"
            "STEP = 50.0\n"
            "t_s = 0.01 * np.arange(300)\n"
            "wn = true.servo_natural_freq_rad_s\n"
            "servo_tf = ([true.servo_gain * wn**2], [1.0, 2 * true.servo_damping * wn, wn**2])\n"
            "vf_mm_s = STEP * signal.step(servo_tf, T=t_s)[1] + 0.024 * rng.standard_normal(t_s.size)\n"
            'print("  d (mm)  ft (mm)  torque (N·mm)")\n'
            "for row in np.column_stack([d_mm, ft_mm, torque_Nmm])[::5]:\n"
            '    print(f"{row[0]:8.2f} {row[1]:8.3f} {row[2]:14.0f}")\n'
            'print(f"... {d_mm.size} cuts; servo record of {t_s.size} samples")'
        ),
        new_markdown_cell(
            "## 2. Identify\n\n"
            "`fit_milling_torque` fits the torque law `T = Ks d^l ft^m D` by least squares in "
            "logarithms (Ks in kgf·mm as the paper gives it, D from `base`); `fit_servo_step` "
            "fits the gain, natural frequency and damping of the second-order feed servo to the "
            "step record. Giving the torque fit's parameter set as the servo fit's `base` "
            "collects both in one `MillingParams`. Every other constant (tool, spindle speed, "
            "sensor gain, reference torque, ...) keeps its nominal value: set those for your "
            "machine with `dataclasses.replace` before fitting.\n\n"
            "Ks is the torque extrapolated to `d = ft = 1 mm`, far outside the cuts, so its error "
            "trades off against the exponents'; what the env uses, the torque over the range cut, "
            "is compared with the true law in the printout."
        ),
        new_code_cell(
            "from machining_envs.identification import fit_milling_torque, fit_servo_step\n\n"
            "cuts = fit_milling_torque(d_mm, ft_mm, torque_Nmm, base=nominal)\n"
            "servo = fit_servo_step(t_s, vf_mm_s, step=STEP, base=cuts.params)\n"
            "fitted = servo.params\n"
            'print(f"torque law: R^2 {cuts.r_squared:.4f}, RMS error {cuts.rms_relative_error:.1%}")\n'
            'print(f"servo:      R^2 {servo.r_squared:.4f}, NRMSE {servo.nrmse:.1%}")\n'
            "law_error = fitted.steady_torque_Nmm(d_mm, ft_mm) / true.steady_torque_Nmm(d_mm, ft_mm) - 1\n"
            'print(f"fitted torque law within {abs(law_error).max():.1%} of the true one over the cuts\\n")\n'
            "print(f\"{'constant':<26}{'true':>8}{'fitted':>8}{'error':>8}\")\n"
            "for name in (\n"
            '    "torque_coefficient_kgfmm",\n'
            '    "depth_exponent",\n'
            '    "feed_exponent",\n'
            '    "servo_gain",\n'
            '    "servo_natural_freq_hz",\n'
            '    "servo_damping",\n'
            "):\n"
            "    a, b = getattr(true, name), getattr(fitted, name)\n"
            '    print(f"{name:<26}{a:>8.4g}{b:>8.4g}{b / a - 1:>+8.1%}")'
        ),
        new_code_cell(
            "fig, ax = plt.subplots(1, 2, figsize=(10, 4))\n"
            "f_grid = np.geomspace(ft_mm.min(), ft_mm.max(), 50)\n"
            "for i, depth in enumerate(np.unique(d_mm)):\n"
            "    sel = d_mm == depth\n"
            '    ax[0].loglog(ft_mm[sel], torque_Nmm[sel], "o", color=f"C{i}", label=f"d = {depth:g} mm")\n'
            '    ax[0].loglog(f_grid, fitted.steady_torque_Nmm(depth, f_grid), "-", color=f"C{i}")\n'
            'ax[0].set(xlabel="feed per tooth (mm)", ylabel="torque (N·mm)", title="test cuts and fit")\n'
            "ax[0].legend()\n"
            "w = servo.natural_freq_rad_s\n"
            "fit_tf = ([servo.gain * w**2], [1.0, 2 * servo.damping * w, w**2])\n"
            'ax[1].plot(t_s, vf_mm_s, ".", ms=3, label="measured")\n'
            'ax[1].plot(t_s, STEP * signal.step(fit_tf, T=t_s)[1], "k-", label="fit")\n'
            'ax[1].set(xlabel="time (s)", ylabel="feed velocity (mm/s)", title="servo step and fit")\n'
            "ax[1].legend()\n"
            "plt.show()"
        ),
        new_markdown_cell(
            "## 3. The env on your machine, and a classical baseline\n\n"
            "Any field of `MillingParams` is a keyword of `gym.make`, so the fitted plant is "
            "`params=fitted` or, equally, the fields that differ from the nominal set as "
            "overrides. The overrides are plain numbers, so they also fit in a training config "
            "(step 4). The integral ACC of Park & Yoon is designed from the env's nominal "
            "constants, now your fitted ones; it sets the baseline on `validation` scenarios "
            "(random workpieces, spindle speeds and torque limits, with the true Ks and m within "
            "±20 % of the fitted ones; `test` is kept for a final comparison)."
        ),
        new_code_cell(
            "import gymnasium as gym\n"
            "from IPython.display import Markdown, display\n\n"
            "from agents import IntegralACC\n"
            "from agents.eval import Evaluation, evaluate\n"
            "from machining_envs.milling.metrics import milling_metrics\n\n"
            'ENV_ID = "machining_envs/EndMilling-v0"\n'
            "machine = {\n"
            "    f.name: getattr(fitted, f.name)\n"
            "    for f in dataclasses.fields(fitted)\n"
            "    if getattr(fitted, f.name) != getattr(nominal, f.name)\n"
            "}\n"
            "env = gym.make(ENV_ID, **machine)\n"
            "assert env.unwrapped.params == gym.make(ENV_ID, params=fitted).unwrapped.params\n"
            "print(machine)\n\n"
            "n = 2 if QUICK else 20\n"
            "kw = dict(n_episodes=n, seed=5000, env_kwargs=machine, metrics_fn=milling_metrics)\n"
            'acc = evaluate(IntegralACC.from_env, ENV_ID, ["validation"], **kw)\n'
            'COLUMNS = ["machining_time_min", "iae", "oscillation", "time_over_limit", "breakage", "finished"]\n'
            "display(Markdown(acc.to_markdown(COLUMNS)))"
        ),
        new_markdown_cell(
            "## 4. Train a policy on it\n\n"
            "`agents.rl.train` reads its hyperparameters from a YAML file with one entry per "
            "env id (layout and checks in `agents/rl/config.py`). Here the notebook writes its own "
            "PPO entry, with the fitted constants in `env_kwargs`, into a temporary folder and "
            "trains there; the run keeps the model that scored best on held-out episodes, with "
            "its VecNormalize statistics, and `load_policy` loads both.\n\n"
            "The hyperparameters and reward are the shipped EndMilling-v0 entry of "
            "`agents/rl/configs/ppo.yml` (the one that trained `agents/rl/pretrained/end_milling_ppo`); "
            "only the plant constants and the budget change.\n\n"
            "**Budget.** Here PPO trains 100 000 steps (a few minutes on one CPU core), an "
            "eighth of the entry's own budget (800 000 steps, which trained the shipped "
            "policy; pass `n_timesteps=None` for it); under the tests (`MACHINING_NB_QUICK=1`) "
            "4 096, far too few to learn anything. Read the table, not this text, to see "
            "whether the policy matches the ACC on your machine."
        ),
        new_code_cell(
            "import tempfile\n"
            "from pathlib import Path\n\n"
            "import yaml\n\n"
            "from agents.rl import CONFIG_DIR, load_policy, primary_score, train\n\n"
            "folder = Path(tempfile.mkdtemp())\n"
            'entry = yaml.safe_load((CONFIG_DIR / "ppo.yml").read_text())[ENV_ID]\n'
            'entry["env_kwargs"] = {**entry["env_kwargs"], **machine}  # your plant\n'
            "if QUICK:\n"
            '    entry["eval_episodes"] = 2\n'
            '(folder / "ppo.yml").write_text(yaml.safe_dump({ENV_ID: entry}))\n'
            "run = train(\n"
            "    ENV_ID,\n"
            '    "ppo",\n'
            '    folder / "run",\n'
            "    seed=0,\n"
            '    config_path=folder / "ppo.yml",\n'
            "    n_timesteps=4_096 if QUICK else 100_000,  # None: the entry's own budget\n"
            "    progress_bar=False,\n"
            "    verbose=False,\n"
            ")"
        ),
        new_markdown_cell(
            "The trained policy beside the ACC on the same held-out episodes. The primary score "
            "is the mean machining time (s, lower is better) with every episode that breaks "
            "the tool, spends over 2 % of its time above 1.1x the reference torque or does not "
            "finish charged the env's time limit (1200 s); `valid` is the share of episodes "
            "that count. A policy that cuts faster by running over the torque limit does not win."
        ),
        new_code_cell(
            'policy = load_policy(run / "best_model.zip", name="PPO (your machine)")\n'
            'ev = Evaluation.concat([acc, evaluate(policy, ENV_ID, ["validation"], **kw)])\n'
            "display(Markdown(ev.to_markdown(COLUMNS)))\n"
            "limit = env.unwrapped.max_episode_time_s\n"
            'lines = ["| agent | score (s) | episodes that count |", "|---|---|---|"]\n'
            'for name in dict.fromkeys(r["agent"] for r in ev.rows):\n'
            '    s = primary_score([r for r in ev.rows if r["agent"] == name], limit)\n'
            "    lines.append(f\"| {name} | {s['score']:.1f} | {s['valid']:.0%} |\")\n"
            'display(Markdown("\\n".join(lines)))'
        ),
        new_markdown_cell(
            "To use your machine from another project, register it under an id of your own: "
            '`gym.register(id="mylab/MyMill-v0", '
            'entry_point="machining_envs.milling.env:EndMillingEnv", '
            'kwargs={"params": fitted})`, and pass `metrics_fn=milling_metrics` to `evaluate`.'
        ),
        new_markdown_cell(
            "## 5. A lathe from its force log\n\n"
            "A turning record is a CSV with one row per control period: `time_s`, the servo "
            "`command` (counts), the measured `force_N`, the `spindle_rpm` and the `depth_mm` "
            "of cut (a column, or one value for the whole record). `fit_turning_record` runs "
            "the commands through the servo and cutting lag of eq. (11), keeps the samples "
            "where the feed has settled and fits `F = Kf f^p a` to them; it reports R², 95 % "
            "intervals and a residual plot, and `fit.scenario()` replays the record's "
            "workpiece and spindle speed on the fitted plant.\n\n"
            "**In real use the CSV comes from your data logger.** Here a hidden lathe "
            "(Kf = 2400, p = 0.72, the env's nominal 1 % sensor noise) cuts a stepped bar "
            "under six open-loop feed levels, 1.5 s each, and writes the record."
        ),
        new_code_cell(
            "import csv\n"
            "import tempfile\n"
            "from pathlib import Path\n\n"
            "from machining_envs.core.workpieces import DepthProfile\n"
            "from machining_envs.identification import TURNING_RECORD_COLUMNS, fit_turning_record\n"
            "from machining_envs.turning import TurningParams\n"
            "from machining_envs.turning.scenarios import TurningScenario\n\n"
            "hidden = TurningParams().replace(force_coefficient=2400.0, feed_exponent=0.72)\n"
            'bar = TurningScenario("logged cut", DepthProfile.steps((1.0, 2.0, 1.5, 2.5), 15.0), 405.0)\n'
            "LEVELS = (-0.6, -0.3, -0.7, -0.45, -0.2, -0.55)  # actions, 1.5 s each\n\n\n"
            "def log_cut(params, scenario, seed):\n"
            '    lathe = gym.make("machining_envs/Turning-v0", params=params).unwrapped\n'
            '    obs, _ = lathe.reset(seed=seed, options={"scenario": scenario})\n'
            "    p, rows, k, done = lathe.params, [], 0, False\n"
            "    while not done:\n"
            "        a = LEVELS[(k // 15) % len(LEVELS)]\n"
            "        obs, _, term, trunc, info = lathe.step(np.array([a]))\n"
            "        u = (a + 1) / 2 * p.command_max\n"
            "        f = obs[0] * p.force_scale_N\n"
            '        rows.append((k * p.sample_time_s, u, f, scenario.spindle_rpm, info["depth_mm"]))\n'
            "        k, done = k + 1, term or trunc\n"
            "    return rows\n\n\n"
            'record = Path(tempfile.mkdtemp()) / "cut.csv"\n'
            'with open(record, "w", newline="") as fh:\n'
            "    csv.writer(fh).writerows([TURNING_RECORD_COLUMNS, *log_cut(hidden, bar, seed=1)])\n"
            "fit = fit_turning_record(record)\n"
            'for name, true in (("force_coefficient", 2400.0), ("feed_exponent", 0.72)):\n'
            "    lo, hi = fit.interval(name)\n"
            "    est = getattr(fit.params, name)\n"
            '    print(f"{name:<18} true {true:<7g} fitted {est:8.4g}   95 % [{lo:.4g}, {hi:.4g}]")\n'
            'print(f"R^2 {fit.fit.r_squared:.4f} on {fit.used.sum()} settled samples of {fit.used.size}")\n'
            "fit.plot()"
        ),
        new_markdown_cell(
            "The fitted lathe replays the logged workpiece: the same commands on "
            "`fit.scenario()` with `params=fit.params` give the logged forces back (a "
            "different noise draw)."
        ),
        new_code_cell(
            "replay_scenario = fit.scenario()\n"
            "print(replay_scenario.profile.start_depths_mm, replay_scenario.spindle_rpm, \"rpm\")\n"
            "logged = np.array([r[2] for r in log_cut(hidden, bar, seed=1)])\n"
            "replayed = np.array([r[2] for r in log_cut(fit.params, replay_scenario, seed=2)])\n"
            "n = min(logged.size, replayed.size)\n"
            "cutting = logged[:n] > 100.0\n"
            "err = np.median(np.abs(replayed[:n][cutting] / logged[:n][cutting] - 1))\n"
            'print(f"median relative difference while cutting: {err:.1%}")\n'
            "fig, ax = plt.subplots(figsize=(8, 3))\n"
            "t = 0.1 * np.arange(n)\n"
            'ax.plot(t, logged[:n], color="0.5", lw=0.8, label="logged (hidden lathe)")\n'
            'ax.plot(t, replayed[:n], "C0", lw=1.0, label="replayed on the fitted lathe")\n'
            'ax.set(xlabel="time (s)", ylabel="measured force (N)")\n'
            "ax.legend()\n"
            "plt.show()"
        ),
    ],
}


def _sources(nb) -> list[tuple[str, str]]:
    return [(c.cell_type, c.source) for c in nb.cells]


def write(name: str) -> bool:
    """Write notebook ``name`` from its cells unless the file holds them already (and with
    them its stored outputs); True if written."""
    cells = NOTEBOOKS[name]
    for i, cell in enumerate(cells):
        cell.id = f"cell-{i}"  # stable ids: rewriting an unchanged notebook changes nothing
    path = HERE / name
    if path.is_file() and _sources(nbformat.read(path, as_version=4)) == _sources_of(cells):
        return False
    nb = new_notebook(
        cells=cells,
        metadata={
            "kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}
        },
    )
    nbformat.write(nb, path)
    return True


def _sources_of(cells) -> list[tuple[str, str]]:
    return [(c.cell_type, c.source) for c in cells]


def execute(name: str, timeout_s: int = 3600) -> None:
    """Run notebook ``name`` top to bottom with its full budgets in a scratch folder and
    store its outputs in the file."""
    from nbclient import NotebookClient

    path = HERE / name
    nb = nbformat.read(path, as_version=4)
    with tempfile.TemporaryDirectory() as scratch:
        client = NotebookClient(
            nb, timeout=timeout_s, kernel_name="python3", resources={"metadata": {"path": scratch}}
        )
        client.execute()
    nbformat.write(nb, path)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--execute", nargs="*", metavar="NAME", default=None,
                    help="run these notebooks (default: all) and store their outputs")  # fmt: skip
    args = ap.parse_args(argv)
    for name in NOTEBOOKS:
        if write(name):
            print("wrote", name, "(without outputs: run with --execute)")
    if args.execute is not None:
        for name in args.execute or NOTEBOOKS:
            if name not in NOTEBOOKS:
                raise SystemExit(f"no notebook {name!r}; the notebooks: {list(NOTEBOOKS)}")
            print("executing", name, flush=True)
            execute(name)


if __name__ == "__main__":
    main()
