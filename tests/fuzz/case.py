"""One named malformed input and the helper that writes its files."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Case:
    """A malformed input: ``kind`` (entry point), ``name``, ``build(tmp) -> argv``."""

    kind: str
    name: str
    build: Callable[[Path], list[str]]


def write_file(path: Path, text: str | bytes) -> Path:
    """Write ``text`` (str or bytes) to ``path``, making its folder."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path
