"""Repair on request (``mesp slice --repair``): every hole closed, or a non-manifold surface
wrapped (``slicer.winding_repair``), and said so.

``mesh_io.load_surface`` fills only cracks (holes small against the model) and refuses a real
opening rather than guess it shut. A scan or a CT segmentation is often open where the scanner
did not see (the top of a limb, the eyes of a head): with ``--repair`` the user asks for
every hole to be closed. Each boundary loop (a connected chain of edges used by one face) is
closed by a fan of triangles around the loop's centroid, wound like its neighbours; the
closed surface then goes through ``load_surface``'s checks (size, winding, volume) like any
other. What changed (holes, open edges, area added, the largest hole) is one line in the
surface's notes, so the report and the command say it.
"""

from __future__ import annotations

import multiprocessing
import queue as queue_module
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from core.errors import InputError
from core.tolerance import tol
from slicer.config import ModelConfig
from slicer.mesh_io import Surface, load_surface
from slicer.winding_repair import wrap

# Seconds the refusal of a non-manifold surface waits for the check that --repair works.
OFFER_SECONDS = 30.0
_TIMED_OUT = "timed out"


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


def _repairable(refusal: InputError) -> str | None:
    """Which repair answers ``load_surface``'s refusal: "open" (holes), "non-manifold"
    (closed, with edges of 3 or more faces), or None (another cause)."""
    if "not watertight" not in refusal.problem:
        return None
    if "open edges" in refusal.problem:
        return "open"
    return "non-manifold" if "non-manifold edges" in refusal.problem else None


def load_repaired(path: str | Path, units: str | ModelConfig = "mm") -> Surface:
    """``load_surface``, with every hole closed first where the surface is open, or wrapped by
    fTetWild (``slicer.winding_repair``) where it is closed but non-manifold.

    A surface that loads as it is is returned as it is (a note says there was nothing to
    repair).

    Raises:
        InputError: what ``load_surface`` raises for another reason, or the repaired surface
            is still refused (overlapping sheets, edges shared by 3 faces after the fill).
    """
    path = Path(path)
    try:
        surface = load_surface(path, units)
    except InputError as exc:
        kind = _repairable(exc)
        if kind is None:
            raise
    else:
        return replace(surface, notes=(*surface.notes, "--repair: the surface is closed, "
                                                       "nothing to repair"))
    mesh = trimesh.load_mesh(path, file_type=path.suffix.lower().lstrip("."), process=False)
    if isinstance(mesh, trimesh.Scene):
        mesh = mesh.to_geometry()
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    if kind == "non-manifold":
        return _load_wrapped(path, units, mesh)
    mesh.update_faces(mesh.unique_faces() & mesh.nondegenerate_faces())
    vertices, faces, fill = fill_holes(np.asarray(mesh.vertices, dtype=np.float64),
                                       np.asarray(mesh.faces))
    with tempfile.TemporaryDirectory(prefix="mesp-repair-") as scratch:
        closed = Path(scratch) / f"{path.stem}.ply"
        trimesh.Trimesh(vertices, faces, process=False).export(closed)
        try:
            surface = load_surface(closed, units)
        except InputError as exc:
            raise InputError(
                f"{path.name} stays open after --repair filled {fill.holes} holes "
                f"({exc.problem.replace(closed.name, 'the filled surface')})",
                "its surface is not a set of clean holes (edges shared by 3 faces, or "
                "overlapping sheets): close it in a mesh editor (e.g. Blender 3D-Print "
                "Toolbox, Meshmixer)") from exc
    scale = _scale(surface, vertices)
    line = (f"--repair: filled {fill.holes} hole{'s' if fill.holes != 1 else ''} "
            f"({fill.open_edges} open edges, largest {fill.largest_perimeter * scale:.1f} mm "
            f"round), added {fill.area_added * scale**2:.0f} mm^2 of surface")
    return replace(surface, source=path, notes=(line, *surface.notes))


