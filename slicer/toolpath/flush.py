"""Flush exposed filaments: move waypoints whose filament would stick out of the model inwards.

Why: a layer is the mid-surface of a slab of height H (the iso-values sit half a layer inside
the model), but the filament printed there is h_f = H / beta tall (paper section 3.2; 2 H at
beta = 0.5), centred on the nozzle tip. Where a layer is covered on both sides by other layers
the extra height only overlaps them, and the overlapping ink fills the gaps between filaments.
Where nothing covers it (the first layer on a bottom face, the last one under a top face, the
exposed treads of a layer under a sloped surface) the filament bulges (h_f - H) / 2 out of the
model. Moving the nozzle inwards along the printing direction by that much makes the filament
flush with the surface; its ink is unchanged (same speed, width and height).

How (vectorised over waypoints; a few fixed-point iterations): for every extruding waypoint p
with unit printing direction n, the filament's top and bottom points are p +- n h_f / 2.
Their signed distance d to the model's boundary surface (> 0 outside) and the surface normal
n_s at the closest point give the move along -n (top) or +n (bottom) that brings the point
onto the surface to first order: d / max(n . n_s, COS_MIN). The move is capped at the bulge
of a slab-centred filament, (h_f - H) / 2 (times ``fraction``): anything larger comes from the
layer meeting the wall at an angle, which the contour inset handles, not a move across
layers. A waypoint sticking out on both sides (a region thinner than h_f) gets the mean of
the two moves. Travel waypoints are not moved.

Measured (hemisphere job, ecoflex-0030, 0.25 mm voxels, `sim.deposition`): pores 0.67 % ->
0.03 %, infill 97.1 % -> 97.8 %, mean surface error 0.214 -> 0.192 mm; moving only half the
bulge (``fraction = 0.5``) was no better (0.194 mm).

Along a path the moves change so little that no step leaves the plane normal to the
printing direction by more than the cell's flush step limit (``AlphaRange.flush_step_deg``,
14 deg for alpha in [70, 110]): where one waypoint alone is exposed (a tread's
edge) its full move made the nozzle dive out of the layer and back (the aorta: 0.33 mm over a
0.41 mm step, 56 deg out of that plane, beyond the planner's alpha range of 90 +- 20 deg, so
the job was refused). Each step allows a change of move of L tan(limit) less what the
step itself already climbs (a layer curling at its edge: up to 22 deg on the membrane's dome);
a move beyond that is cut back (the lower envelope; the filament there sticks out by the
difference, counted in ``residual_mm``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from core.alpha_range import AlphaRange
from core.stages import TetMesh, Toolpath
from core.tolerance import tol

# Smallest cosine between the printing direction and the surface normal used to convert a
# distance to the surface into a move along the printing direction (steeper: capped anyway).
COS_MIN = 0.5


class FilamentModel(Protocol):
    """What flushing needs from an extrusion profile (``slicer.extrusion.ExtrusionProfile``)."""

    @property
    def rate_mm3_s(self) -> float:
        """mm^3/s, constant extrusion rate C."""
        ...

    def filament_size(self, v: NDArray[np.float64]) -> tuple[NDArray[np.float64],
                                                              NDArray[np.float64]]:
        """Filament width w_f and height h_f (mm) at nozzle speed ``v`` (mm/s)."""
        ...


@dataclass(frozen=True)
class FlushReport:
    """What ``flush_toolpath`` did.

    Attributes:
        extruding: int, extruding waypoints examined.
        moved: int, waypoints moved (by more than ``min_move_mm``).
        moved_down: int, of them moved against the printing direction (top exposed).
        moved_up: int, of them moved along it (bottom exposed).
        mean_mm, p95_mm, max_mm: float, mm, size of the moves over the moved waypoints.
        capped: int, moved waypoints whose move hit the cap (h_f - H) / 2.
        residual_mm: float, mm, largest stick-out of a filament top or bottom left at the
            final positions (where the move was capped or both sides stick out).
    """

    extruding: int
    moved: int
    moved_down: int
    moved_up: int
    mean_mm: float
    p95_mm: float
    max_mm: float
    capped: int
    residual_mm: float

    def as_dict(self) -> dict[str, float | int]:
        """The report.json view (mm)."""
        return {k: (round(v, 4) if isinstance(v, float) else v)
                for k, v in self.__dict__.items()}


def boundary_surface(tetmesh: TetMesh) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The tet mesh's boundary triangles, outward oriented.

    Returns:
        vertices: (V, 3) float64, mm (all tet mesh vertices; unused ones are harmless).
        faces: (F, 3) int64, the faces that belong to exactly one tet, oriented outwards
            (tets are positively oriented, so (1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1) of
            each tet point out of it).
    """
    t = np.asarray(tetmesh.tets, dtype=np.int64)
    faces = np.concatenate([t[:, [1, 2, 3]], t[:, [0, 3, 2]], t[:, [0, 1, 3]], t[:, [0, 2, 1]]])
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    once = counts[inverse.ravel()] == 1
    return np.asarray(tetmesh.vertices, dtype=np.float64), faces[once]


