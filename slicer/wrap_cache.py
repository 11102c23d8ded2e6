"""Repeatable repairs: fTetWild's wrap kept per input surface, so ``--repair`` gives one answer.

fTetWild is not deterministic (``slicer.tet_cache``): two wraps of one surface differ, and so
would the tet meshes, toolpaths and even the verdict (printed or refused) of two runs of the
same job. The first wrap of an input is stored, keyed by a SHA-256 of the input as read (the
file's vertices merged, in its own units, and its faces), the wrap's code and pytetwild's
version; every later wrap of that input reads it back. The key leaves out the units and the
size range: they only scale the wrap, and ``load_surface`` checks it afresh each time. So
the wrap made by the check that offers ``--repair`` (in a child process) is the one the
``--repair`` run that follows it uses, and the one ``mesp check`` reports.

Where: the tet-mesh cache's folder (``tet_cache.cache_dir``: ``$MESP_CACHE_DIR``, ``off``
disables both), files ``wrap-<key>.npz``, written atomically.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from dataclasses import asdict
from importlib import metadata
from pathlib import Path

import numpy as np

from slicer.body_wrap import wrap_troubled
from slicer.tet_cache import cache_dir
from slicer.winding_repair import Wrap

#: the code a stored wrap depends on (files of this package)
WRAP_SOURCES = ("body_wrap.py", "winding_repair.py", "shell_split.py", "tet_geometry.py",
                "solid_volume.py")


def wrap_key(vertices: np.ndarray, faces: np.ndarray) -> str:
    """SHA-256 (hex) of everything the wrap depends on (module docstring)."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
    h.update(metadata.version("pytetwild").encode())
    for source in WRAP_SOURCES:
        h.update(Path(__file__).with_name(source).read_bytes())
    return h.hexdigest()


def load(folder: Path, key: str) -> tuple[np.ndarray, np.ndarray, Wrap] | None:
    """The stored wrap for ``key`` (vertices, faces, summary), or None (missing, unreadable)."""
    try:
        with np.load(folder / f"wrap-{key}.npz") as data:
            return (np.asarray(data["vertices"], dtype=np.float64),
                    np.asarray(data["faces"], dtype=np.int64),
                    Wrap(**json.loads(str(data["summary"]))))
    except (OSError, EOFError, zipfile.BadZipFile, KeyError, ValueError, TypeError):
        return None  # a missing, truncated or corrupt file is a miss: wrapped again


def store(folder: Path, key: str, vertices: np.ndarray, faces: np.ndarray,
          summary: Wrap) -> None:
    """Keep the wrap for ``key`` (best effort: a cache that cannot be written is skipped)."""
    tmp = folder / f".wrap-{key}.{os.getpid()}.npz"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        np.savez(tmp, vertices=vertices, faces=faces,
                 summary=np.array(json.dumps(asdict(summary))))
        os.replace(tmp, folder / f"wrap-{key}.npz")
    except OSError:
        tmp.unlink(missing_ok=True)


def stored_wrap(vertices: np.ndarray, faces: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, Wrap] | None:
    """The wrap of this input if one is stored (no fTetWild run), else None."""
    folder = cache_dir()
    return None if folder is None else load(folder, wrap_key(vertices, faces))


def cached_wrap(vertices: np.ndarray, faces: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, Wrap]:
    """``body_wrap.wrap_troubled`` of ``vertices`` (n, 3) float64 and ``faces`` (m, 3) int, read
    back where this input was wrapped before, stored otherwise (also an empty wrap: the same
    input gets the same answer)."""
    folder = cache_dir()
    key = wrap_key(vertices, faces)
    if folder is not None:
        found = load(folder, key)
        if found is not None:
            return found
    out_v, out_f, summary = wrap_troubled(vertices, faces)
    if folder is not None:
        store(folder, key, out_v, out_f, summary)
    return out_v, out_f, summary
