"""Two measures of the code's shape: functions with long positional parameter lists and
``# fmt: skip`` markers.

A function of 15 or more positional parameters (``def`` arguments and positional-only
ones, counted by ``ast``) is one whose callers must keep a long list in order; a
``# fmt: skip`` marker is usually there to keep such a list compact. Both are counted
over the library and the agents (or the paths given)::

    python benchmarks/code_shape.py                 # the counts and the long functions
    python benchmarks/code_shape.py --min-params 10 machining_envs/turning
    python benchmarks/code_shape.py --root ../other-checkout

It prints each long function (parameters, file, name), then the two totals.
"""

from __future__ import annotations

import argparse
import ast
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: What is counted when no path is given.
DEFAULT_PATHS = ("machining_envs", "agents")
#: A function with this many positional parameters or more is long.
MIN_PARAMS = 15


def _files(paths, root: Path = ROOT) -> list[Path]:
    out = []
    for p in paths:
        p = Path(p)
        p = p if p.is_absolute() else root / p
        out.extend(sorted(p.rglob("*.py")) if p.is_dir() else [p])
    return out


def long_functions(paths=DEFAULT_PATHS, min_params: int = MIN_PARAMS, root=ROOT) -> list[tuple]:
    """``(positional parameters, file relative to ``root``, name)`` of every function of
    ``paths`` (relative to ``root``, this repository by default) with at least
    ``min_params`` positional parameters, most first."""
    rows = []
    for f in _files(paths, root):
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = len(node.args.args) + len(node.args.posonlyargs)
                if n >= min_params:
                    rows.append((n, f.relative_to(root).as_posix(), node.name))
    return sorted(rows, key=lambda r: (-r[0], r[1], r[2]))


def fmt_skips(paths=DEFAULT_PATHS, root=ROOT) -> dict[str, int]:
    """The ``# fmt: skip`` comments of each file of ``paths`` (relative to ``root``) that
    has any (comments only, read by the tokenizer: not the words in a string)."""
    counts = {}
    for f in _files(paths, root):
        with tokenize.open(f) as fh:
            n = sum(
                1
                for tok in tokenize.generate_tokens(fh.readline)
                if tok.type == tokenize.COMMENT and tok.string.lstrip("# ").startswith("fmt: skip")
            )
        if n:
            counts[f.relative_to(root).as_posix()] = n
    return counts


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("paths", nargs="*", default=list(DEFAULT_PATHS))
    parser.add_argument("--min-params", type=int, default=MIN_PARAMS)
    parser.add_argument("--root", type=Path, default=ROOT, help="the checkout to count")
    args = parser.parse_args(argv)
    root = args.root.resolve()
    rows = long_functions(args.paths, args.min_params, root)
    for n, path, name in rows:
        print(f"{n:3d}  {path}  {name}")
    skips = fmt_skips(args.paths, root)
    print(f"functions with {args.min_params}+ positional parameters: {len(rows)}")
    print(f"# fmt: skip markers: {sum(skips.values())} in {len(skips)} files")


if __name__ == "__main__":
    main()
