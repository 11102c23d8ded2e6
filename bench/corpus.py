"""The real-model corpus: meshes nobody on this project made, and generated stand-ins for the field.

``shared_models()`` lists ``../shared/models/`` (the trimesh project's test meshes, as their
authors left them: mixed units, open scans, soups). ``generated_models(dir)`` writes three
parts a soft-robotics or medical lab brings that the shared folder lacks: an organ-like blob
(a smooth union of ellipsoids), a thin-walled cup (2 mm wall) and a part with an overhanging
branch (a trunk with a side arm rising at 35 deg from the horizontal). They are made with
manifold3d, so they are closed by construction, and written as STL in millimetres.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _shared_folder(start: Path) -> Path:
    """The nearest ``shared/models`` beside ``start`` or beside one of its parents (a git
    worktree lies deeper than the main checkout); ``start.parent/shared/models`` if none."""
    for parent in start.parents:
        if (parent / "shared" / "models").is_dir():
            return parent / "shared" / "models"
    return start.parent / "shared" / "models"


SHARED_MODELS = _shared_folder(ROOT)
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".3mf", ".msh", ".vtk", ".vtu")


class CorpusModel(NamedTuple):
    """One corpus entry.

    Attributes:
        name: short name (file stem).
        path: the mesh file.
        origin: "shared" (made by others) or "generated" (bench/corpus.py).
    """

    name: str
    path: Path
    origin: str


def shared_models(folder: Path = SHARED_MODELS) -> list[CorpusModel]:
    """Every mesh file of the shared folder, sorted by name."""
    if not folder.is_dir():
        return []
    return [CorpusModel(p.stem, p, "shared") for p in sorted(folder.iterdir())
            if p.suffix.lower() in MESH_SUFFIXES]


def _blob() -> object:
    import manifold3d as m3d

    parts = [((0, 0, 0), (22, 16, 14)), ((14, 6, 8), (12, 10, 9)), ((-12, -4, 6), (10, 9, 8))]
    body = None
    for centre, radii in parts:
        s = m3d.Manifold.sphere(1.0, 64).scale(radii).translate(centre)
        body = s if body is None else body + s
    return body


def _cup() -> object:
    import manifold3d as m3d

    outer = m3d.Manifold.cylinder(40.0, 25.0, 25.0, 96)
    inner = m3d.Manifold.cylinder(40.0, 23.0, 23.0, 96).translate((0, 0, 2.0))
    return outer - inner


def _branch() -> object:
    import manifold3d as m3d

    trunk = m3d.Manifold.cylinder(40.0, 9.0, 9.0, 64)
    arm = (m3d.Manifold.cylinder(34.0, 6.0, 6.0, 64)
           .rotate((0.0, 55.0, 0.0)).translate((0.0, 0.0, 14.0)))
    return trunk + arm


GENERATED = {"blob": _blob, "cup": _cup, "branch": _branch}


def generated_models(folder: Path) -> list[CorpusModel]:
    """Write the generated parts into ``folder`` (once) and list them."""
    import trimesh

    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for name, make in GENERATED.items():
        path = folder / f"{name}.stl"
        if not path.is_file():
            mesh = make().to_mesh()  # type: ignore[attr-defined]
            tri = trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3],
                                  np.asarray(mesh.tri_verts), process=True)
            tri.export(path)
        out.append(CorpusModel(name, path, "generated"))
    return out
