"""Every example in README.md and docs/*.md runs as written.

Each page's ```python blocks run in order in one namespace (a page is read top to bottom),
in a temporary folder. A block that cannot run in the test suite carries, on the line just
before its fence, a visible marker with the reason::

    <!-- docs-test: skip: needs a running Ray cluster -->
    <!-- docs-test: requires ray -->          (runs where the module imports, else skipped)

The ```bash blocks are checked without running them: every ``machining-bench`` line
parses with the CLI's own parser (lines with placeholders such as ``...`` or ``[--quick]``
only name a real subcommand), every ``make`` target exists in the Makefile, every
``python benchmarks/...`` script exists and every extra named in a ``pip install`` line
is one of pyproject.toml's.
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from agents.bench.run import installed

tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
MARKER = re.compile(r"<!--\s*docs-test:\s*(skip|requires)\s*:?\s*(.*?)\s*-->")
FENCE = re.compile(r"^```(\w*)\s*$")

#: What a page's examples must print, beyond running: text from the page's own comments.
PRINTS = {
    "README.md": ["limit 1000 N"],
    "docs/getting-started.md": ["cut in", "| adaptive PI K=0.5 | validation | 3 |"],
    "docs/turning.md": ["fixed PI Kh=0.02: force swings", "adaptive PI K=0.5: force swings"],
    "docs/identification.md": ["Kf = 18"],
    "docs/index.md": ["(7,) 3600.0"],
    "docs/milling.md": ["step workpiece: 3.14 min, MRR 815 mm3/min"],
    "docs/vector.md": ["(256,) ['train' 'train']", "[245. 700.]"],
}


def _drilling(namespace, text):
    value = float(text.strip().splitlines()[0])
    assert 1.0 < value < 1.06, value  # "about 1.03"


def _vector(namespace, text):
    # the DISABLED example reset the lanes that ended, and its info is masked to them
    np.testing.assert_array_equal(namespace["reset_info"]["_scenario"], namespace["done"])


#: Checks of a page's results beyond its printed text: (namespace, printed text).
CHECKS = {"docs/drilling.md": _drilling, "docs/vector.md": _vector}


@dataclass
class Block:
    page: str
    line: int
    lang: str
    code: str
    marker: tuple[str, str] | None


def blocks(path: Path) -> list[Block]:
    """The fenced blocks of a page, each with the marker on the line before its fence."""
    lines = path.read_text().splitlines()
    out, i = [], 0
    name = path.relative_to(ROOT).as_posix()
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        start = i
        i += 1
        body = []
        while i < len(lines) and lines[i].strip() != "```":
            body.append(lines[i])
            i += 1
        before = lines[start - 1] if start > 0 else ""
        mark = MARKER.search(before)
        marker = (mark.group(1), mark.group(2)) if mark else None
        out.append(Block(name, start + 1, m.group(1), "\n".join(body) + "\n", marker))
        i += 1
    return out


def _python_pages():
    return [p for p in PAGES if any(b.lang == "python" for b in blocks(p))]


@pytest.mark.parametrize("page", _python_pages(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_the_python_examples_run(page, tmp_path, monkeypatch):
    import gymnasium as gym

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    before = set(gym.registry)
    namespace: dict = {"__name__": "__docs__"}
    out = io.StringIO()
    ran = 0
    try:
        for block in blocks(page):
            if block.lang != "python":
                continue
            where = f"{block.page}, line {block.line}"
            if block.marker is not None:
                kind, what = block.marker
                if kind == "skip":
                    continue
                missing = [m for m in what.replace(",", " ").split() if not installed(m)]
                if missing:
                    continue
            with contextlib.redirect_stdout(out):
                exec(compile(block.code, where, "exec"), namespace)
            ran += 1
    finally:  # ids an example registers leave the registry as it was
        for key in set(gym.registry) - before:
            gym.registry.pop(key, None)
        for value in list(namespace.values()):
            if hasattr(value, "close") and hasattr(value, "step"):
                with contextlib.suppress(Exception):
                    value.close()
    assert ran > 0, f"{page.name}: every python block was skipped"
    text = out.getvalue()
    name = page.relative_to(ROOT).as_posix()
    for expected in PRINTS.get(name, []):
        assert expected in text, f"{page.name} should print {expected!r}; it printed:\n{text}"
    if name in CHECKS:
        CHECKS[name](namespace, text)


def test_every_opt_out_says_why_and_marks_a_block():
    for page in PAGES:
        lines = page.read_text().splitlines()
        for n, line in enumerate(lines):
            m = MARKER.search(line)
            if m is None:
                continue
            where = f"{page.name}:{n + 1}"
            assert n + 1 < len(lines) and FENCE.match(lines[n + 1]), (
                f"{where}: a docs-test marker must be the line just before a fence"
            )
            kind, what = m.groups()
            if kind == "skip":
                assert len(what.split()) >= 3, f"{where}: a skip must say why ({what!r})"
            else:
                assert what, f"{where}: requires names the modules"


def _shell_commands(text: str):
    """The commands of a bash block: continuation lines joined, comments dropped."""
    joined = re.sub(r"\\\n\s*", " ", text)
    for line in joined.splitlines():
        line = line.split(" #", 1)[0].strip()
        if line and not line.startswith("#"):
            yield line


def _bash_blocks():
    for page in PAGES:
        for block in blocks(page):
            if block.lang == "bash" and (block.marker is None or block.marker[0] != "skip"):
                yield block


def test_the_shell_commands_name_real_things():
    from agents.bench.cli import build_parser

    parser = build_parser()
    commands = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    makefile = (ROOT / "Makefile").read_text()
    targets = set(re.findall(r"^([\w-]+):", makefile, re.M))
    extras = set(
        tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    )
    checked = 0
    for block in _bash_blocks():
        for cmd in _shell_commands(block.code):
            where = f"{block.page}, block at line {block.line}: {cmd}"
            words = shlex.split(cmd)
            if words[0] == "machining-bench":
                args = words[1:]
                placeholder = any(
                    w == "..." or w.startswith(("[", "<")) or "|" in w or "ID" == w for w in args
                )
                if placeholder or not args:
                    assert not args or args[0] in commands.choices or args[0] == "--help", where
                else:
                    with contextlib.redirect_stderr(io.StringIO()) as err:
                        try:
                            parser.parse_args(args)
                        except SystemExit as stop:
                            assert stop.code == 0, f"{where}\n{err.getvalue()}"
                checked += 1
            elif words[0] == "make":
                assert all(t in targets for t in words[1:] if not t.startswith("-")), where
                checked += 1
            elif words[0] == "python" and len(words) > 1 and words[1].startswith("benchmarks/"):
                assert (ROOT / words[1]).exists(), where
                checked += 1
            elif words[:2] == ["pip", "install"]:
                for spec in words[2:]:
                    m = re.search(r"\[([\w,-]+)\]", spec)
                    if m and ("machining" in spec or spec.startswith((".", "dist/"))):
                        named = set(m.group(1).split(","))
                        assert named <= extras, f"{where}: unknown extras {named - extras}"
                checked += 1
    assert checked > 10


def test_the_pages_name_no_missing_file():
    """Paths in backticks that look like the repository's files exist (a renamed module or
    script shows up here before a reader finds it)."""
    for page in PAGES:
        text = page.read_text()
        for path in set(
            re.findall(
                r"`((?:agents|machining_envs|benchmarks|tests|notebooks)/[\w/.-]+\.(?:py|yml|json|ipynb))`",
                text,
            )
        ):
            if "grinding" in path:  # the architecture page's example of a new process
                continue
            assert (ROOT / path).exists() or any(ROOT.glob(path)), f"{page.name}: {path}"


def test_the_machine_files_load(tmp_path):
    """Every ```yaml block of the pages that describes a machine (it starts with its
    ``name:``) is one ``machining_envs.core.machine.load_machine`` reads (the files users
    copy for ``tune --machine`` / ``train --machine``), as is the shipped docs/my_cnc.yml."""
    from machining_envs.core.machine import load_machine

    found = [ROOT / "docs" / "my_cnc.yml"]
    for page in PAGES:
        machines = (x for x in blocks(page) if x.lang == "yaml" and x.code.startswith("name:"))
        for i, b in enumerate(machines):
            path = tmp_path / f"{page.stem}_{i}.yml"
            path.write_text(b.code)
            found.append(path)
    assert len(found) > 1  # the README's example at least
    for path in found:
        machine = load_machine(path)
        assert machine.actuation is not None, path
