"""Tetrahedralisation of a closed surface with fTetWild (pytetwild), and tet-mesh quality.

``tetrahedralize`` runs fTetWild with the ``[mesh]`` settings of the job, then orients every
tet positively, drops unused vertices and measures the result (``TetStats``). With
``refine`` (default "auto": 1 for models of more than ``AUTO_REFINE_ABOVE`` tets) fTetWild
meshes at twice the edge length and every tet is split into 8 (``slicer.refine``), the new
boundary vertices snapped onto the input surface: much faster on large models, at the same
mean quality. ``grading`` hands fTetWild a sizing field that grows the edge length away from
the solid (off by default: it did not make fTetWild faster; ``bench/bench_tetwild.py``).

fTetWild is not deterministic (not even on one thread); ``cache`` makes a slice repeatable by
reading back the mesh made before for the same input and settings (``slicer.tet_cache``).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from core.errors import InputError
from core.progress import NullProgress, Progress
from core.stages import TetMesh
from core.tolerance import tol
from slicer import tet_cache
from slicer.config import MeshConfig
from slicer.tet_geometry import compact, orient_positive, tet_volumes
from slicer.tet_stats import TetStats

if TYPE_CHECKING:
    from slicer.mesh_io import Surface

# fTetWild's background mesh holds about this many tets per (edge length)^3 of box volume
# (measured: ~10 at the default settings); used to refuse absurd requests up front.
BACKGROUND_TETS_PER_EDGE3 = 10.0
MAX_BACKGROUND_TETS = 4e7
# Growth of the target edge length outside the solid (mm per mm), used when the [mesh]
# config has no ``grading`` key; 0 = fTetWild's uniform target (see the module docstring).
DEFAULT_GRADING = 0.0

# refine = "auto": one refinement where the direct mesh would have more tets than this (about
# where fTetWild starts taking tens of seconds: aorta 98k tets 100 s, actuator 200k 39 s, cube
# 7k 0.6 s). fTetWild makes ~9.5 tets per edge^3 of solid (socket: 239k at 2.95 mm).
AUTO_REFINE_ABOVE = 50_000
TETS_PER_EDGE3 = 9.5
# ... and it meshes directly instead where the refined mesh misses the solid's volume by more
# than this (direct meshes of the examples: within 0.2 %; refined: within 0.13 %)
AUTO_MAX_VOLUME_ERROR = 0.01

# A tet with a dihedral angle below this (deg) counts as a sliver in the statistics.
SLIVER_DEG = 10.0

# The pairs of faces of a tet (face k is opposite vertex k) meeting at each of its 6 edges.
_FACE_PAIRS = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])
_EDGES = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])


def quality(
    vertices: np.ndarray, tets: np.ndarray, surface_volume_mm3: float = float("nan")
) -> TetStats:
    """Size and shape statistics of a tet mesh (all vectorised over tets).

    Args:
        vertices: (V, 3) float64, mm.
        tets: (T, 4) int, positively oriented.
        surface_volume_mm3: volume of the surface that was meshed, for the volume error.
    """
    p = vertices[tets]
    volume = tet_volumes(vertices, tets)
    # Outward normal of face k (opposite vertex k); its norm is twice the face area.
    others = np.array([(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)])
    normals = np.cross(
        p[:, others[:, 1]] - p[:, others[:, 0]], p[:, others[:, 2]] - p[:, others[:, 0]]
    )  # (T, 4, 3); the orderings above make each normal point away from vertex k
    areas = 0.5 * np.linalg.norm(normals, axis=2)
    unit = normals / np.maximum(2.0 * areas, tol.zero)[:, :, None]
    cos = np.einsum("tij,tij->ti", unit[:, _FACE_PAIRS[:, 0]], unit[:, _FACE_PAIRS[:, 1]])
    dihedral = np.pi - np.arccos(np.clip(cos, -1.0, 1.0))
    lengths = np.linalg.norm(p[:, _EDGES[:, 1]] - p[:, _EDGES[:, 0]], axis=2)  # (T, 6)
    # Circumradius from the products of opposite edge lengths (edges 0-5, 1-4, 2-3).
    a = lengths[:, 0] * lengths[:, 5]
    b = lengths[:, 1] * lengths[:, 4]
    c = lengths[:, 2] * lengths[:, 3]
    heron = np.maximum((a + b + c) * (a + b - c) * (a - b + c) * (-a + b + c), 0.0)
    safe_volume = np.maximum(np.abs(volume), tol.zero)
    r_circ = np.sqrt(heron) / (24.0 * safe_volume)
    r_in = 3.0 * np.abs(volume) / np.maximum(areas.sum(axis=1), tol.zero)
    ratio = np.where(volume > 0, 3.0 * r_in / np.maximum(r_circ, tol.zero), 0.0)
    n_vertices = int(np.unique(tets).size)
    edge_keys = np.sort(tets[:, _EDGES], axis=2).astype(np.int64)
    keys = edge_keys[:, :, 0] * (int(tets.max()) + 1) + edge_keys[:, :, 1]
    _, first = np.unique(keys.ravel(), return_index=True)
    total = float(volume.sum())
    return TetStats(
        tets=len(tets),
        vertices=n_vertices,
        mean_edge_mm=float(lengths.ravel()[first].mean()),
        min_dihedral_deg=float(np.degrees(dihedral.min())),
        max_dihedral_deg=float(np.degrees(dihedral.max())),
        sliver_fraction=float(np.mean(dihedral.min(axis=1) < np.radians(SLIVER_DEG))),
        mean_quality=float(ratio.mean()),
        worst_quality=float(ratio.min()),
        volume_mm3=total,
        surface_volume_mm3=float(surface_volume_mm3),
        volume_error=float(total / surface_volume_mm3 - 1.0),
        seconds=0.0,
    )


def sizing_field(
    surface: Surface, edge_length_mm: float, grading: float, margin: float = 0.1
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A background tet grid giving fTetWild's target edge length at every point.

    The target is ``edge_length_mm`` inside the solid and within two edge lengths (plus one
    grid cell) of its surface, and grows by ``grading`` mm per mm of distance beyond that.
    The grid (~40 cells a side) only has to carry the distance, not resolve the mesh.

    Returns:
        (points (n, 3) float64 mm, tets (m, 4) int32, target edge length (n,) float64 mm).
    """
    import igl

    lo = surface.vertices.min(axis=0)
    hi = surface.vertices.max(axis=0)
    pad = margin * float(np.linalg.norm(hi - lo)) + 2.0 * edge_length_mm
    lo, hi = lo - pad, hi + pad
    step = max(float(np.max(hi - lo)) / 40.0, edge_length_mm)
    counts = np.maximum(np.ceil((hi - lo) / step).astype(int), 1)
    axes = [np.linspace(lo[i], hi[i], counts[i] + 1) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    distance, *_ = igl.signed_distance(
        grid,
        surface.vertices,
        surface.faces.astype(np.int64),
        sign_type=igl.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER,
    )
    # Grid cells are 'step' wide, so the fine band must be at least one cell wide outside.
    band = 2.0 * edge_length_mm + step
    values = edge_length_mm + grading * np.maximum(np.asarray(distance) - band, 0.0)
    return grid, _grid_tets(counts), values


def _grid_tets(counts: np.ndarray) -> np.ndarray:
    """Six tets per cell of an (nx, ny, nz)-cell grid, points in C order: (6 nx ny nz, 4) int32."""
    nx, ny, nz = (int(c) for c in counts)
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")

    def index(di: int, dj: int, dk: int) -> np.ndarray:
        return (((i + di) * (ny + 1) + (j + dj)) * (nz + 1) + (k + dk)).ravel()

    corner = [index((c >> 2) & 1, (c >> 1) & 1, c & 1) for c in range(8)]
    # Kuhn split along the main diagonal 0-7: one tet per path 0 -> 7 through the cube.
    paths = [(4, 6), (4, 5), (2, 6), (2, 3), (1, 5), (1, 3)]
    tets = np.concatenate(
        [np.stack([corner[0], corner[a], corner[b], corner[7]], axis=1) for a, b in paths]
    )
    return tets.astype(np.int32)


def refinements(config: MeshConfig, solid_volume_mm3: float) -> int:
    """Red refinements after fTetWild: ``config.refine``, or for "auto" 1 where the direct
    mesh would exceed ``AUTO_REFINE_ABOVE`` tets, else 0."""
    if config.refine != "auto":
        return int(config.refine)
    estimated = TETS_PER_EDGE3 * solid_volume_mm3 / config.edge_length_mm**3
    return 1 if estimated > AUTO_REFINE_ABOVE else 0


def tetrahedralize(
    surface: Surface,
    config: MeshConfig,
    progress: Progress | None = None,
    grading: float | None = None,
    threads: int = 0,
    cache: Path | None = None,
) -> tuple[TetMesh, TetStats]:
    """Fill a closed surface with tets of about ``config.edge_length_mm`` using fTetWild.

    Args:
        surface: closed, outward-oriented triangle surface (``slicer.mesh_io.load_surface``).
        config: target edge length and fTetWild's settings (``[mesh]`` of the job file).
        progress: receives a start note and completion.
        grading: growth (mm per mm) of the target edge length outside the solid, given to
            fTetWild as a sizing field; 0 = uniform target everywhere (fTetWild's own way).
            None = ``config.grading`` if the config has it, else ``DEFAULT_GRADING``.
        threads: fTetWild threads; 0 = all cores.
        cache: folder of stored meshes (``slicer.tet_cache``): the mesh made earlier for the
            same input and settings is read back, a new one stored; None = always mesh.

    Returns:
        The tet mesh (positively oriented tets, no unused vertices) and its statistics.

    Raises:
        InputError: fTetWild failed or produced nothing, or the request is absurdly large.
    """
    progress = progress if progress is not None else NullProgress()
    box = np.prod(surface.vertices.max(axis=0) - surface.vertices.min(axis=0))
    # (the final mesh is as large with refinements as without: the same limit)
    expected = BACKGROUND_TETS_PER_EDGE3 * box / config.edge_length_mm**3
    if expected > MAX_BACKGROUND_TETS:
        edge = config.edge_length_mm
        smallest = edge * (expected / MAX_BACKGROUND_TETS) ** (1 / 3)
        raise InputError(
            f"an edge length of {edge:g} mm would need about {expected / 1e6:.0f} M tets "
            f"for {surface.source.name}",
            f"use a larger --edge-length (at least {smallest:.2g} mm)",
        )
    if grading is None:
        grading = float(getattr(config, "grading", DEFAULT_GRADING))
    if cache is None:
        return _fresh(surface, config, grading, threads, progress)
    key = tet_cache.cache_key(surface, config, grading)
    hit = tet_cache.load(cache, key)
    if hit is not None:
        progress.update(1.0, f"{hit[1].tets} tets, {hit[1].vertices} vertices (the mesh made "
                             "before for this model and settings)")
        return hit[0], replace(hit[1], cached=True)
    mesh, stats = _fresh(surface, config, grading, threads, progress)
    tet_cache.store(cache, key, mesh, stats)
    return mesh, stats


def _fresh(surface: Surface, config: MeshConfig, grading: float, threads: int,
           progress: Progress) -> tuple[TetMesh, TetStats]:
    """A new mesh by fTetWild (and refinements, see ``tetrahedralize``)."""
    n_refine = refinements(config, surface.volume_mm3)
    if config.refine != "auto" or n_refine == 0:
        mesh, stats = _mesh(surface, config, n_refine, grading, threads, progress)
        progress.update(1.0, f"{stats.tets} tets, {stats.vertices} vertices")
        return mesh, stats
    # A feature thinner than the coarse edge (a fin, a thin wall) may not survive fTetWild at
    # twice the size: "auto" then pays for the direct mesh.
    start = time.perf_counter()
    try:
        mesh, stats = _mesh(surface, config, n_refine, grading, threads, progress)
        missed = abs(stats.volume_error) > AUTO_MAX_VOLUME_ERROR
        why = f"the refined mesh misses the volume by {100 * stats.volume_error:+.1f}%"
    except InputError as exc:
        missed, why = True, f"the coarse mesh failed ({exc})"
    if missed:
        progress.update(0.0, f"{why}: meshing directly")
        mesh, stats = _mesh(surface, config, 0, grading, threads, progress)
        stats = TetStats(**{**stats.as_dict(), "refine_fallback": True,
                            "seconds": time.perf_counter() - start})  # both attempts
    progress.update(1.0, f"{stats.tets} tets, {stats.vertices} vertices")
    return mesh, stats


def _mesh(surface: Surface, config: MeshConfig, n_refine: int, grading: float, threads: int,
          progress: Progress) -> tuple[TetMesh, TetStats]:
    """fTetWild at ``config.edge_length_mm x 2^n_refine``, then ``n_refine`` red
    refinements with the new boundary vertices snapped onto the surface."""
    import pytetwild

    edge = config.edge_length_mm * 2**n_refine
    kwargs: dict[str, Any] = {}
    if grading > 0.0:
        bg_vertices, bg_tets, bg_values = sizing_field(surface, edge, grading)
        kwargs = {"bg_vertices": bg_vertices, "bg_tets": bg_tets, "bg_values": bg_values}
    used = threads if threads > 0 else os.cpu_count() or 1
    then = f", then {n_refine} refinement{'s' if n_refine > 1 else ''}" if n_refine else ""
    progress.update(0.0, f"fTetWild, target edge {edge:g} mm, {used} threads{then}")
    start = time.perf_counter()
    # fTetWild drops debug files (__tracked_surface.stl, ...) into the working directory;
    # run it in a scratch directory so they never land in the user's (or a job) directory.
    try:
        with tempfile.TemporaryDirectory(prefix="ftetwild-") as scratch, contextlib.chdir(scratch):
            vertices, tets = pytetwild.tetrahedralize(
                # Writable copies: the extension refuses read-only arrays.
                np.array(surface.vertices, dtype=np.float64, order="C"),
                np.array(surface.faces, dtype=np.int32, order="C"),
                edge_length_abs=edge,
                epsilon=config.epsilon,
                stop_energy=config.stop_energy,
                coarsen=config.coarsen,
                num_threads=threads,
                num_opt_iter=config.optimize_iterations,
                quiet=True,
                **kwargs,
            )
    except Exception as exc:  # the C++ extension raises RuntimeError/ValueError variants
        raise InputError(
            f"fTetWild could not mesh {surface.source.name} ({type(exc).__name__}: {exc})",
            "check the surface is one clean closed solid, or try a larger --edge-length",
        ) from exc
    seconds = time.perf_counter() - start
    tets = np.asarray(tets, dtype=np.int64)
    if tets.ndim != 2 or tets.shape[1] != 4 or len(tets) == 0:
        raise InputError(
            f"fTetWild produced no tets for {surface.source.name}",
            "the solid may be thinner than the edge length: use a smaller --edge-length"
            + (" or [mesh] refine = 0" if n_refine else ""),
        )
    vertices, tets32 = compact(np.asarray(vertices, dtype=np.float64), tets)
    reoriented = int(np.count_nonzero(tet_volumes(vertices, tets32) < 0))
    tets32 = orient_positive(vertices, tets32)
    coarse_tets, snapped = len(tets32), 0.0
    for k in range(n_refine):
        from slicer.refine import boundary_vertices, red_refine, snap_boundary

        progress.update((k + 0.5) / (n_refine + 1),
                        f"refinement {k + 1}/{n_refine} of {len(tets32)} tets")
        n_old = len(vertices)
        vertices, tets32 = red_refine(vertices, tets32)
        new_boundary = boundary_vertices(tets32)
        snap = snap_boundary(vertices, tets32, new_boundary[new_boundary >= n_old],
                             surface.vertices, surface.faces)
        vertices = snap.vertices
        snapped = max(snapped, float(snap.moved_mm.max(initial=0.0)))
    mesh = TetMesh(vertices=vertices, tets=tets32)
    stats = quality(mesh.vertices, mesh.tets, surface.volume_mm3)
    return mesh, TetStats(**{**stats.as_dict(), "seconds": time.perf_counter() - start,
                             "reoriented": reoriented, "refinements": n_refine,
                             "ftetwild_tets": coarse_tets, "ftetwild_seconds": seconds,
                             "snapped_mm_max": snapped})
