"""Where the benchmark's figures go (``agents.bench.figures``)."""

from __future__ import annotations

from matplotlib.figure import Figure

from agents.bench.figures import reproduction_figure, save_figure


def _figure() -> Figure:
    fig = Figure()
    fig.subplots().plot([0.0, 1.0])
    return fig


def test_save_figure_makes_the_folder(tmp_path):
    path = save_figure(_figure(), tmp_path / "new" / "fig.png")
    assert path == tmp_path / "new" / "fig.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_reproduction_draws_its_figure_only_with_a_folder(tmp_path, capsys):
    drawn = []
    reproduction_figure(None, "r.png", drawn.append, verbose=True)
    assert drawn == [] and capsys.readouterr().out == ""
    reproduction_figure(tmp_path, "r.png", drawn.append, verbose=True)
    assert drawn == [tmp_path / "r.png"]
    assert capsys.readouterr().out == f"figure: {tmp_path / 'r.png'}\n"
    reproduction_figure(tmp_path, "r.png", drawn.append, verbose=False)
    assert capsys.readouterr().out == ""