def filament_height(toolpath: Toolpath, model: FilamentModel) -> NDArray[np.float64]:
    """(N,) float64, mm, filament height h_f at each waypoint's speed, area-consistent.

    The profile's (w_f, h_f) are rescaled so that pi/4 w_f h_f = C / v exactly, as in the
    deposition simulation (``sim.deposition``).
    """
    v = np.asarray(toolpath.speed, dtype=np.float64)
    safe = np.where(v > 0, v, 1.0)
    w, h = (np.broadcast_to(np.asarray(a, dtype=np.float64), v.shape)
            for a in model.filament_size(safe))
    scale = np.sqrt((model.rate_mm3_s / safe) / (0.25 * np.pi * w * h))
    return np.where(v > 0, h * scale, 0.0)


def _envelope(f: NDArray[np.float64], x: NDArray[np.float64], group: NDArray[np.int64]
              ) -> NDArray[np.float64]:
    """min_j (f_j + |x_i - x_j|) over j in i's group, for x increasing in each group (a
    one-dimensional distance transform: two cumulative minima, no loop)."""
    # groups are contiguous; an offset falling with the group keeps a minimum from carrying
    # over into the next group
    big = 2.0 * (float(np.abs(f).max()) + float(np.abs(x).max())) + 1.0
    off = big * (group.max() - group).astype(np.float64)
    fwd = np.minimum.accumulate(f - x + off) - off + x
    rev = (np.minimum.accumulate((f + x - off)[::-1]) + off[::-1])[::-1] - x
    return np.minimum(np.minimum(fwd, rev), f)


def limit_step_angle(move: NDArray[np.float64], points: NDArray[np.float64],
                normals: NDArray[np.float64], path: NDArray[np.integer],
                max_deg: float) -> NDArray[np.float64]:
    """Moves cut back so that no step of a path leaves the plane normal to the printing
    direction by more than ``max_deg``.

    Step k (waypoints k, k + 1 of one path, length L_k) allows a change of move of
    b_k = max(L_k tan(max_deg) - |(p_k+1 - p_k) . n_k|, 0): what the angle leaves once the
    step's own climb is counted. Each sign's magnitude is replaced by its lower envelope
    min_j (m_j + sum of b_k between i and j), so a spike is cut back to what its neighbours
    allow and no move grows.

    Args:
        move: (k,) float64, mm, signed move along the normal of consecutive waypoints.
        points: (k, 3) float64, mm, their positions before the moves.
        normals: (k, 3) float64, unit printing directions.
        path: (k,) int, path of each waypoint; a path is a run of equal values.
        max_deg: float, deg.

    Returns:
        (k,) float64, mm.
    """
    if len(move) == 0:
        return move
    new_group = np.r_[True, path[1:] != path[:-1]]
    group = np.cumsum(new_group) - 1
    step = points[1:] - points[:-1]
    length = np.linalg.norm(step, axis=1)
    climb = np.abs(np.einsum("ij,ij->i", step, normals[:-1]))
    budget = np.r_[0.0, np.maximum(length * np.tan(np.radians(max_deg)) - climb, 0.0)]
    budget[new_group] = 0.0
    # in the coordinate x (the budgets summed along the path) the envelope has slope 1
    x = np.cumsum(budget)
    x -= x[np.flatnonzero(new_group)][group]
    up = _envelope(np.maximum(move, 0.0), x, group)
    down = _envelope(np.maximum(-move, 0.0), x, group)
    return up - down


