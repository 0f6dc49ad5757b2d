"""docs/vector.md: its examples run as written, in order, and print what the text says."""

import re
from pathlib import Path

import numpy as np

DOC = Path(__file__).resolve().parents[2] / "docs" / "vector.md"


def test_the_examples_run_and_print_what_the_text_says(capsys):
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert len(blocks) == 4
    namespace: dict = {}
    for i, code in enumerate(blocks):
        exec(compile(code, f"docs/vector.md, example {i + 1}", "exec"), namespace)
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0] == "(256,) ['train' 'train']"
    assert lines[1] == "[245. 700.]"
    # the DISABLED example reset the lanes that ended, and its info is masked to them
    np.testing.assert_array_equal(namespace["reset_info"]["_scenario"], namespace["done"])
