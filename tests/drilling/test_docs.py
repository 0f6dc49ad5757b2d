"""docs/drilling.md: its example runs as written and prints what the text says."""

import re
from pathlib import Path

DOC = Path(__file__).resolve().parents[2] / "docs" / "drilling.md"


def test_docs_example_runs(capsys):
    code = re.search(r"```python\n(.*?)```", DOC.read_text(), re.S).group(1)
    exec(compile(code, "docs/drilling.md", "exec"), {})
    value = float(capsys.readouterr().out.strip())
    assert 1.0 < value < 1.06  # "about 1.03"
