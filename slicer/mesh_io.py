"""Reading the user's model: a closed triangle surface (STL, OBJ, PLY) or an existing tet mesh.

Every problem with the file is an ``InputError`` with one line saying what is wrong and what
to do. Repairs are made only where they cannot change the intended shape: merging duplicate
vertices, filling holes that are small against the model (perimeter at most
``SMALL_HOLE_FRACTION`` of the bounding-box diagonal), making the winding consistent and, for
a surface whose normals all point inwards (negative volume), flipping every face. Each
repair is reported in ``Surface.notes``; a larger opening is refused, with the number of open
edges, rather than guessed shut. A surface that does not bound a solid is refused with a
``SurfaceRefused`` whose reason (``slicer.surface_refusal.SurfaceReason``) ``--repair``
dispatches on.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import trimesh

from core.errors import InputError
from core.stages import TetMesh
from core.tolerance import tol
from slicer.config import UNIT_SCALE_MM, ModelConfig
from slicer.solid_volume import solid_volume
from slicer.surface_refusal import SurfaceReason, SurfaceRefused
from slicer.tet_geometry import compact, orient_positive, tet_volumes

SURFACE_SUFFIXES = (".stl", ".obj", ".ply")
TET_SUFFIXES = (".msh", ".vtk", ".vtu")
# A hole whose boundary is at most this fraction of the bounding-box diagonal is a crack
# from export and is filled; a larger one is a real opening and is refused.
SMALL_HOLE_FRACTION = 0.05
# Below this volume (relative to the bounding-box diagonal cubed) the solid is flat.
FLAT_VOLUME_FRACTION = 1e-9
# A model file larger than this is refused before it is read (a binary STL of 20 M triangles).
MAX_MODEL_BYTES = 1 << 30


@dataclass(frozen=True, eq=False)
class Surface:
    """A closed, outward-oriented triangle surface in millimetres.

    Attributes:
        vertices: (n, 3) float64, mm.
        faces: (m, 3) int32, vertex indices, counter-clockwise seen from outside.
        source: the file it was read from.
        notes: repairs made while loading, one sentence each (for the report).
    """

    vertices: np.ndarray
    faces: np.ndarray
    source: Path
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name, dtype in (("vertices", np.float64), ("faces", np.int32)):
            arr = np.array(getattr(self, name), dtype=dtype, copy=True)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"vertices must be (n, 3), got {self.vertices.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise ValueError(f"faces must be (m, 3), got {self.faces.shape}")

    @cached_property
    def volume_mm3(self) -> float:
        """Enclosed volume, mm^3 (positive for an outward-oriented surface): overlapping
        shells counted once (``solid_volume``)."""
        return solid_volume(self.vertices, self.faces)

    @property
    def bbox_mm(self) -> tuple[float, float, float]:
        """Size of the axis-aligned bounding box (x, y, z), mm."""
        size = self.vertices.max(axis=0) - self.vertices.min(axis=0)
        return (float(size[0]), float(size[1]), float(size[2]))

    def as_report(self) -> dict[str, object]:
        """The ``model`` section of report.json: volume, bounding box, source and repairs."""
        return {
            "volume_mm3": self.volume_mm3,
            "bbox_mm": list(self.bbox_mm),
            "faces": len(self.faces),
            "source": str(self.source),
            "repairs": list(self.notes),
        }

    def as_trimesh(self) -> trimesh.Trimesh:
        """A trimesh copy (for queries such as containment or sampling)."""
        return trimesh.Trimesh(self.vertices.copy(), self.faces.copy(), process=False)


def model_config(units: str | ModelConfig) -> ModelConfig:
    """``units`` as a ``ModelConfig`` (a unit name gets the default size range)."""
    if isinstance(units, ModelConfig):
        return units
    if units not in UNIT_SCALE_MM:
        raise InputError(f"unknown units '{units}'", f"use one of {', '.join(UNIT_SCALE_MM)}")
    return ModelConfig(units=units)  # type: ignore[arg-type]


def _check_file(path: Path, suffixes: tuple[str, ...], what: str) -> None:
    if not path.exists():
        raise InputError(f"model file {path} does not exist", "check the path and its spelling")
    if not path.is_file():
        raise InputError(f"{path} is not a file", f"give the path of a {what} file")
    if path.suffix.lower() not in suffixes:
        raise InputError(
            f"{path.name}: '{path.suffix}' is not a {what} format",
            f"export the model as {', '.join(s.lstrip('.').upper() for s in suffixes)}",
        )
    if path.stat().st_size == 0:
        raise InputError(f"{path} is empty (0 bytes)", "export the model again")
    if path.stat().st_size > MAX_MODEL_BYTES:
        raise InputError(f"{path} is {path.stat().st_size / 2**30:.1f} GiB, larger than "
                         f"{MAX_MODEL_BYTES >> 30} GiB", "decimate the mesh before exporting it")


def _looks_like_stl(path: Path) -> bool:
    """Whether the bytes are a binary STL (size matches its triangle count) or ASCII STL."""
    size = path.stat().st_size
    with path.open("rb") as handle:
        head = handle.read(84)
        if len(head) == 84:
            count = int(np.frombuffer(head[80:84], dtype="<u4")[0])
            if size == 84 + 50 * count:
                return True
        handle.seek(0)
        text = handle.read(4096).lower()
    return text.lstrip().startswith(b"solid") and b"facet" in text


def _read_trimesh(path: Path) -> trimesh.Trimesh:
    fix = "export it again as a binary STL, OBJ or PLY triangle mesh"
    try:
        loaded = trimesh.load_mesh(path, file_type=path.suffix.lower().lstrip("."), process=False)
    except (Exception, SystemExit) as exc:  # trimesh raises many types for malformed files
        problem = f"{path} is not a readable mesh ({type(exc).__name__}: {_short(exc)})"
        raise InputError(problem, fix) from exc
    if isinstance(loaded, trimesh.Scene):
        loaded = loaded.to_geometry() if loaded.geometry else trimesh.Trimesh()
    if not isinstance(loaded, trimesh.Trimesh):
        raise InputError(f"{path} holds no triangle surface ({type(loaded).__name__})", fix)
    if len(loaded.faces) == 0:
        if path.suffix.lower() == ".stl" and not _looks_like_stl(path):
            raise InputError(f"{path} is not an STL file (neither binary nor ASCII STL)", fix)
        raise InputError(f"{path} contains no triangles", fix)
    vertices = np.asarray(loaded.vertices)
    faces = np.asarray(loaded.faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or vertices.dtype.kind != "f":
        raise InputError(f"{path} does not hold 3-D vertices ({vertices.shape})", fix)
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.dtype.kind not in "iu":
        raise InputError(f"{path} does not hold triangles ({faces.shape})", fix)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(f"{path} has faces naming vertices it does not have "
                         f"(index {int(faces.max())}, {len(vertices)} vertices)", fix)
    return loaded


def _short(exc: BaseException) -> str:
    """A library's message on one line, at most 200 characters."""
    return " ".join(str(exc).split())[:200]


