"""Key expressions of the cell bus: ``mesp/<cell>/<node>/<topic>``.

Every name part is a lower-case identifier (letters, digits, ``_``, ``-``) so a key never holds
zenoh wildcards or separators by accident; ``*`` is allowed where a pattern is built for a
subscription.
"""

from __future__ import annotations

import re
from typing import NamedTuple

from core.errors import InputError

PREFIX = "mesp"
_PART = re.compile(r"^[a-z0-9][a-z0-9_\-]*$")


class KeyParts(NamedTuple):
    """The parts of a cell key expression."""

    cell: str
    node: str
    topic: str


def check_part(value: str, what: str, wildcard: bool = False) -> str:
    """Return ``value`` if it is a valid key part, else raise ``InputError`` naming ``what``."""
    if wildcard and value in ("*", "**"):
        return value
    if not _PART.match(value):
        raise InputError(
            f"{what} '{value}' is not a valid bus name",
            "use lower-case letters, digits, '_' or '-', starting with a letter or digit",
        )
    return value


def key(cell: str, node: str, topic: str) -> str:
    """The key expression ``mesp/<cell>/<node>/<topic>`` (``node``/``topic`` may be ``*``)."""
    check_part(cell, "cell name")
    check_part(node, "node name", wildcard=True)
    for part in topic.split("/"):
        check_part(part, "topic", wildcard=True)
    return f"{PREFIX}/{cell}/{node}/{topic}"


def liveliness_key(cell: str, node: str) -> str:
    """Key of a node's liveliness token (present exactly while the process is alive)."""
    return key(cell, node, "alive")


def parse_key(text: str) -> KeyParts:
    """Split a concrete key expression into its cell, node and topic."""
    parts = str(text).split("/")
    if len(parts) < 4 or parts[0] != PREFIX:
        raise ValueError(f"'{text}' is not a mesp/<cell>/<node>/<topic> key")
    return KeyParts(parts[1], parts[2], "/".join(parts[3:]))
