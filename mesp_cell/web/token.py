"""The console's bearer token: generated on first start, kept 0600 with the cell's state.

Binding the console to anything but loopback needs it for every API call; once it exists, the
endpoints that move or stop the cell need it on loopback too.
"""

from __future__ import annotations

import hmac
import ipaddress
import os
import secrets
from pathlib import Path


def token_path(home: Path) -> Path:
    """Where the token lives: ``$MESP_HOME/console/token``."""
    return Path(home) / "console" / "token"


def is_loopback(host: str) -> bool:
    """The bind address only accepts connections from this host."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def load_token(home: Path, create: bool) -> str:
    """The stored token ("" if none and not ``create``); a new one is written 0600."""
    path = token_path(home)
    if path.is_file():
        return path.read_text().strip()
    if not create:
        return ""
    path.parent.mkdir(parents=True, exist_ok=True)
    os.chmod(path.parent, 0o700)
    token = secrets.token_urlsafe(32)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(token + "\n")
    return token


def bearer_ok(token: str, header: str | None) -> bool:
    """``header`` is ``Bearer <token>`` (constant-time compare)."""
    if not token or not header or not header.startswith("Bearer "):
        return False
    return hmac.compare_digest(header[len("Bearer "):].strip().encode(), token.encode())