def _boundary_loops(mesh: trimesh.Trimesh) -> tuple[int, np.ndarray]:
    """Open edges and the perimeter (mm) of each connected chain of them.

    Returns:
        (number of edges used by exactly one face, (k,) float64 perimeter of each hole).
    """
    groups = trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)
    edges = mesh.edges_sorted[groups]
    if len(edges) == 0:
        return 0, np.zeros(0)
    lengths = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    labels = trimesh.graph.connected_component_labels(edges, node_count=len(mesh.vertices))
    per_edge = labels[edges[:, 0]]
    _, inverse = np.unique(per_edge, return_inverse=True)
    return len(edges), np.bincount(inverse, weights=lengths)


def _fill_small_holes(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Close every hole with a fan around a new vertex at the hole's centroid.

    Each boundary half-edge (a, b) (of an edge used by one face only) gets the triangle
    (b, a, centre), so the new faces follow the winding of their neighbours.
    """
    directed = mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    n = len(mesh.vertices)
    ends = np.sort(directed, axis=1).astype(np.int64)
    _, edge_id, uses = np.unique(
        ends[:, 0] * n + ends[:, 1], return_inverse=True, return_counts=True
    )
    boundary = directed[uses[edge_id] == 1]
    labels = trimesh.graph.connected_component_labels(boundary, node_count=n)
    _, loop_of_edge = np.unique(labels[boundary[:, 0]], return_inverse=True)
    # Centroid of each loop's vertices (each boundary vertex starts one half-edge).
    counts = np.bincount(loop_of_edge)
    centres = (
        np.column_stack(
            [np.bincount(loop_of_edge, weights=mesh.vertices[boundary[:, 0], i]) for i in range(3)]
        )
        / counts[:, None]
    )
    new_faces = np.column_stack([boundary[:, 1], boundary[:, 0], n + loop_of_edge])
    return trimesh.Trimesh(
        np.vstack([mesh.vertices, centres]), np.vstack([mesh.faces, new_faces]), process=False
    )


def _consistent_winding(faces: np.ndarray) -> tuple[np.ndarray, bool]:
    """Which faces to flip so a closed 2-manifold surface has one consistent winding.

    Two faces sharing an edge agree when they run through it in opposite directions. On a
    doubled graph (each face as two nodes, "as is" and "flipped"), agreeing neighbours link
    same-state nodes and disagreeing neighbours link opposite-state nodes; a face's two nodes
    in one component means the surface cannot be oriented. In each connected part of the
    surface the smaller set of faces is flipped.

    Args:
        faces: (m, 3) int, every undirected edge used by exactly two faces.

    Returns:
        ((m,) bool faces to flip, whether the surface is orientable).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = len(faces)
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)
    face_of = np.repeat(np.arange(m), 3)
    key = np.sort(directed, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    first, second = order[0::2], order[1::2]  # watertight: edges come in pairs
    agree = directed[first, 0] != directed[second, 0]
    f, g = face_of[first], face_of[second]
    # node f = face f as is, node f + m = face f flipped
    rows = np.concatenate([f, f + m])
    cols = np.concatenate([np.where(agree, g, g + m), np.where(agree, g + m, g)])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(2 * m, 2 * m))
    _, label = connected_components(graph, directed=False)
    if np.any(label[:m] == label[m:]):
        return np.zeros(m, dtype=bool), False
    # Per surface part, keep the orientation state that most faces already have.
    part = np.minimum(label[:m], label[m:])
    keep_state = label[:m] == part  # face is in the "lower-labelled" state as is
    votes = np.bincount(part, weights=keep_state, minlength=2 * m)
    sizes = np.bincount(part, minlength=2 * m)
    majority_as_is = votes[part] * 2 >= sizes[part]
    flip = keep_state != majority_as_is
    return flip, True


