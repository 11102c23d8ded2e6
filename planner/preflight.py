"""Preflight: does a model fit the cell, do its units look right, which surfaces are critical.

Answers in seconds, from the surface alone (no tet mesh, no slicing), what a user wants to
know before a slice of minutes: whether the part fits the tank (footprint at some rotation
within the wall margin, height under the gel), whether the arm reaches it (the nozzle held
vertical at the corners of the part's box and at points spread over its top, the part at
the tank centre, every check of the planner: inverse kinematics, joint limits, singularity,
clearance), whether the size suggests other units (a part of 8 mm or of 8 m is read as mm
by mistake more often than it is meant), and which boundary patches the critical-surface
selectors would pick (``slicer.critical`` on the surface's faces; the tet mesh's boundary
follows the surface to within fTetWild's envelope). Each answer is a ``Finding``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import cast

import numpy as np

from core.stages import Toolpath
from planner.cell import CellConfig
from planner.nozzle_axis import tool_rotation
from planner.placement import _fits, fit_gel, model_transform
from planner.preflight_walls import walls_text
from planner.reach import COLLISION, OK, REASONS, Reach
from slicer.config import UNIT_SCALE_MM, JobConfig
from slicer.critical import CriticalSelection, select_critical_regions
from slicer.mesh_io import Surface
from slicer.operators import BoundaryFaces, TetOperators
from slicer.wall_thickness import wall_thickness

# smaller than this (mm, largest extent) a part is a few filaments across: likely in cm or in
SMALL_PART_MM = 10.0
TOP_POINTS = 48  # surface points near the top whose reach is checked (plus the box corners)
YAW_STEP_DEG = 15.0  # footprint rotations tried for the fit
MAX_PATCH_FACES = 100_000  # faces of the subdivided surface the regions are selected on
EQUILATERAL = np.sqrt(3.0) / 4.0  # area of an equilateral triangle of unit edge


@dataclass(frozen=True)
class Finding:
    """One answer of the preflight.

    Attributes:
        topic: "size", "units", "tank", "gel", "reach", "walls" or "critical".
        ok: nothing to fix.
        text: the answer in one line (with the fix where not ok).
    """

    topic: str
    ok: bool
    text: str


@dataclass(frozen=True)
class Preflight:
    """All findings, and the critical regions (for the figure).

    Attributes:
        findings: in the order size, units, tank, gel, reach, walls, critical.
        selection: the regions the job's selectors pick on ``patches``.
        patches: the surface subdivided to the tet mesh's edge length (``fine_surface``),
            on which the regions were selected.
        face_region: (F,) int64, region index of each face of ``patches``, -1 for none.
    """

    findings: tuple[Finding, ...]
    selection: CriticalSelection
    patches: Surface
    face_region: np.ndarray

    @property
    def ok(self) -> bool:
        """Every finding is fine."""
        return all(f.ok for f in self.findings)


def surface_operators(surface: Surface) -> TetOperators:
    """The surface's faces as the boundary ``select_critical_regions`` reads (no tets)."""
    tri = surface.vertices[surface.faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(cross, axis=1)
    normal = cross / np.where(norm > 0, norm, 1.0)[:, None]
    boundary = BoundaryFaces(surface.faces.astype(np.int64), normal, 0.5 * norm,
                             np.full(len(surface.faces), -1, dtype=np.int64))

    class _Ops:  # the two attributes the selection reads
        vertices = surface.vertices

    ops = _Ops()
    ops.boundary = boundary  # type: ignore[attr-defined]
    return cast(TetOperators, ops)


def fine_surface(surface: Surface, edge_mm: float) -> Surface:
    """The surface with every edge split down to ``edge_mm`` (shape unchanged): the tet
    mesh's boundary has faces of about that size, and a region needs a few faces
    (``critical.MIN_REGION_FACES``) to count, so CAD exports with large triangles are
    selected on faces like the slicer's. At most about ``MAX_PATCH_FACES`` faces (a longer
    edge on a large surface: the answer stays within seconds)."""
    import trimesh

    tri = surface.vertices[surface.faces]
    area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                                      axis=1).sum())
    edge = max(edge_mm, float(np.sqrt(area / (EQUILATERAL * MAX_PATCH_FACES))))
    v, f = trimesh.remesh.subdivide_to_size(surface.vertices, surface.faces, max_edge=edge,
                                            max_iter=20)
    return replace(surface, vertices=v, faces=f)


