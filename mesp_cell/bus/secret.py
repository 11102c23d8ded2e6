"""The cell's secret: the key every process of a cell signs its bus messages with.

One random 32-byte key per cell, ``$MESP_HOME/auth/<cell>.key``, created at the first start
of the cell (by whichever of the cell's processes starts first) with mode 0600 in a 0700
folder, so only the user running the cell (and root) can read it. A process that cannot read
it cannot sign, and the nodes refuse its commands (``mesp_cell.bus.signing``). A key file
that others can read or write is refused rather than trusted.
"""

from __future__ import annotations

import os
import secrets
import stat
from pathlib import Path

from core.errors import InputError

KEY_BYTES = 32


def mesp_home() -> Path:
    """The state directory: ``$MESP_HOME`` or ``~/.mesp``."""
    return Path(os.environ.get("MESP_HOME") or Path.home() / ".mesp")


def private_dir(path: Path) -> Path:
    """Create ``path`` (and parents) if missing; the folder itself ends mode 0700."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True, mode=0o700)
    if stat.S_IMODE(path.stat().st_mode) != 0o700 and path.stat().st_uid == os.getuid():
        path.chmod(0o700)
    return path


def write_private(path: Path, data: bytes | str) -> None:
    """Write a state file readable by its owner only (0600), atomically (temp + rename)."""
    path = Path(path)
    raw = data.encode() if isinstance(data, str) else data
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.write(fd, raw)
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)


def key_path(cell: str, home: Path | None = None) -> Path:
    """Where the secret of ``cell`` lives."""
    return (Path(home) if home is not None else mesp_home()) / "auth" / f"{cell}.key"


def _check_private(path: Path) -> None:
    st = path.stat()
    if st.st_uid != os.getuid() or stat.S_IMODE(st.st_mode) & 0o077:
        raise InputError(f"the cell secret {path} can be read or changed by other users "
                         f"(mode {stat.S_IMODE(st.st_mode):o})",
                         f"delete it (`rm {path}`) and start the cell again to make a new one")


def cell_secret(cell: str, home: Path | None = None, create: bool = True) -> bytes | None:
    """The secret of ``cell``; made at first use when ``create`` (None if absent and not
    created). Two processes starting at once agree: the first link wins, the other reads it."""
    path = key_path(cell, home)
    if not path.exists():
        if not create:
            return None
        private_dir(path.parent)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.new")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            os.write(fd, secrets.token_bytes(KEY_BYTES).hex().encode())
            os.fsync(fd)
        finally:
            os.close(fd)
        try:
            os.link(tmp, path)  # fails if another process made it meanwhile: use theirs
        except FileExistsError:
            pass
        finally:
            tmp.unlink()
    _check_private(path)
    try:
        key = bytes.fromhex(path.read_text().strip())
    except ValueError as exc:
        raise InputError(f"the cell secret {path} is corrupt",
                         f"delete it (`rm {path}`) and start the cell again") from exc
    if len(key) < 16:
        raise InputError(f"the cell secret {path} is too short",
                         f"delete it (`rm {path}`) and start the cell again")
    return key
