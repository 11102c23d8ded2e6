"""The defaults of the config dataclasses, read from the one defaults file that owns them.

A job's defaults live in ``slicer/defaults.toml`` and a cell's in ``planner/cells/default.toml``;
the frozen dataclasses that validate them take their field defaults from those files
(``table``), never from literals of their own, so the two cannot drift apart
(``tests/core/test_toml_defaults.py`` fails on a literal default).
"""

from __future__ import annotations

import functools
import tomllib
from importlib import resources
from typing import Any


@functools.cache
def _parsed(package: str, resource: str) -> dict[str, Any]:
    return tomllib.loads(resources.files(package).joinpath(resource).read_text())


def frozen(value: Any) -> Any:
    """``value`` with every list turned into a tuple (a frozen dataclass's default)."""
    if isinstance(value, list):
        return tuple(frozen(v) for v in value)
    if isinstance(value, dict):
        return {k: frozen(v) for k, v in value.items()}
    return value


def table(package: str, resource: str, *keys: str) -> dict[str, Any]:
    """The table at ``keys`` of the TOML file ``resource`` of ``package``, lists as tuples."""
    data: Any = _parsed(package, resource)
    for key in keys:
        data = data[key]
    return dict(frozen(data))
