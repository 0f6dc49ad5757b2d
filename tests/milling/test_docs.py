"""The quickstart of docs/milling.md runs as written and prints what the page says."""

import re
from pathlib import Path

DOC = Path(__file__).resolve().parents[2] / "docs" / "milling.md"


def test_milling_quickstart_runs(capsys):
    code = re.search(r"```python\n(.*?)```", DOC.read_text(), re.S).group(1)
    exec(compile(code, "docs/milling.md quickstart", "exec"), {})
    out = capsys.readouterr().out
    assert "step workpiece: 3.14 min, MRR 815 mm3/min" in out