def fits_tank(cell: CellConfig, size: np.ndarray) -> float | None:
    """The first yaw (deg) at which a box of ``size`` (3,) mm fits inside the tank walls
    (``wall_margin_mm``) at the tank centre; None if none does."""
    box = (np.zeros(3), np.asarray(size, dtype=float))
    for yaw in np.arange(0.0, 180.0, YAW_STEP_DEG):
        if _fits(cell, box, np.zeros(2), float(yaw)):
            return float(yaw)
    return None


def fits_gel(cell: CellConfig, height: float) -> bool:
    """The part, lifted by the placement's offset, stays under the tank's highest gel."""
    return cell.placement.offset_mm[2] + height <= cell.tank.gel_fill_mm


def _reach_points(surface: Surface) -> np.ndarray:
    """(K, 3) mm, model frame: the 8 corners of the box and points spread over the top."""
    v = surface.vertices
    lo, hi = v.min(axis=0), v.max(axis=0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    top = v[v[:, 2] >= lo[2] + 0.8 * (hi[2] - lo[2])]
    if len(top) > TOP_POINTS:
        top = top[np.linspace(0, len(top) - 1, TOP_POINTS).round().astype(int)]
    return np.vstack([corners, top])


def reach_check(cell: CellConfig, surface: Surface, spins: int = 12) -> tuple[int, int, str]:
    """(unreached points, points, the first one's reason): the nozzle vertical at
    ``_reach_points``, the part at the tank centre, the gel filled to cover it, any spin."""
    v = surface.vertices
    lo, hi = v.min(axis=0), v.max(axis=0)
    # the gel level of the job (fit_gel reads the toolpath's box only)
    box = Toolpath(position=np.vstack([lo, hi]), normal=np.tile([0.0, 0.0, 1.0], (2, 1)),
                   layer=np.zeros(2, np.int32), path=np.zeros(2, np.int32),
                   height=np.ones(2), width=np.ones(2), speed=np.ones(2),
                   extrude=np.zeros(2, bool), pattern=np.zeros(2, np.int8))
    job_cell = fit_gel(cell, box)
    reach = Reach(job_cell)
    T = model_transform(job_cell, (lo, hi), np.array([0.0, 0.0, cell.placement.offset_mm[2]]),
                        0.0)
    p = _reach_points(surface) @ T[:3, :3].T + T[:3, 3]
    grid = np.linspace(-np.pi, np.pi, spins, endpoint=False)
    axis = np.tile([0.0, 0.0, -1.0], (len(p) * spins, 1))
    q = reach.solve(np.repeat(p, spins, axis=0), tool_rotation(axis, np.tile(grid, len(p))),
                    reach.home)
    ev = reach.check(q, iters=8)
    status = ev.status.reshape(len(p), spins)
    bad = ~(status == OK).any(axis=1)
    why = ""
    if bad.any():
        first = status[np.flatnonzero(bad)[0]]
        code = int(np.bincount(first[first != OK]).argmax())
        why = REASONS[code]
        pair = ev.pair.reshape(len(p), spins)[np.flatnonzero(bad)[0]].max()
        if code == COLLISION and pair >= 0:
            why += f" ({reach.collision.names[int(pair)]})"
    return int(bad.sum()), len(p), why


def _units(size_mm: float, given: str, cell: CellConfig) -> Finding:
    """Whether the size looks like a unit mistake, and which --units would fit the cell."""
    raw = size_mm / UNIT_SCALE_MM[given]
    fitting = [u for u, s in UNIT_SCALE_MM.items()
               if u != given and SMALL_PART_MM <= raw * s
               and raw * s <= min(cell.tank.inner_size_mm[:2])]
    if size_mm < SMALL_PART_MM or size_mm > min(cell.tank.inner_size_mm[:2]):
        what = "small" if size_mm < SMALL_PART_MM else "large"
        hint = (f"; if the file is not in {given}, say so: " + ", ".join(
            f"--units {u} makes it {raw * UNIT_SCALE_MM[u]:.0f} mm" for u in fitting)
            if fitting else "; scale the model in a CAD tool")
        return Finding("units", False, f"{size_mm:.4g} mm across (read as {given}) is "
                                       f"{what} for this cell{hint}")
    return Finding("units", True, f"read as {given}: {size_mm:.1f} mm across, a plausible size")


def preflight(surface: Surface, job: JobConfig, cell: CellConfig, line_width_mm: float,
              other_cells: dict[str, CellConfig] | None = None) -> Preflight:
    """The findings for ``surface`` sliced with ``job`` and planned in ``cell`` (see module
    docstring) with lines ``line_width_mm`` wide (the job's profile at its layer height);
    ``other_cells`` (name -> cell) are checked for the fit where ``cell`` fails."""
    size = np.asarray(surface.bbox_mm)
    found = [Finding("size", True, f"{size[0]:.1f} x {size[1]:.1f} x {size[2]:.1f} mm, "
                                   f"{surface.volume_mm3 / 1000:.1f} cm^3")]
    found.append(_units(float(size.max()), job.model.units, cell))
    tank = cell.tank
    yaw = fits_tank(cell, size)
    alt = other_cells or {}

    def elsewhere(test: str) -> str:
        names = [n for n, c in alt.items()
                 if (fits_tank(c, size) is not None if test == "tank" else
                     fits_gel(c, float(size[2])))]
        return f"; it fits the bundled {', '.join(names)} cell" if names else ""

    inner = f"{tank.inner_size_mm[0]:.0f} x {tank.inner_size_mm[1]:.0f} mm"
    if yaw is None:
        found.append(Finding("tank", False, f"the footprint does not fit the {inner} tank "
                                            f"(wall margin {cell.placement.wall_margin_mm:g} "
                                            f"mm) at any rotation{elsewhere('tank')}"))
    else:
        found.append(Finding("tank", True, f"fits the {inner} tank"
                                           + (f" turned {yaw:.0f} deg" if yaw else "")))
    lift = cell.placement.offset_mm[2]
    if fits_gel(cell, float(size[2])):
        found.append(Finding("gel", True, f"{size[2]:.1f} mm tall + {lift:g} mm lift, under "
                                          f"the {tank.gel_fill_mm:g} mm of gel the tank holds"))
    else:
        found.append(Finding("gel", False, f"{size[2]:.1f} mm tall + {lift:g} mm lift rises "
                                           f"above the {tank.gel_fill_mm:g} mm of gel the tank "
                                           f"holds{elsewhere('gel')}"))
    if yaw is not None and fits_gel(cell, float(size[2])):
        bad, total, why = reach_check(cell, surface)
        found.append(Finding("reach", bad == 0,
                             f"the nozzle reaches all {total} checked points (box corners, "
                             "top), held vertical, the part at the tank centre" if not bad else
                             f"{bad} of {total} checked points (box corners, top) out of reach "
                             f"with the nozzle vertical at the tank centre: {why}; move the "
                             "tank or the robot base ([tank] floor_center_mm, [robot] "
                             "base_xyz_mm) or use a smaller model"))
    found.append(Finding("walls", *walls_text(
        wall_thickness(surface), line_width_mm,
        lambda k: (fits_tank(cell, size * k) is not None and fits_gel(cell, float(size[2] * k))
                   and float(size.max() * k) <= job.model.max_size_mm))))
    fine = fine_surface(surface, job.mesh.edge_length_mm)
    selection = select_critical_regions(surface_operators(fine), job.slicing.selectors)
    face_region = np.full(len(fine.faces), -1, dtype=np.int64)
    for k, r in enumerate(selection.regions):
        face_region[r.faces] = k
    regions = selection.regions
    if regions:
        total_area = float(np.sum([r.area for r in regions]))
        lines = "; ".join(
            f"{r.selector} {r.area:.0f} mm^2 at z {fine.vertices[r.vertices, 2].mean():.1f}"
            for r in regions[:6]) + (f"; {len(regions) - 6} more" if len(regions) > 6 else "")
        text = (f"{len(regions)} critical region{'s' if len(regions) != 1 else ''} "
                f"({total_area:.0f} mm^2): {lines}")
    else:
        text = "no critical region: the layers follow the field without a fixed surface"
    found.append(Finding("critical", True, text + "".join(f" ({n})" for n in selection.notes)))
    return Preflight(tuple(found), selection, fine, face_region)

