"""Repeatable tet meshes: fTetWild's result kept per input, so the same job slices the same.

fTetWild is not deterministic (the same surface and settings give different meshes from run
to run, even on one thread) and cannot be seeded from Python, so the first mesh made for an
input is stored, keyed by a SHA-256 of the surface, the ``[mesh]`` settings, the grading,
pytetwild's version and the source of the meshing code, and every later slice of the same
input reads it back. A changed model, setting or mesher is a new key.

Where: ``$MESP_CACHE_DIR`` (``off`` disables it), else ``$XDG_CACHE_HOME/mesp/tetmesh``, else
``~/.cache/mesp/tetmesh``. Entries are written atomically (a temporary file renamed).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict
from importlib import metadata
from pathlib import Path

import numpy as np

from core.stages import TetMesh
from slicer.config import MeshConfig
from slicer.mesh_io import Surface
from slicer.tet_stats import TetStats

CACHE_ENV = "MESP_CACHE_DIR"
#: the meshing code a cached mesh depends on (files of this package)
MESHING_SOURCES = ("tetrahedralize.py", "refine.py", "tet_geometry.py")


def cache_dir() -> Path | None:
    """Where tet meshes are kept (module docstring); None when disabled."""
    value = os.environ.get(CACHE_ENV, "")
    if value.lower() == "off":
        return None
    if value:
        return Path(value)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "mesp" / "tetmesh"


def cache_key(surface: Surface, config: MeshConfig, grading: float) -> str:
    """SHA-256 (hex) of everything the tet mesh depends on (module docstring)."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(surface.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(surface.faces, dtype=np.int64).tobytes())
    h.update(json.dumps(asdict(config), sort_keys=True).encode())
    h.update(repr(float(grading)).encode())
    h.update(metadata.version("pytetwild").encode())
    for source in MESHING_SOURCES:  # read as files: this module imports none of them
        h.update(Path(__file__).with_name(source).read_bytes())
    return h.hexdigest()


def load(folder: Path, key: str) -> tuple[TetMesh, TetStats] | None:
    """The stored mesh and its statistics for ``key``, or None (missing or unreadable)."""
    path = folder / f"{key}.npz"
    try:
        with np.load(path) as data:
            mesh = TetMesh(vertices=data["vertices"], tets=data["tets"])
            stats = TetStats(**json.loads(str(data["stats"])))
    except (OSError, KeyError, ValueError, TypeError):
        return None
    return mesh, stats


def store(folder: Path, key: str, mesh: TetMesh, stats: TetStats) -> None:
    """Keep ``mesh`` for ``key`` (best effort: a cache that cannot be written is skipped)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tmp = folder / f".{key}.{os.getpid()}.npz"
        np.savez(tmp, vertices=np.asarray(mesh.vertices), tets=np.asarray(mesh.tets),
                 stats=np.array(json.dumps(stats.as_dict())))
        os.replace(tmp, folder / f"{key}.npz")
    except OSError:
        return
