"""Reading the JSON files of runs and settings: a damaged file is refused naming it."""

from __future__ import annotations

import json
from pathlib import Path

__all__ = ["read_json_object", "read_utf8"]


def read_utf8(path, what: str, error: type[Exception] = ValueError) -> str:
    """The text of the file ``path``; ``error`` (a ``ValueError`` by default) naming the
    file and ``what`` it should be when it is not UTF-8 text."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise error(f"{path}: not a {what} (not UTF-8 text)") from None


def read_json_object(path, what: str) -> dict:
    """The JSON object in the file ``path``; ``ValueError`` naming the file and ``what`` it
    should be when it is not UTF-8 text, not JSON, or not an object."""
    path = Path(path)
    try:
        data = json.loads(read_utf8(path, what))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not a {what} ({exc})") from None
    if not isinstance(data, dict):
        raise ValueError(
            f"{path}: not a {what} (a JSON object is expected, got {type(data).__name__})"
        )
    return data