def clean_faces(mesh: trimesh.Trimesh, mm_per_unit: float = 1.0) -> int:
    """Merge coincident vertices and drop exact repeats and degenerate faces (lower than
    ``tol.merge`` mm; ``mm_per_unit``: the mesh's unit), in place: export noise, removed the
    same way before every check of a surface and before its repair. Returns the faces dropped.
    A face and its reverse are not repeats (together a zero-thickness sheet, refused later)."""
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    faces_before = len(mesh.faces)
    shift = np.argmin(mesh.faces, axis=1)
    cyclic = np.take_along_axis(mesh.faces, (shift[:, None] + np.arange(3)) % 3, axis=1)
    _, first = np.unique(cyclic, axis=0, return_index=True)
    unique = np.zeros(len(mesh.faces), dtype=bool)
    unique[first] = True
    mesh.update_faces(unique & mesh.nondegenerate_faces(height=tol.merge / mm_per_unit))
    mesh.remove_unreferenced_vertices()
    return faces_before - len(mesh.faces)


def mm_per_unit(vertices: np.ndarray, units: str | ModelConfig) -> float:
    """mm per coordinate unit of a file's ``vertices`` (N, 3) as ``load_surface`` scales
    them: the unit, times the ``scale_to`` factor where one is asked for."""
    config = model_config(units)
    return config.scale_mm * _scale_to(np.asarray(vertices) * config.scale_mm, config, [])


