"""Atomic, validated ``.npz`` stage files (design.md: write, then rename)."""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from core.errors import InputError

# Mode of the files a job writes: readable by the lab like any output (mkstemp makes 0600).
FILE_MODE = 0o644

# (name -> (ndim, dtype kind, trailing shape or None)) used to validate a loaded file.
Schema = Mapping[str, tuple[int, str, tuple[int, ...] | None]]


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so a reader never sees a half-written file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, FILE_MODE)
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_npz(path: Path, arrays: Mapping[str, npt.ArrayLike]) -> None:
    """Save named arrays to ``path`` (uncompressed npz) atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.fchmod(fd, FILE_MODE)
    os.close(fd)
    try:
        with open(tmp, "wb") as handle:
            named: dict[str, Any] = {k: np.asarray(v) for k, v in arrays.items()}
            np.savez(handle, **named)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_npz(path: Path, schema: Schema) -> dict[str, np.ndarray]:
    """Load ``path`` and check every array named in ``schema``.

    Raises:
        InputError: the file is missing, unreadable, or an array is absent or mis-shaped.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path} does not exist", "run the stage that writes it first")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise InputError(f"{path} is not a readable .npz file ({exc})", "re-run the stage") from exc
    for name, (ndim, kind, trailing) in schema.items():
        if name not in arrays:
            raise InputError(f"{path} has no array '{name}'", "re-run the stage that writes it")
        arr = arrays[name]
        if arr.ndim != ndim or (trailing is not None and arr.shape[1:] != trailing):
            raise InputError(
                f"{path}: '{name}' has shape {arr.shape}, expected {ndim}-D"
                + (f" ending in {trailing}" if trailing else ""),
                "re-run the stage that writes it",
            )
        if arr.dtype.kind not in kind:
            raise InputError(
                f"{path}: '{name}' has dtype {arr.dtype}", "re-run the stage that writes it"
            )
    return arrays


def read_json(path: Path) -> dict[str, Any]:
    """Read a JSON object, or an empty dict if the file does not exist."""
    path = Path(path)
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"{path} is not valid JSON ({exc})", "delete it and re-run") from exc
    if not isinstance(data, dict):
        raise InputError(f"{path} does not hold a JSON object", "delete it and re-run")
    return data


def write_json(path: Path, data: Mapping[str, Any]) -> None:
    """Write a JSON object atomically, pretty-printed."""
    atomic_write_bytes(Path(path), (json.dumps(data, indent=2, default=_jsonable) + "\n").encode())


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot write {type(value).__name__} to JSON")
