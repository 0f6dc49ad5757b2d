"""Every notebook runs top to bottom (small budgets through MACHINING_NB_QUICK=1)."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


def test_notebooks_exist():
    assert len(NOTEBOOKS) >= 5


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_executes(path, tmp_path, monkeypatch):
    monkeypatch.setenv("MACHINING_NB_QUICK", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()
    errors = [
        o
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.get("outputs", [])
        if o.output_type == "error"
    ]
    assert not errors


def test_notebooks_are_what_make_notebooks_writes():
    """The .ipynb files are generated: editing ``make_notebooks.py`` without running it
    would leave the tested notebooks behind their sources."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "make_notebooks", NOTEBOOKS[0].parent / "make_notebooks.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert sorted(mod.NOTEBOOKS) == [p.name for p in NOTEBOOKS]
    for path in NOTEBOOKS:
        written = [(c.cell_type, c.source) for c in nbformat.read(path, as_version=4).cells]
        sources = [(c.cell_type, c.source) for c in mod.NOTEBOOKS[path.name]]
        assert written == sources, f"{path.name}: run python notebooks/make_notebooks.py"


def _outputs(path):
    nb = nbformat.read(path, as_version=4)
    return nb, [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_stored_notebooks_hold_their_outputs(path):
    """The notebooks read without running (``make_notebooks.py --execute`` stores their
    outputs): every code cell ran, none failed, and no output shows a scratch folder."""
    nb, outputs = _outputs(path)
    assert all(c.get("execution_count") for c in nb.cells if c.cell_type == "code"), path.name
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(
        o.get("text", "")
        + o.get("data", {}).get("text/markdown", "")
        + o.get("data", {}).get("text/plain", "")
        for o in outputs
    )
    assert "/tmp" not in text and "ipywidgets" not in text
    assert any("image/png" in o.get("data", {}) for o in outputs), "no plot"


def test_the_benchmark_and_training_notebooks_show_tables_and_plots():
    """03 shows the report's tables as Markdown and its plots inline; 02 a learning curve
    and its results as a table."""
    for name, plots in (("03_benchmark.ipynb", 3), ("02_train_sb3.ipynb", 1)):
        _, outputs = _outputs(NOTEBOOKS[0].parent / name)
        tables = [
            o["data"]["text/markdown"] for o in outputs if "text/markdown" in o.get("data", {})
        ]
        assert any("|---|" in t for t in tables), name
        assert sum("image/png" in o.get("data", {}) for o in outputs) >= plots, name
        assert not [o for o in outputs if o.output_type == "stream" and "| agent |" in o.text]