def _repair(mesh: trimesh.Trimesh, name: str, notes: list[str]) -> trimesh.Trimesh:
    """Merge, drop degenerate faces, fill small holes, fix winding; refuse what stays open."""
    dropped = clean_faces(mesh)
    if dropped:
        notes.append(f"removed {dropped} duplicate or degenerate faces")
    if len(mesh.faces) == 0:
        raise SurfaceRefused(f"{name} has only degenerate triangles", "export the model again",
                             SurfaceReason.DEGENERATE)
    diagonal = float(np.linalg.norm(mesh.extents))
    open_edges, perimeters = _boundary_loops(mesh)
    if open_edges and perimeters.max() <= SMALL_HOLE_FRACTION * diagonal:
        mesh = _fill_small_holes(mesh)
        notes.append(f"filled {len(perimeters)} small holes ({open_edges} open edges)")
        open_edges, perimeters = _boundary_loops(mesh)
    if open_edges or not mesh.is_watertight:
        shared = trimesh.grouping.group_rows(mesh.edges_sorted, require_count=2)
        non_manifold = len(mesh.edges_unique) - len(shared) - open_edges
        detail = f"{open_edges} open edges" if open_edges else f"{non_manifold} non-manifold edges"
        largest = f", largest hole {perimeters.max():.1f} mm round" if len(perimeters) else ""
        raise SurfaceRefused(
            f"{name} is not watertight ({detail}{largest})",
            "close the surface in a mesh editor (e.g. Blender 3D-Print Toolbox, Meshmixer)",
            SurfaceReason.OPEN if open_edges else SurfaceReason.NON_MANIFOLD,
        )
    flip, orientable = _consistent_winding(mesh.faces)
    if not orientable:
        raise SurfaceRefused(
            f"{name} cannot be oriented consistently (non-orientable or self-overlapping)",
            "repair the surface in a mesh editor", SurfaceReason.NON_ORIENTABLE,
        )
    if flip.any():
        faces = mesh.faces.copy()
        faces[flip] = faces[flip][:, ::-1]
        mesh = trimesh.Trimesh(mesh.vertices, faces, process=False)
        notes.append(f"re-oriented {int(flip.sum())} faces for a consistent winding")
    return mesh


def load_surface(path: str | Path, units: str | ModelConfig = "mm") -> Surface:
    """Read a closed triangle surface and return it in millimetres, repaired where safe.

    Args:
        path: an ``.stl``, ``.obj`` or ``.ply`` file.
        units: the unit of the file's coordinates (mm, cm, m, in), or a ``ModelConfig``
            that also gives the accepted size range.

    Raises:
        InputError: the file is missing, unreadable, empty, open, flat, or of absurd size.
            A surface whose normals all point inwards is not an error: it is flipped and a
            note says so (STL exporters get this wrong; the solid is unambiguous).
    """
    path = Path(path)
    config = model_config(units)
    _check_file(path, SURFACE_SUFFIXES, "surface mesh")
    mesh = _read_trimesh(path)
    name = path.name
    if not np.all(np.isfinite(mesh.vertices)):
        raise InputError(f"{name} has NaN or infinite coordinates", "export the model again")
    mesh.apply_scale(config.scale_mm)
    notes: list[str] = []
    factor = _scale_to(mesh.vertices, config, notes)
    if factor != 1.0:
        mesh.apply_scale(factor)
    _check_size(mesh.vertices, name, config)
    try:
        mesh = _repair(mesh, name, notes)
    except InputError:
        raise
    except (ValueError, IndexError, OverflowError) as exc:  # trimesh on a malformed surface
        raise InputError(f"{name} is not a valid triangle surface ({type(exc).__name__}: "
                         f"{_short(exc)})", "export it again as a closed triangle mesh") from exc
    diagonal = float(np.linalg.norm(mesh.extents))
    tri = mesh.vertices[mesh.faces]
    volume = float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6)
    if abs(volume) <= FLAT_VOLUME_FRACTION * diagonal**3:
        raise SurfaceRefused(
            f"{name} encloses no volume ({volume:.3g} mm^3): it is flat or doubled-up",
            "give a solid model (a closed surface around a volume)", SurfaceReason.FLAT,
        )
    if volume < 0:
        mesh.invert()
        notes.append("all normals pointed inwards (negative volume): flipped every face")
    return Surface(vertices=mesh.vertices, faces=mesh.faces, source=path, notes=tuple(notes))


def _scale_to(vertices: np.ndarray, config: ModelConfig, notes: list[str]) -> float:
    """The uniform factor that makes the largest extent ``config.scale_to_mm`` (1 when off),
    with a note saying what was done."""
    if config.scale_to_mm <= 0:
        return 1.0
    size = float(np.max(vertices.max(axis=0) - vertices.min(axis=0)))
    if not size > 0:
        return 1.0  # a point or empty model: the size check refuses it
    factor = config.scale_to_mm / size
    notes.append(f"scaled by {factor:.4g} from {size:.4g} to {config.scale_to_mm:g} mm "
                 "(largest extent)")
    return factor