def flush_toolpath(toolpath: Toolpath, tetmesh: TetMesh, model: FilamentModel,
                   iterations: int = 4, min_move_mm: float = 1e-3, fraction: float = 1.0,
                   alpha: AlphaRange | None = None) -> tuple[Toolpath, FlushReport]:
    """Move extruding waypoints inwards so their filament does not stick out of the model.

    Args:
        toolpath: waypoints (positions, printing directions, speeds) in the tet mesh's frame.
        tetmesh: the sliced model; its boundary is the model surface.
        model: extrusion rate and filament size at a speed (gives h_f per waypoint).
        iterations: fixed-point iterations of the move (1 is exact for a surface normal to
            the printing direction; sloped surfaces converge geometrically).
        min_move_mm: float, mm, smaller moves are dropped (not counted, positions unchanged).
        fraction: float in [0, 1], scales the cap (h_f - H) / 2: 1 = the filament's extreme
            is flush (no ink outside the model before spreading); smaller values leave part
            of the bulge, for when the exposed filaments spread (0 = no move).
        alpha: the cell's printing-angle range (None: the bundled cell's); it limits how
            steep a step the moves may make (``AlphaRange.flush_step_deg``).

    Raises:
        ValueError: ``fraction`` outside [0, 1].

    Returns:
        The new toolpath (only ``position`` differs) and what was moved.
    """
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"fraction must be in [0, 1], got {fraction}")
    vertices, faces = boundary_surface(tetmesh)
    ext = np.asarray(toolpath.extrude, dtype=bool)
    idx = np.flatnonzero(ext)
    p = toolpath.position[idx]
    n = toolpath.normal[idx]
    half = 0.5 * filament_height(toolpath, model)[idx]
    cap = fraction * np.maximum(half - 0.5 * toolpath.height[idx], 0.0)
    down = np.zeros(len(idx))  # move against n (top sticks out)
    up = np.zeros(len(idx))  # move along n (bottom sticks out)
    active = np.flatnonzero(cap > 0)
    residual = np.zeros(len(idx))
    for _ in range(max(iterations, 1)):
        if active.size == 0:
            break
        shift = (up - down)[active, None] * n[active]
        tops = p[active] + shift + half[active, None] * n[active]
        bottoms = p[active] + shift - half[active, None] * n[active]
        d, normal = signed_distance(np.concatenate([tops, bottoms]), vertices, faces)
        m = active.size
        d_top, d_bot = d[:m], d[m:]
        c_top = np.maximum(np.einsum("ij,ij->i", normal[:m], n[active]), COS_MIN)
        c_bot = np.maximum(-np.einsum("ij,ij->i", normal[m:], n[active]), COS_MIN)
        residual[active] = np.maximum(np.maximum(d_top, d_bot), 0.0)
        down[active] = np.clip(down[active] + d_top / c_top, 0.0, cap[active])
        up[active] = np.clip(up[active] + d_bot / c_bot, 0.0, cap[active])
        # Keep iterating only where a point is still outside and the move can still grow.
        still = ((d_top > min_move_mm) & (down[active] < cap[active])) | (
            (d_bot > min_move_mm) & (up[active] < cap[active]))
        active = active[still]
    both = (down > 0) & (up > 0)
    net = np.where(both, 0.5 * (up - down), up - down)
    net = limit_step_angle(net, p, n, np.asarray(toolpath.path)[idx],
                           (alpha or AlphaRange.bundled()).flush_step_deg)
    net = np.where(np.abs(net) >= min_move_mm, net, 0.0)
    position = toolpath.position.copy()
    position[idx] = p + net[:, None] * n
    moved = net != 0
    # The stick-out left at the final positions (capped moves, thin regions).
    check = np.flatnonzero(moved | (residual > 0))
    residual[:] = 0.0
    if check.size:
        q = position[idx[check]]
        off = half[check, None] * n[check]
        d, _ = signed_distance(np.concatenate([q + off, q - off]), vertices, faces)
        residual[check] = np.maximum(np.maximum(d[:check.size], d[check.size:]), 0.0)
    size = np.abs(net[moved])
    report = FlushReport(
        extruding=len(idx),
        moved=int(moved.sum()),
        moved_down=int((net < 0).sum()),
        moved_up=int((net > 0).sum()),
        mean_mm=float(size.mean()) if size.size else 0.0,
        p95_mm=float(np.percentile(size, 95)) if size.size else 0.0,
        max_mm=float(size.max()) if size.size else 0.0,
        capped=int((moved & (np.abs(net) >= cap - tol.slack)).sum()),
        residual_mm=float(residual.max()) if residual.size else 0.0,
    )
    fields = toolpath.arrays()
    fields["position"] = position
    return Toolpath(**fields), report


def signed_distance(points: NDArray[np.float64], vertices: NDArray[np.float64],
                     faces: NDArray[np.int64]) -> tuple[NDArray[np.float64],
                                                        NDArray[np.float64]]:
    """Signed distance (> 0 outside, mm) of (P, 3) points and the unit outward normal there."""
    import igl

    sd, _, _, normal = igl.signed_distance(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(vertices, dtype=np.float64),
        np.ascontiguousarray(faces, dtype=np.int64),
        igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)
    normal = np.asarray(normal, dtype=np.float64)
    norm = np.linalg.norm(normal, axis=1, keepdims=True)
    return np.asarray(sd, dtype=np.float64), normal / np.where(norm > 0, norm, 1.0)
