"""Writes the notebooks of this folder from the cell sources below (run it after editing).

Keeping the sources here keeps the notebooks reviewable as code; the tests execute the
written .ipynb files top to bottom. Each notebook reads ``MACHINING_NB_QUICK`` (set by the
tests) to shrink its budgets.
"""

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent
QUICK = "import os\nQUICK = os.environ.get('MACHINING_NB_QUICK') == '1'  # small budgets under the tests\n"

NOTEBOOKS = {
    "01_quickstart.ipynb": [
        new_markdown_cell(
            "# Quickstart\n\nMake the turning env, run the paper's adaptive PI on the stepped bar, "
            "and plot force, feed and depth of cut."
        ),
        new_code_cell(
            "import gymnasium as gym\nimport matplotlib.pyplot as plt\nimport numpy as np\n\n"
            "import machining_envs\nfrom agents import ConstantFeed, VariableGainPI\nfrom agents.harness import rollout"
        ),
        new_code_cell(
            'env = gym.make("machining_envs/Turning-v0", scenario="paper_405")\n'
            "print(env.observation_space, env.action_space)\n"
            "agents = [VariableGainPI.from_env(env), ConstantFeed.from_env(env)]\n"
            "trajs = {a.name: rollout(a, env, seed=0) for a in agents}\n"
            "for name, tr in trajs.items():\n"
            "    print(f\"{name}: cut in {tr['machining_time_s'][-1]:.1f} s, broke: {bool(tr['breakage'].any())}\")"
        ),
        new_code_cell(
            "fig, ax = plt.subplots(3, 1, figsize=(8, 6), sharex=True)\n"
            "for name, tr in trajs.items():\n"
            "    ax[0].plot(tr['t_s'], tr['force_N'], label=name)\n"
            "    ax[1].plot(tr['t_s'], tr['feed_mm_per_rev'])\n"
            "    ax[2].plot(tr['t_s'], tr['depth_mm'])\n"
            "ax[0].axhline(1000, color='k', ls='--')\n"
            "ax[0].set_ylabel('force (N)'); ax[1].set_ylabel('feed (mm/rev)'); ax[2].set_ylabel('depth (mm)')\n"
            "ax[2].set_xlabel('time (s)'); ax[0].legend(); plt.show()"
        ),
    ],
    "02_train_sb3.ipynb": [
        new_markdown_cell(
            "# Train a feed-rate policy with Stable-Baselines3\n\nPPO with the hyperparameters of "
            "`agents/configs/ppo.yml`, VecNormalize kept with the model, evaluated on the held-out "
            "scenarios by the same harness as the classical controllers."
        ),
        new_code_cell(QUICK),
        new_code_cell(
            "import tempfile\nfrom pathlib import Path\n\n"
            "from agents import VariableGainPI\nfrom agents.harness import evaluate\n"
            "from agents.rl import load_policy, primary_score, train\n\n"
            "out = Path(tempfile.mkdtemp()) / 'ppo_turning'\n"
            "run = train('machining_envs/Turning-v0', 'ppo', out, seed=0,\n"
            "            n_timesteps=2_000 if QUICK else 300_000, progress_bar=not QUICK)"
        ),
        new_code_cell(
            "n = 2 if QUICK else 20\n"
            "policy = load_policy(run / 'best_model.zip')\n"
            "for agent in (policy, VariableGainPI.from_env):\n"
            "    ev = evaluate(agent, 'machining_envs/Turning-v0', ['test'], n_episodes=n, seed=1000)\n"
            "    print(ev.rows[0]['agent'], primary_score(ev.rows))"
        ),
    ],
    "03_benchmark.ipynb": [
        new_markdown_cell(
            "# Benchmark\n\nEvery agent on the same held-out scenarios: one table, the same metrics."
        ),
        new_code_cell(QUICK),
        new_code_cell(
            "from agents import ConstantFeed, FixedGainPI, VariableGainPI\n"
            "from agents.harness import Evaluation, evaluate\n\n"
            "n = 2 if QUICK else 20\n"
            "ev = Evaluation.concat(\n"
            "    evaluate(f, 'machining_envs/Turning-v0', ['test'], n_episodes=n, seed=1000)\n"
            "    for f in (ConstantFeed.from_env, FixedGainPI.from_env, VariableGainPI.from_env)\n"
            ")\n"
            "print(ev.to_markdown(['machining_time_s', 'iae', 'itae', 'max_overshoot', 'time_over_limit', 'breakage']))"
        ),
    ],
    "04_reproduce_papers.ipynb": [
        new_markdown_cell(
            "# Reproducing the papers\n\nNoh, Kim & Kim (1992), Fig. 8-15: fixed-gain PI at three gains "
            "and three spindle speeds, and the adaptive PI."
        ),
        new_code_cell(
            "import tempfile\nfrom pathlib import Path\n\nfrom IPython.display import Image, display\n\n"
            "from agents.cli import REPRODUCTIONS, reproduction\n\n"
            "out = Path(tempfile.mkdtemp())\n"
            "for process in REPRODUCTIONS:\n"
            "    results = reproduction(process)(out)\n"
            "    display(Image(filename=str(out / f'reproduce_{process}.png')))"
        ),
    ],
}


def main() -> None:
    for name, cells in NOTEBOOKS.items():
        nb = new_notebook(
            cells=cells,
            metadata={
                "kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}
            },
        )
        nbformat.write(nb, HERE / name)
        print("wrote", name)


if __name__ == "__main__":
    main()