def _check_size(vertices: np.ndarray, name: str, config: ModelConfig) -> None:
    size = float(np.max(vertices.max(axis=0) - vertices.min(axis=0)))
    given = f"--units {config.units}" if config.units != "mm" else "millimetres"
    if size > config.max_size_mm:
        raise InputError(
            f"{name} is {size:.4g} mm across, larger than {config.max_size_mm:g} mm "
            f"(read as {given})",
            "if the file is in smaller units, say so with --units (mm, cm, m, in) or "
            "[model] units in the job file",
        )
    if size < config.min_size_mm:
        raise InputError(
            f"{name} is {size:.4g} mm across, smaller than {config.min_size_mm:g} mm "
            f"(read as {given})",
            "if the file is in larger units, say so with --units (cm, m, in) or [model] "
            "units in the job file",
        )


def load_tet_mesh(path: str | Path, units: str | ModelConfig = "mm") -> TetMesh:
    """Read an existing tetrahedral mesh (``.msh``, ``.vtk``, ``.vtu``) through meshio.

    All ``tetra`` cell blocks are used; other cells (surface triangles, lines) are ignored.
    Tets are re-oriented to positive volume, degenerate tets are refused, vertices not used
    by any tet are dropped.

    Raises:
        InputError: missing or unreadable file, no tetra cells, degenerate tets, bad size.
    """
    import meshio

    path = Path(path)
    config = model_config(units)
    _check_file(path, TET_SUFFIXES, "tet mesh")
    said = io.StringIO()  # meshio prints its complaint to stderr, then calls sys.exit(1)
    try:
        with contextlib.redirect_stderr(said), contextlib.redirect_stdout(said):
            data = meshio.read(path)
    except (Exception, SystemExit) as exc:  # malformed files: many types, and sys.exit(1)
        why = _short(exc) if not isinstance(exc, SystemExit) else " ".join(said.getvalue().split())
        raise InputError(f"{path} is not a readable tet mesh ({why[:200] or type(exc).__name__})",
                         "write it again as Gmsh .msh, .vtk or .vtu") from exc
    blocks = [np.asarray(c.data) for c in data.cells if c.type == "tetra"]
    if not blocks:
        kinds = ", ".join(sorted({c.type for c in data.cells})) or "none"
        raise InputError(
            f"{path.name} has no tetrahedra (cell types: {kinds})",
            "give a volume mesh, or give the surface (STL/OBJ/PLY) and let mesp tetrahedralize it",
        )
    points = np.asarray(data.points)
    if points.ndim != 2 or points.shape[1] != 3 or points.dtype.kind not in "fiu":
        raise InputError(f"{path.name} does not have 3-D points", "give a 3-D tet mesh")
    if not np.all(np.isfinite(points)):
        raise InputError(f"{path.name} has NaN or infinite point coordinates",
                         "export the tet mesh again")
    vertices = points.astype(np.float64) * config.scale_mm
    vertices = vertices * _scale_to(vertices, config, [])
    tets = np.vstack(blocks)
    if tets.ndim != 2 or tets.shape[1] != 4 or tets.dtype.kind not in "iu":
        raise InputError(f"{path.name} has malformed tetra cells", "export it again")
    tets = tets.astype(np.int64)
    if len(tets) == 0 or tets.min() < 0 or tets.max() >= len(vertices):
        raise InputError(f"{path.name} has tets indexing missing points", "export it again")
    _check_size(vertices, path.name, config)
    vertices, tets = compact(vertices, tets)
    volumes = tet_volumes(vertices, tets)
    scale = float(np.max(vertices.max(axis=0) - vertices.min(axis=0)))
    degenerate = int(np.count_nonzero(np.abs(volumes) <= tol.zero * scale**3))
    if degenerate:
        raise InputError(
            f"{path.name} has {degenerate} zero-volume tets", "remesh it, or give the surface"
        )
    return TetMesh(vertices=vertices, tets=orient_positive(vertices, tets))


def write_tet_mesh(mesh: TetMesh, path: str | Path) -> Path:
    """Write a tet mesh for other tools (``.msh``, ``.vtk`` or ``.vtu``, by suffix), in mm."""
    import meshio

    path = Path(path)
    if path.suffix.lower() not in TET_SUFFIXES:
        raise InputError(
            f"cannot write a tet mesh as '{path.suffix}'", f"use one of {', '.join(TET_SUFFIXES)}"
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    out = meshio.Mesh(points=np.asarray(mesh.vertices), cells=[("tetra", np.asarray(mesh.tets))])
    kwargs = {"file_format": "gmsh22", "binary": True} if path.suffix.lower() == ".msh" else {}
    meshio.write(path, out, **kwargs)
    return path
