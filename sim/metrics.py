"""Print quality of a simulated deposit against the model (paper section 5.3).

Definitions (f = ink fraction of a voxel, clipped to 1; m = model fraction of a voxel: 1 inside,
0 outside and, in the one-voxel band around the model surface, 1/2 - signed distance / voxel,
so a surface through voxel centres is not counted as a whole voxel in or out; V_m = sum of m):

* infill ratio = sum of min(f, m) / V_m (ink within the model's share of each voxel).
* interior infill ratio = the same over the voxels at least ``interior_depth_mm`` inside the
  model surface (every voxel of the cube of that half-width around them inside): the density
  of the part's core, the number a CT porosity analysis gives (paper: 99.47 %), free of the
  surface's roughness and offset, which on a small part dominate the infill ratio (a 0.25 mm
  scalloped skin on a 20 mm cube is about 4 % of its volume).
* pore ratio = gel volume inside the printed body / V_m, where the printed body is the solid
  (f >= 0.5) closed over narrow openings (``scan_bridge_mm``) with its cavities filled, minus
  its one-voxel skin (a CT sees the skin's partial voxels as surface roughness, not
  porosity), and only where the model is solid; the gel there is sum of (1 - f). A cavity of
  the design (space the model encloses, like the membrane's air chamber) is not filled: gel
  connected to it is that cavity's surface, as gel connected to the outside is the outer
  surface (grooves between the filaments of a cavity's ceiling are surface error, not pores).
* over-deposition = ink beyond the model's share (sum of f - min(f, m)) / V_m;
  under-deposition = 1 - infill ratio.
* surface error: distance from the printed body's surface (the f = 0.5 iso-surface of the
  printed body above, at sub-voxel precision; what a 3D scanner sees, the walls of a designed
  cavity included, as a CT would) to the model surface:
  mean, p95, max of its absolute value (mm), computed exactly against the model triangles;
  and split by where the model surface faces (up, side, down: ``SurfaceError.by_facing``),
  with the signed mean of each, which shows a systematic bulge or shortfall.
* error map: at points on the model surface, the signed distance to the printed surface
  (> 0 where ink lies outside the model, < 0 where the print falls short).
* per layer: every voxel is attributed to the layer that brought most of its ink, or, if it has
  no ink, to the layer of the nearest extruding waypoint.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy import ndimage
from scipy.spatial import cKDTree

from core.stages import Toolpath
from sim.deposition import Deposit
from sim.voxels import VoxelGrid, closing_cube, fill_enclosed, iso_points, voxelize_mesh

FACING_DEG = 45.0  # a model face within this of +z is "up", of -z "down", else "side"


@dataclass(frozen=True, eq=False)
class SurfaceError:
    """Distances between the printed and the model surface.

    Attributes:
        points: (P, 3) float64, mm, points of the printed surface (outer, and of designed cavities).
        distance: (P,) float64, mm, signed distance of each point to the model surface
            (> 0 outside the model).
        map_points: (Q, 3) float64, mm, sample points on the model surface.
        map_distance: (Q,) float64, mm, signed distance from each to the printed surface
            (> 0 where the print bulges out, < 0 where it falls short).
        facing_z: (P,) float64, z component of the model's outward unit normal at the model
            point closest to each printed point (+1 on a top face, -1 on a bottom face; the
            model frame's z is up in the tank). Empty when not computed.
    """

    points: NDArray[np.float64]
    distance: NDArray[np.float64]
    map_points: NDArray[np.float64]
    map_distance: NDArray[np.float64]
    facing_z: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))

    def stats(self) -> dict[str, float]:
        """mean, p95, max of |distance| and the signed mean (mm)."""
        a = np.abs(self.distance)
        if a.size == 0:
            return {"mean": 0.0, "p95": 0.0, "max": 0.0, "signed_mean": 0.0}
        return {"mean": float(a.mean()), "p95": float(np.percentile(a, 95)),
                "max": float(a.max()), "signed_mean": float(self.distance.mean())}

    def by_facing(self) -> dict[str, dict[str, float]]:
        """The error split by where the model surface faces: ``up`` (normal within
        FACING_DEG of +z), ``down`` (of -z) and ``side`` (the rest). Per class: ``share`` of
        the printed surface points, ``mean`` |distance| and ``signed_mean`` (mm, > 0: the
        print bulges out there), and ``contribution`` to the overall mean (mm; the three add
        up to it). A systematic bias shows here that the overall mean averages away: ink
        displaced from where round filaments cannot reach (bottom grooves, edges) piling up
        on the top faces."""
        if self.facing_z.size != self.distance.size or self.distance.size == 0:
            return {}
        c = float(np.cos(np.radians(FACING_DEG)))
        classes = {"up": self.facing_z > c, "side": np.abs(self.facing_z) <= c,
                   "down": self.facing_z < -c}
        n = self.distance.size
        out: dict[str, dict[str, float]] = {}
        for name, sel in classes.items():
            d = self.distance[sel]
            if d.size == 0:
                out[name] = {"share": 0.0, "mean": 0.0, "signed_mean": 0.0,
                             "contribution": 0.0}
                continue
            out[name] = {"share": d.size / n, "mean": float(np.abs(d).mean()),
                         "signed_mean": float(d.mean()),
                         "contribution": float(np.abs(d).sum() / n)}
        return out


@dataclass(frozen=True, eq=False)
class LayerQuality:
    """Over/under-deposition per layer.

    Attributes:
        layer: (L,) int32, layer indices.
        model_mm3: (L,) float64, mm^3, model volume attributed to the layer.
        under_mm3: (L,) float64, mm^3, unfilled model volume attributed to the layer.
        over_mm3: (L,) float64, mm^3, ink outside the model attributed to the layer.
    """

    layer: NDArray[np.int32]
    model_mm3: NDArray[np.float64]
    under_mm3: NDArray[np.float64]
    over_mm3: NDArray[np.float64]

    def ratios(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(under, over) per layer relative to the layer's model volume (0 where it has none)."""
        den = np.where(self.model_mm3 > 0, self.model_mm3, np.inf)
        return self.under_mm3 / den, self.over_mm3 / den


@dataclass(frozen=True, eq=False)
class Quality:
    """The inspection of one deposit.

    Attributes:
        infill_ratio, pore_ratio, over_deposition, under_deposition: float, see module doc.
        interior_infill_ratio: float, see module doc (nan when no voxel is that deep).
        interior_depth_mm: float, mm, the depth of the interior.
        model_mm3: float, mm^3, model volume on the grid.
        model_mesh_mm3: float, mm^3, exact volume of the model mesh.
        deposited_mm3: float, mm^3, ink on the grid.
        inside: (nx, ny, nz) bool, voxels at least half inside the model.
        model: (nx, ny, nz) float32, model fraction m of each voxel.
        body: (nx, ny, nz) bool, printed body (solid with enclosed cavities filled).
        pores: (nx, ny, nz) bool, voxels of the body's interior that are mostly gel.
        surface: SurfaceError.
        layers: LayerQuality, or None without a toolpath.
    """

    infill_ratio: float
    interior_infill_ratio: float
    interior_depth_mm: float
    pore_ratio: float
    over_deposition: float
    under_deposition: float
    model_mm3: float
    model_mesh_mm3: float
    deposited_mm3: float
    inside: NDArray[np.bool_]
    model: NDArray[np.float32]
    body: NDArray[np.bool_]
    pores: NDArray[np.bool_]
    surface: SurfaceError
    layers: LayerQuality | None

    def summary(self) -> dict[str, Any]:
        """The report.json view (mm, mm^3, ratios)."""
        out: dict[str, Any] = {
            "infill_ratio": self.infill_ratio,
            "interior_infill_ratio": self.interior_infill_ratio,
            "interior_depth_mm": self.interior_depth_mm,
            "pore_ratio": self.pore_ratio,
            "over_deposition": self.over_deposition,
            "under_deposition": self.under_deposition,
            "surface_error_mm": self.surface.stats(),
            "surface_error_by_facing": self.surface.by_facing(),
            "model_volume_mm3": self.model_mm3,
            "deposited_volume_mm3": self.deposited_mm3,
        }
        if self.layers is not None:
            under, over = self.layers.ratios()
            out["per_layer"] = {
                "layer": self.layers.layer.tolist(),
                "model_mm3": np.round(self.layers.model_mm3, 4).tolist(),
                "under": np.round(under, 5).tolist(),
                "over": np.round(over, 5).tolist(),
            }
        return out


def inspect_deposit(deposit: Deposit, vertices: NDArray[np.float64],
                    faces: NDArray[np.integer], toolpath: Toolpath | None = None,
                    map_samples: int = 20_000, seed: int = 0,
                    scan_bridge_mm: float = 0.5, interior_depth_mm: float = 1.0) -> Quality:
    """Measure ``deposit`` against the closed model surface ``vertices`` (V, 3) mm, ``faces``.

    Args:
        deposit: the simulated print; its grid must cover the model.
        vertices, faces: the model surface in the toolpath's frame.
        toolpath: for the per-layer attribution (optional).
        map_samples: number of points of the error map on the model surface.
        seed: of the surface sampling.
        scan_bridge_mm: float, mm, channels up to about twice this wide that open to the outside
            count as pores, not as surface (a scanner bridges them).
        interior_depth_mm: float, mm, depth below the model surface of the interior whose
            infill is reported separately.
    """
    grid = deposit.grid
    vv = grid.voxel_volume
    f = np.minimum(deposit.fill, 1.0)
    mesh = trimesh.Trimesh(vertices=np.asarray(vertices, dtype=np.float64),
                           faces=np.asarray(faces, dtype=np.int64), process=False)
    m = model_fraction(mesh, grid)
    inside = m >= 0.5
    model = float(m.sum(dtype=np.float64)) * vv
    if model <= 0:
        raise ValueError("the model covers no voxel centre: grid too coarse or misplaced")
    shared = np.minimum(f, m)
    filled_in = float(shared.sum(dtype=np.float64)) * vv
    interior = _interior(inside, round(interior_depth_mm / grid.voxel))
    deep = float(m[interior].sum(dtype=np.float64))
    interior_infill = (float(shared[interior].sum(dtype=np.float64)) / deep if deep > 0
                       else float("nan"))
    ink_out = float((deposit.fill - shared).sum(dtype=np.float64)) * vv
    solid = deposit.fill >= 0.5
    # Like a scan: openings narrower than ~2 * scan_bridge_mm are bridged, then cavities
    # filled, except the cavities of the design (the membrane's air chamber): gel connected
    # to one is that cavity's surface, as gel connected to the outside is the outer surface
    bridge = round(scan_bridge_mm / grid.voxel)
    cavity = fill_enclosed(inside) & ~inside
    body = fill_enclosed(closing_cube(solid, bridge) | solid, cavity if cavity.any() else None)
    # gel counts only where the model is solid (a print that fills a designed cavity)
    core = ndimage.binary_erosion(body) & inside
    gel = np.where(core, 1.0 - f, 0.0)
    pores = core & ~solid
    pore = float(gel.sum(dtype=np.float64)) * vv
    surface = _surface_error(np.where(body & ~solid, 1.0, f), deposit, mesh, map_samples, seed)
    layers = _per_layer(deposit, m, shared, toolpath) if toolpath is not None else None
    return Quality(
        infill_ratio=filled_in / model,
        interior_infill_ratio=interior_infill,
        interior_depth_mm=float(interior_depth_mm),
        pore_ratio=pore / model,
        over_deposition=ink_out / model,
        under_deposition=1.0 - filled_in / model,
        model_mm3=model,
        model_mesh_mm3=float(abs(mesh.volume)),
        deposited_mm3=deposit.deposited_mm3,
        inside=inside,
        model=m,
        body=body,
        pores=pores,
        surface=surface,
        layers=layers,
    )


def _interior(inside: NDArray[np.bool_], depth: int) -> NDArray[np.bool_]:
    """(nx, ny, nz) bool, voxels whose (2 depth + 1)^3 neighbourhood is all inside."""
    if depth <= 0:
        return inside.copy()
    out: NDArray[np.bool_] = ndimage.minimum_filter(inside.view(np.uint8), size=2 * depth + 1,
                                                    mode="constant", cval=0).astype(bool)
    return out


def _signed_distance(points: NDArray[np.float64], mesh: trimesh.Trimesh) -> NDArray[np.float64]:
    """(P,) float64, mm, signed distance of points to the mesh, > 0 outside
    (``_signed_distance_faces`` without the faces)."""
    return _signed_distance_faces(points, mesh)[0]


def _signed_distance_faces(points: NDArray[np.float64], mesh: trimesh.Trimesh
                           ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """(P,) float64, mm, signed distance of points to the mesh, > 0 outside, and (P,) int64,
    the face holding each point's closest mesh point.

    The sign comes from the closest point's angle-weighted pseudonormal on a closed,
    consistently wound mesh (every model that passed the slicer's checks): the same signs as
    the winding number there, 12 times faster (socket, 200k points: 0.39 s against 4.6 s);
    otherwise from the winding number.
    """
    if len(points) == 0:
        return np.zeros(0), np.zeros(0, dtype=np.int64)
    import igl

    closed = bool(mesh.is_watertight and mesh.is_winding_consistent)
    sign = igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL if closed else (
        igl.SIGNED_DISTANCE_TYPE_WINDING_NUMBER)
    s, face, _ = igl.signed_distance(np.ascontiguousarray(points, dtype=np.float64),
                                     np.ascontiguousarray(mesh.vertices, dtype=np.float64),
                                     np.ascontiguousarray(mesh.faces, dtype=np.int64),
                                     sign_type=sign)[:3]
    return np.asarray(s, dtype=np.float64), np.asarray(face, dtype=np.int64).reshape(-1)


def _surface_error(body_fill: NDArray[np.floating], deposit: Deposit, mesh: trimesh.Trimesh,
                   samples: int, seed: int) -> SurfaceError:
    grid = deposit.grid
    pts = iso_points(body_fill, grid, 0.5)
    dist, face = _signed_distance_faces(pts, mesh)
    facing_z = np.asarray(mesh.face_normals, dtype=np.float64)[face, 2] if len(face) else (
        np.zeros(0))
    rng = np.random.default_rng(seed)
    mpts, _ = trimesh.sample.sample_surface(mesh, samples, seed=int(rng.integers(1 << 31)))
    mpts = np.asarray(mpts, dtype=np.float64)
    if len(pts):
        near, _ = cKDTree(pts).query(mpts, workers=-1)
        # Inside the printed body (trilinear f >= 0.5) means the print covers the model point.
        ijk = grid.to_index_space(mpts).T
        covered = ndimage.map_coordinates(body_fill.astype(np.float32), ijk, order=1,
                                          mode="constant") >= 0.5
        mdist = np.where(covered, near, -near)
    else:
        mdist = np.full(len(mpts), -np.inf)
    return SurfaceError(points=pts, distance=dist, map_points=mpts, map_distance=mdist,
                        facing_z=facing_z)


def _per_layer(deposit: Deposit, m: NDArray[np.float32], shared: NDArray[np.float32],
               toolpath: Toolpath) -> LayerQuality:
    grid = deposit.grid
    vv = grid.voxel_volume
    tag = deposit.layer.copy()
    ext = toolpath.extrude
    layers = np.unique(toolpath.layer[ext]) if ext.any() else np.zeros(0, dtype=np.int32)
    orphan = (m > 0) & (tag < 0)
    if orphan.any() and ext.any():
        idx = np.argwhere(orphan)
        _, near = cKDTree(toolpath.position[ext]).query(grid.centers(idx), workers=-1)
        tag[orphan] = toolpath.layer[ext][near]
    n = int(max(layers.max() if layers.size else -1, tag.max())) + 1
    if n <= 0:
        z = np.zeros(0)
        return LayerQuality(np.zeros(0, dtype=np.int32), z, z, z)
    ok = tag >= 0
    t = tag[ok]
    model = np.bincount(t, weights=m[ok].astype(np.float64), minlength=n) * vv
    under = np.bincount(t, weights=(m[ok] - shared[ok]).astype(np.float64), minlength=n) * vv
    over = np.bincount(t, weights=(deposit.fill[ok] - shared[ok]).astype(np.float64),
                       minlength=n) * vv
    keep = np.flatnonzero((model > 0) | (over > 0))
    return LayerQuality(layer=keep.astype(np.int32), model_mm3=model[keep].astype(np.float64),
                        under_mm3=under[keep].astype(np.float64),
                        over_mm3=over[keep].astype(np.float64))


def model_fraction(mesh: trimesh.Trimesh, grid: VoxelGrid) -> NDArray[np.float32]:
    """(nx, ny, nz) float32, share of each voxel inside the closed ``mesh``.

    Voxel centres get the ray-parity inside test; voxels next to a voxel of the other state
    (the band the surface passes through) get 1/2 - signed distance / voxel, clipped to
    [0, 1] (exact for a plane through the voxel, parallel to a face).
    """
    inside = voxelize_mesh(mesh.vertices, mesh.faces, grid)
    frac = inside.astype(np.float32)
    edge = np.zeros_like(inside)
    for axis in range(3):
        a = [slice(None)] * 3
        b = [slice(None)] * 3
        a[axis], b[axis] = slice(None, -1), slice(1, None)
        diff = inside[tuple(a)] != inside[tuple(b)]
        edge[tuple(a)] |= diff
        edge[tuple(b)] |= diff
    idx = np.argwhere(edge)
    if len(idx):
        sd = _signed_distance(grid.centers(idx), mesh)
        frac[tuple(idx.T)] = np.clip(0.5 - sd / grid.voxel, 0.0, 1.0).astype(np.float32)
    return frac