def _scale(surface: Surface, vertices: np.ndarray) -> float:
    """mm per file unit as loaded (the units and any --scale-to)."""
    return (float(np.ptp(np.asarray(surface.vertices), axis=0).max())
            / max(float(np.ptp(vertices, axis=0).max()), tol.tiny))


def _load_wrapped(path: Path, units: str | ModelConfig, mesh: trimesh.Trimesh) -> Surface:
    """``load_surface`` on fTetWild's wrap of the closed, non-manifold ``mesh``."""
    vertices, faces, wrapped = wrap(np.asarray(mesh.vertices, dtype=np.float64),
                                    np.asarray(mesh.faces))
    fix = ("its surface does not bound a solid fTetWild can find (overlapping or open "
           "sheets): close it in a mesh editor (e.g. Blender 3D-Print Toolbox, Meshmixer)")
    if not len(faces):
        raise InputError(f"{path.name}: fTetWild's winding-number test finds no inside "
                         "(--repair)", fix)
    with tempfile.TemporaryDirectory(prefix="mesp-repair-") as scratch:
        closed = Path(scratch) / f"{path.stem}.ply"
        trimesh.Trimesh(vertices, faces, process=False).export(closed)
        try:
            surface = load_surface(closed, units)
        except InputError as exc:
            raise InputError(
                f"{path.name} is still refused after --repair wrapped it with fTetWild "
                f"({exc.problem.replace(closed.name, 'the wrapped surface')})", fix) from exc
    scale = _scale(surface, vertices)
    line = (f"--repair: wrapped by fTetWild's winding-number test ({wrapped.non_manifold_edges} "
            f"non-manifold edges resolved, {wrapped.pinches} touching vertices split, "
            f"{wrapped.faces_before} -> {wrapped.faces_after} "
            f"faces, volume {wrapped.volume_before * scale**3:.0f} -> "
            f"{surface.volume_mm3:.0f} mm^3)")
    return replace(surface, source=path, notes=(line, *surface.notes))


def repair_offer(path: str | Path, units: str | ModelConfig, refusal: InputError
                 ) -> InputError:
    """The refusal of an open or non-manifold surface with ``--repair`` as its fix where the
    repair was tried here and works; ``refusal`` unchanged otherwise.

    A non-manifold surface is wrapped in a child process given ``OFFER_SECONDS`` (fTetWild's
    time grows with the input's faces); past that the refusal says ``--repair`` was not
    checked, beside its fix."""
    kind = _repairable(refusal)
    if kind is None:
        return refusal
    if kind == "open":
        try:
            what = load_repaired(path, units).notes[0]
        except InputError:
            return refusal
    else:
        checked = _wrap_within(Path(path), units, OFFER_SECONDS)
        if checked is None:
            return refusal
        what = checked
        if what == _TIMED_OUT:
            return InputError(refusal.problem, f"{refusal.fix}; or try --repair (fTetWild's "
                              f"wrap: not checked here, it takes over {OFFER_SECONDS:.0f} s "
                              "on this mesh)")
    return InputError(refusal.problem,
                      f"re-run with --repair (checked: it {what.removeprefix('--repair: ')})")


def _wrap_note(path: Path, units: str | ModelConfig, queue: Any) -> None:
    """Child process: ``load_repaired``'s first note, or None where it is refused."""
    try:
        queue.put(load_repaired(path, units).notes[0])
    except InputError:
        queue.put(None)


def _wrap_within(path: Path, units: str | ModelConfig, seconds: float) -> str | None:
    """``load_repaired``'s first note (None: refused), or ``_TIMED_OUT`` after ``seconds``."""
    context = multiprocessing.get_context("spawn")  # fork would inherit fTetWild's threads
    queue = context.Queue()
    child = context.Process(target=_wrap_note, args=(path, units, queue), daemon=True)
    child.start()
    try:
        note: str | None = queue.get(timeout=seconds)
    except queue_module.Empty:
        note = _TIMED_OUT
    finally:
        if child.is_alive():
            child.kill()
        child.join()
    return note
