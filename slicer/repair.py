"""Repair on request (``mesp slice --repair``): every hole closed, or the surface wrapped
(``slicer.winding_repair``), and said so.

``mesh_io.load_surface`` fills only cracks (holes small against the model) and refuses a real
opening rather than guess it shut. A scan or a CT segmentation is often open where the scanner
did not see (the top of a limb, the eyes of a head): with ``--repair`` the user asks for
every hole to be closed. Each boundary loop (a connected chain of edges used by one face) is
closed by a fan of triangles around the loop's centroid, wound like its neighbours; the
closed surface then goes through ``load_surface``'s checks (size, winding, volume) like any
other. What changed (holes, open edges, area added, the largest hole) is one line in the
surface's notes, so the report and the command say it.

The repair is picked by the refusal's reason (``SurfaceRefused.reason``): an open surface is
filled, and where the filled surface is still refused (open sheets, a wall with a hole) it is
wrapped by fTetWild's winding-number test, which handles open surfaces. A closed,
non-manifold surface (an assembly's bodies touching along edges or faces, or pushed into
each other) is split where its parts touch (``shell_split.separate_shells``) and its
shells joined into one solid by manifold3d (``slicer.shell_union``): exact, in seconds, and
one boundary, which fTetWild meshes far faster than overlapping shells; where that split
leaves a crowded edge, the surface is wrapped. A wrap of several shells is joined the same
way. Wraps are kept per input (``slicer.wrap_cache``), so a repeated run, or the
``--repair`` run after the check that offered it, gets the same surface; the split and the
union are deterministic. A repaired surface still refused raises ``RepairRefused`` (what
was tried, typed). Whether ``--repair`` is offered, and checked, is ``slicer.repair_offer``.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import trimesh

from core.errors import InputError
from core.tolerance import tol
from slicer.config import ModelConfig
from slicer.mesh_io import Surface, clean_faces, load_surface, mm_per_unit
from slicer.shell_split import (
    SPLIT_OFFSET_FAC,
    non_manifold_edges,
    open_edges,
    separate_shells,
)
from slicer.shell_union import union_shells
from slicer.solid_volume import shells
from slicer.surface_refusal import RepairRefused, SurfaceReason, SurfaceRefused
from slicer.wrap_cache import cached_wrap, stored_wrap

_EDITOR = "close it in a mesh editor (e.g. Blender 3D-Print Toolbox, Meshmixer)"


@dataclass(frozen=True)
class HoleFill:
    """What ``fill_holes`` changed.

    Attributes:
        holes: boundary loops closed.
        open_edges: edges used by one face before the fill.
        area_added: area of the new triangles, in the mesh's units squared.
        largest_perimeter: the longest loop's perimeter, in the mesh's units.
    """

    holes: int
    open_edges: int
    area_added: float
    largest_perimeter: float


def fill_holes(vertices: np.ndarray, faces: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, HoleFill]:
    """Close every boundary loop with a fan around its centroid.

    Args:
        vertices: (n, 3) float64. faces: (m, 3) int, vertices merged (shared edges use the
            same two vertex indices).

    Returns:
        (vertices (n + k, 3) with one centroid per loop, faces (m + e, 3) with one new
        triangle per open edge, the summary). Each open half-edge (a, b) gets the triangle
        (b, a, centroid), so the new faces turn like the face they border.
    """
    faces = np.asarray(faces, dtype=np.int64)
    n = len(vertices)
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    ends = np.sort(directed, axis=1)
    _, edge_id, uses = np.unique(ends[:, 0] * n + ends[:, 1], return_inverse=True,
                                 return_counts=True)
    boundary = directed[uses[edge_id] == 1]
    if not len(boundary):
        return np.asarray(vertices), faces, HoleFill(0, 0, 0.0, 0.0)
    labels = trimesh.graph.connected_component_labels(boundary, node_count=n)
    _, loop = np.unique(labels[boundary[:, 0]], return_inverse=True)
    count = np.bincount(loop)
    centres = np.column_stack([np.bincount(loop, weights=vertices[boundary[:, 0], i])
                               for i in range(3)]) / count[:, None]
    new_v = np.vstack([vertices, centres])
    new_f = np.column_stack([boundary[:, 1], boundary[:, 0], n + loop])
    tri = new_v[new_f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    length = np.linalg.norm(vertices[boundary[:, 0]] - vertices[boundary[:, 1]], axis=1)
    perimeter = np.bincount(loop, weights=length)
    return new_v, np.vstack([faces, new_f]), HoleFill(
        len(count), len(boundary), float(area.sum()), float(perimeter.max()))


class WrapNotStored(Exception):
    """``load_repaired(..., wrap=False)`` needs a wrap that is not stored yet."""


def load_repaired(path: str | Path, units: str | ModelConfig = "mm", wrap: bool = True,
                  reason: SurfaceReason | None = None) -> Surface:
    """``load_surface``, with the repair its refusal's reason calls for made first
    (module docstring). ``wrap=False``: only a stored wrap is used (raises ``WrapNotStored``
    where fTetWild would have to run). ``reason``: the reason ``load_surface`` already
    refused the file for (it is not read twice).

    A surface that loads as it is is returned as it is (a note says there was nothing to
    repair).

    Raises:
        InputError: what ``load_surface`` raises for a reason no repair answers, or the
            repaired surface is still refused.
    """
    path = Path(path)
    if reason is None:
        try:
            surface = load_surface(path, units)
        except SurfaceRefused as exc:
            if exc.reason not in _REPAIRS:
                raise
            reason = exc.reason
        else:
            return replace(surface, notes=(*surface.notes, "--repair: the surface is closed, "
                                                           "nothing to repair"))
    mesh = trimesh.load_mesh(path, file_type=path.suffix.lower().lstrip("."), process=False)
    if isinstance(mesh, trimesh.Scene):
        mesh = mesh.to_geometry()
    clean_faces(mesh, mm_per_unit(mesh.vertices, units))  # the faces load_surface checked
    return _REPAIRS[reason](path, units, mesh, wrap)


def _load_filled(path: Path, units: str | ModelConfig, mesh: trimesh.Trimesh,
                 wrap: bool) -> Surface:
    """``load_surface`` on ``mesh`` with every hole closed; where that is still refused, on
    fTetWild's wrap of ``mesh``, unless the filled surface encloses nothing (sheets whose
    holes close them onto themselves, a polygon soup: no inside for a wrap to find)."""
    raw_v = np.asarray(mesh.vertices, dtype=np.float64)
    raw_f = np.asarray(mesh.faces)
    vertices, faces, fill = fill_holes(raw_v, raw_f)
    holes = f"filled {fill.holes} hole{'s' if fill.holes != 1 else ''}"
    try:
        surface = _load_as(path, units, vertices, faces, "the filled surface")
    except SurfaceRefused as exc:
        if exc.reason is SurfaceReason.FLAT:  # sheets closed on themselves: no inside to find
            raise RepairRefused(path.name, f"{holes} ({exc.problem})",
                                f"its faces enclose nothing (open sheets, a polygon soup): "
                                f"{_EDITOR}") from exc
        return _load_wrapped(path, units, raw_v, raw_f, wrap, f"{holes} ({exc.problem}) and ")
    scale = _scale(surface, vertices)
    line = (f"--repair: filled {fill.holes} hole{'s' if fill.holes != 1 else ''} "
            f"({fill.open_edges} open edges, largest {fill.largest_perimeter * scale:.1f} mm "
            f"round), added {fill.area_added * scale**2:.0f} mm^2 of surface")
    return replace(surface, notes=(line, *surface.notes))


def _load_as(path: Path, units: str | ModelConfig, vertices: np.ndarray, faces: np.ndarray,
             what: str) -> Surface:
    """``load_surface`` on a repaired surface (file units), its source ``path``; a refusal
    names it ``what``."""
    with tempfile.TemporaryDirectory(prefix="mesp-repair-") as scratch:
        closed = Path(scratch) / f"{path.stem}.ply"
        trimesh.Trimesh(vertices, faces, process=False).export(closed)
        try:
            surface = load_surface(closed, units)
        except SurfaceRefused as exc:
            raise SurfaceRefused(exc.problem.replace(closed.name, what), exc.fix,
                                 exc.reason) from exc
        except InputError as exc:
            raise InputError(exc.problem.replace(closed.name, what), exc.fix) from exc
    return replace(surface, source=path)


def _scale(surface: Surface, vertices: np.ndarray) -> float:
    """mm per file unit as loaded (the units and any --scale-to)."""
    return (float(np.ptp(np.asarray(surface.vertices), axis=0).max())
            / max(float(np.ptp(vertices, axis=0).max()), tol.tiny))


def _load_wrapped(path: Path, units: str | ModelConfig, vertices: np.ndarray,
                  faces: np.ndarray, wrap: bool, tried: str = "") -> Surface:
    """``load_surface`` on fTetWild's wrap of ``vertices`` (n, 3) float64 and ``faces``
    (m, 3) int (file units, merged); ``tried``: what was tried before, for a refusal."""
    stored = cached_wrap(vertices, faces) if wrap else stored_wrap(vertices, faces)
    if stored is None:
        raise WrapNotStored(path.name)
    out_v, out_f, wrapped = stored
    fix = ("its surface does not bound a solid fTetWild can find (overlapping or open "
           f"sheets): {_EDITOR}")
    if not len(out_f):
        raise RepairRefused(path.name, f"{tried}wrapped it: fTetWild's winding-number test "
                            "finds no inside", fix)
    parts = int(shells(out_f).max()) + 1
    joined = union_shells(out_v, out_f) if parts > 1 else None
    if joined is not None:  # fTetWild meshes one boundary far faster than overlapping shells
        out_v, out_f = joined
    try:
        surface = _load_as(path, units, out_v, out_f, "the wrapped surface")
    except InputError as exc:
        raise RepairRefused(path.name, f"{tried}wrapped it with fTetWild ({exc.problem})",
                            fix) from exc
    scale = _scale(surface, out_v)
    # an open input's signed volume means nothing: only the wrap's is said
    edges, before = ((f"{wrapped.open_edges} open and ", "") if wrapped.open_edges else
                     ("", f"{wrapped.volume_before * scale**3:.0f} -> "))
    if wrapped.bodies_wrapped < wrapped.bodies:
        edges = (f"{wrapped.bodies_wrapped} of {wrapped.bodies} bodies, the others kept as "
                 f"they are; {edges}")
    line = (f"--repair: wrapped by fTetWild's winding-number test ({edges}"
            f"{wrapped.non_manifold_edges} non-manifold edges resolved, {wrapped.pinches} "
            f"touching vertices split, {_joined(parts, joined is not None)}"
            f"{wrapped.faces_before} -> {len(out_f)} faces, volume {before}"
            f"{surface.volume_mm3:.0f} mm^3)")
    return replace(surface, notes=(line, *surface.notes))


def _joined(parts: int, joined: bool) -> str:
    """The clause saying the shells were joined, if they were."""
    return f"{parts} shells joined into one solid, " if joined else ""


def _load_split(path: Path, units: str | ModelConfig, mesh: trimesh.Trimesh,
                wrap: bool) -> Surface:
    """A closed, non-manifold ``mesh`` (merged, as read): its parts touching along edges or
    at points split into separate shells, and the shells joined into one solid by
    manifold3d (exact: no fTetWild, no envelope); where the split leaves an edge of 3 or
    more faces or a shell manifold3d cannot read, fTetWild's wrap (``_load_wrapped``)."""
    raw_v = np.asarray(mesh.vertices, dtype=np.float64)
    raw_f = np.asarray(mesh.faces, dtype=np.int64)
    split_v, split_f, pinches = separate_shells(raw_v, raw_f, 0.0)
    joined = (union_shells(split_v, split_f)
              if not non_manifold_edges(split_f) and not open_edges(split_f) else None)
    if joined is not None and len(joined[1]):
        # the union touches itself where parts met along a line (its own vertices coincide
        # there): merged like any input, those contacts are split apart again
        union = trimesh.Trimesh(*joined, process=False)
        clean_faces(union)
        diagonal = float(np.linalg.norm(union.extents))
        joined = separate_shells(np.asarray(union.vertices, dtype=np.float64),
                                 np.asarray(union.faces), SPLIT_OFFSET_FAC * diagonal)[:2]
    if joined is None or not len(joined[1]) or non_manifold_edges(joined[1]):
        return _load_wrapped(path, units, raw_v, raw_f, wrap)
    try:
        surface = _load_as(path, units, *joined, "the joined surface")
    except InputError:
        return _load_wrapped(path, units, raw_v, raw_f, wrap)
    parts = int(shells(split_f).max()) + 1
    line = (f"--repair: split the surface where its parts touch ({non_manifold_edges(raw_f)} "
            f"non-manifold edges, {pinches} touching vertices) and joined its {parts} shells "
            f"into one solid with manifold3d ({len(raw_f)} -> {len(joined[1])} faces, volume "
            f"{surface.volume_mm3:.0f} mm^3)")
    return replace(surface, notes=(line, *surface.notes))


#: the repair each repairable reason calls for
_REPAIRS: dict[SurfaceReason, Callable[[Path, str | ModelConfig, trimesh.Trimesh, bool],
                                       Surface]] = {
    SurfaceReason.OPEN: _load_filled,
    SurfaceReason.NON_MANIFOLD: _load_split,
}


def repairable(refusal: InputError) -> bool:
    """Whether ``--repair`` has a repair for ``refusal`` (by its reason)."""
    return isinstance(refusal, SurfaceRefused) and refusal.reason in _REPAIRS
