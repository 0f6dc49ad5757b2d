"""The README is a manual: short, its first install line works from a clone, no dated
measurements or machine names, and its ten-line example near the top. (Its examples run in
tests/test_docs_snippets.py with every page's.)"""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_is_at_most_250_lines():
    assert len(README.read_text().splitlines()) <= 250


def test_the_first_install_line_installs_from_a_clone():
    """The package is not on PyPI: the first command is an install from the clone's root."""
    text = README.read_text()
    first = re.search(r"```bash\n(.*?)```", text, re.S).group(1).splitlines()[0]
    assert first.split("#")[0].split() == ["pip", "install", "-e", "."]
    assert "pip install machining-envs" not in text


def test_no_dated_measurements_or_machine_names():
    text = README.read_text()
    assert not re.search(r"\b20\d\d-\d\d-\d\d\b", text)
    for machine in ("EPYC", "Xeon", "AVX", "2-core", "16-core", "µs per", "steps/s"):
        assert machine not in text, machine


def test_the_example_is_near_the_top():
    text = README.read_text()
    head = text.splitlines()[:80]
    assert "```python" in head


def test_ci_runs_the_test_command():
    ci = (README.parent / ".ci" / "run").read_text()
    assert "make test" in ci
