"""A regular voxel grid and the vectorised raster operations on it.

The grid is axis-aligned in the model frame (mm). Voxel ``(i, j, k)`` spans
``origin + [i, i+1) * voxel`` (likewise j, k) and its centre is ``origin + (i + 0.5) * voxel``.
Fields on the grid are C-ordered ``(nx, ny, nz)`` arrays, so the flat index of ``(i, j, k)`` is
``(i * ny + j) * nz + k``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from core.errors import InputError
from core.tolerance import tol

# Largest grid the inspection builds (voxels); above it memory (several float32/int32 fields)
# and the distance transforms get too heavy for a workstation.
MAX_VOXELS = 120_000_000

# Column rays of the inside test are shifted by these fractions of a voxel so they do not pass
# exactly through mesh vertices or edges lying on "nice" coordinates (parity would double count).
_RAY_JITTER = (1.0e-6 * np.sqrt(2.0), 1.0e-6 * np.sqrt(3.0))


@dataclass(frozen=True)
class VoxelGrid:
    """An axis-aligned regular grid.

    Attributes:
        origin: (3,) float, mm, min corner of voxel (0, 0, 0).
        voxel: float, mm, edge length of a (cubic) voxel.
        shape: (nx, ny, nz) number of voxels per axis.
    """

    origin: tuple[float, float, float]
    voxel: float
    shape: tuple[int, int, int]

    def __post_init__(self) -> None:
        if not self.voxel > 0:
            raise ValueError(f"voxel must be > 0, got {self.voxel}")
        if len(self.shape) != 3 or min(self.shape) < 1:
            raise ValueError(f"shape must be three positive counts, got {self.shape}")

    @staticmethod
    def around(lo: NDArray[np.float64], hi: NDArray[np.float64], voxel: float,
               pad: float = 0.0, max_voxels: int = MAX_VOXELS) -> VoxelGrid:
        """The grid of ``voxel`` covering the box ``[lo, hi]`` (mm) grown by ``pad`` mm.

        Voxel corners lie on the lattice of multiples of ``voxel`` in the model frame.

        Raises:
            InputError: the grid would exceed ``max_voxels``.
        """
        # Snap to the model frame's lattice of voxel corners (multiples of ``voxel``), so the
        # same model point always falls at the same place in its voxel, whatever the job box.
        lo = np.floor((np.asarray(lo, dtype=np.float64) - pad) / voxel) * voxel
        hi = np.asarray(hi, dtype=np.float64) + pad
        shape = np.maximum(np.ceil((hi - lo) / voxel - tol.slack).astype(np.int64), 1)
        count = int(np.prod(shape))
        if count > max_voxels:
            suggest = voxel * (count / max_voxels) ** (1.0 / 3.0) * 1.05
            raise InputError(
                f"a {voxel:g} mm voxel grid over this job has {count:,} voxels "
                f"(limit {max_voxels:,})",
                f"use --voxel {suggest:.2f} or larger",
            )
        origin = lo
        return VoxelGrid(
            origin=(float(origin[0]), float(origin[1]), float(origin[2])),
            voxel=float(voxel),
            shape=(int(shape[0]), int(shape[1]), int(shape[2])),
        )

    @property
    def size(self) -> int:
        """Number of voxels."""
        return int(np.prod(self.shape))

    @property
    def voxel_volume(self) -> float:
        """mm^3 of one voxel."""
        return self.voxel**3

    @property
    def origin_array(self) -> NDArray[np.float64]:
        """(3,) float64, mm, the origin as an array."""
        return np.asarray(self.origin, dtype=np.float64)

    def axis_centers(self, axis: int) -> NDArray[np.float64]:
        """(n_axis,) float64, mm, voxel-centre coordinates along one axis."""
        steps = np.arange(self.shape[axis], dtype=np.float64) + 0.5
        return np.float64(self.origin[axis]) + steps * np.float64(self.voxel)

    def centers(self, ijk: NDArray[np.integer]) -> NDArray[np.float64]:
        """(n, 3) float64, mm, centres of the voxels ``ijk`` ((n, 3) int)."""
        return self.origin_array + (np.asarray(ijk, dtype=np.float64) + 0.5) * self.voxel

    def to_index_space(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n, 3) float64, continuous voxel coordinates: voxel centres sit at integers."""
        out: NDArray[np.float64] = (np.asarray(points, dtype=np.float64) - self.origin_array
                                    ) / self.voxel - 0.5
        return out

    def bounds(self) -> NDArray[np.float64]:
        """(2, 3) float64, mm, min and max corner of the grid."""
        lo = self.origin_array
        out: NDArray[np.float64] = np.stack([lo, lo + np.asarray(self.shape) * self.voxel])
        return out


def ragged_boxes(lo: NDArray[np.int64], hi: NDArray[np.int64]
                 ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Enumerate all integer cells of many boxes at once.

    Args:
        lo: (K, d) int64, first cell of each box (inclusive).
        hi: (K, d) int64, last cell of each box (inclusive); empty where hi < lo.

    Returns:
        owner: (M,) int64, box index of each enumerated cell.
        cell: (M, d) int64, the cell.
    """
    dims = np.maximum(hi - lo + 1, 0)
    count = np.prod(dims, axis=1)
    owner = np.repeat(np.arange(len(lo)), count)
    if owner.size == 0:
        return owner, np.zeros((0, lo.shape[1]), dtype=np.int64)
    first = np.cumsum(count) - count
    offset = np.arange(owner.size, dtype=np.int64) - first[owner]
    cell = np.empty((owner.size, lo.shape[1]), dtype=np.int64)
    # Decode the mixed-radix offset, last axis fastest.
    for axis in range(lo.shape[1] - 1, -1, -1):
        d = dims[owner, axis]
        cell[:, axis] = offset % d + lo[owner, axis]
        offset //= d
    return owner, cell


def voxelize_mesh(vertices: NDArray[np.float64], faces: NDArray[np.integer], grid: VoxelGrid,
                  batch: int = 2_000_000) -> NDArray[np.bool_]:
    """Inside test of every voxel centre against a closed triangle mesh (ray parity along z).

    Every triangle is rasterised onto the (x, y) columns of voxel centres whose projection it
    covers; each crossing toggles the parity of all voxel centres above it in that column, and a
    cumulative parity along z gives the inside mask. Vectorised over triangles and columns.

    Args:
        vertices: (V, 3) float64, mm, closed (watertight) surface.
        faces: (F, 3) int, triangles.
        grid: the grid.
        batch: upper bound on triangle-column candidates handled at once (memory).

    Returns:
        (nx, ny, nz) bool, True where the voxel centre is inside the surface.
    """
    nx, ny, nz = grid.shape
    vox = grid.voxel
    org = grid.origin_array
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]  # (F, 3, 3)
    # Column coordinates in index space; columns sit at integers + jitter.
    q = (tri - org) / vox - 0.5
    qx, qy = q[..., 0] - _RAY_JITTER[0], q[..., 1] - _RAY_JITTER[1]
    area2 = (qx[:, 1] - qx[:, 0]) * (qy[:, 2] - qy[:, 0]) - (qx[:, 2] - qx[:, 0]) * (
        qy[:, 1] - qy[:, 0])
    keep = np.abs(area2) > tol.edge_on  # vertical triangles: the ray grazes them, no crossing
    lo = np.stack([np.ceil(qx.min(1)), np.ceil(qy.min(1))], axis=1).astype(np.int64)
    hi = np.stack([np.floor(qx.max(1)), np.floor(qy.max(1))], axis=1).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [nx - 1, ny - 1])
    count = np.where(keep, np.prod(np.maximum(hi - lo + 1, 0), axis=1), 0)
    toggles = np.zeros(nx * ny * (nz + 1), dtype=np.int64)
    tri_ids = np.flatnonzero(count)
    cum = np.cumsum(count[tri_ids])
    cuts = np.searchsorted(cum, np.arange(batch, int(cum[-1]) if cum.size else 0, batch))
    for part in np.split(tri_ids, cuts):
        if part.size == 0:
            continue
        owner, cell = ragged_boxes(lo[part], hi[part])
        t = part[owner]
        px, py = cell[:, 0].astype(np.float64), cell[:, 1].astype(np.float64)
        ax, ay, bx, by, cx, cy = qx[t, 0], qy[t, 0], qx[t, 1], qy[t, 1], qx[t, 2], qy[t, 2]
        # Barycentric coordinates of the column in the projected triangle.
        a2 = area2[t]
        l1 = ((px - ax) * (cy - ay) - (cx - ax) * (py - ay)) / a2
        l2 = ((bx - ax) * (py - ay) - (px - ax) * (by - ay)) / a2
        l0 = 1.0 - l1 - l2
        hit = (l0 >= 0) & (l1 >= 0) & (l2 >= 0)
        t, l0, l1, l2 = t[hit], l0[hit], l1[hit], l2[hit]
        z = l0 * q[t, 0, 2] + l1 * q[t, 1, 2] + l2 * q[t, 2, 2]
        # The crossing flips parity of voxel centres k >= ceil(z).
        k = np.clip(np.ceil(z), 0, nz).astype(np.int64)
        flat = (cell[hit, 0] * ny + cell[hit, 1]) * (nz + 1) + k
        toggles += np.bincount(flat, minlength=toggles.size)
    parity = np.cumsum((toggles & 1).astype(np.uint8).reshape(nx, ny, nz + 1), axis=2,
                       dtype=np.uint8)
    return (parity[:, :, :nz] & 1).astype(bool)


def closing_cube(mask: NDArray[np.bool_], radius: int) -> NDArray[np.bool_]:
    """Morphological closing of ``mask`` by a (2 radius + 1)^3 cube; outside counts as empty.

    Separable max/min filters, so the cost does not grow with the cube's volume.
    """
    if radius <= 0:
        return mask.copy()
    size = 2 * radius + 1
    grown = ndimage.maximum_filter(mask.view(np.uint8), size=size, mode="constant", cval=0)
    closed: NDArray[np.bool_] = ndimage.minimum_filter(grown, size=size, mode="constant",
                                                       cval=0).astype(bool)
    return closed


def fill_enclosed(mask: NDArray[np.bool_], open_seeds: NDArray[np.bool_] | None = None
                  ) -> NDArray[np.bool_]:
    """``mask`` with every region of empty voxels it encloses filled, except those that hold
    an ``open_seeds`` voxel (the cavities of a design, which count as outside).

    Empty regions are the 6-connected components of ``~mask``; one touching the grid's border
    is outside. Without seeds this is ``scipy.ndimage.binary_fill_holes`` (same result), in
    one labelling pass rather than an iterated dilation.

    Args:
        mask: (nx, ny, nz) bool, e.g. the printed solid.
        open_seeds: (nx, ny, nz) bool or None; empty regions holding one of these stay empty.

    Returns:
        (nx, ny, nz) bool.
    """
    empty = ~mask
    labels, count = ndimage.label(empty)
    if count == 0:
        return mask.copy()
    outside = np.zeros(count + 1, dtype=bool)
    for axis in range(3):
        for end in (0, -1):
            outside[np.take(labels, end, axis=axis).ravel()] = True
    if open_seeds is not None:
        outside[labels[open_seeds & empty]] = True
    outside[0] = False  # label 0 is the mask itself
    filled: NDArray[np.bool_] = ~outside[labels]
    return filled


def iso_points(field: NDArray[np.floating], grid: VoxelGrid, level: float = 0.5
               ) -> NDArray[np.float64]:
    """Points where a voxel field crosses ``level`` between 6-neighbour voxel centres.

    The crossing is placed by linear interpolation between the two centres, so the points
    resolve the surface below the voxel size (they are the vertices marching cubes would make).

    Args:
        field: (nx, ny, nz) float, e.g. an ink fraction; values outside the grid count as 0.
        grid: the grid the field lives on.
        level: iso-value.

    Returns:
        (P, 3) float64, mm, crossing points.
    """
    f = np.pad(np.asarray(field, dtype=np.float32), 1)
    out = []
    for axis in range(3):
        a = np.moveaxis(f, axis, 0)
        lo, hi = a[:-1], a[1:]
        cross = (lo >= level) != (hi >= level)
        idx = np.nonzero(cross)
        fa, fb = lo[idx], hi[idx]
        frac = (level - fa) / (fb - fa)
        pos = np.stack([c.astype(np.float64) for c in idx], axis=1)
        pos[:, 0] += frac
        # Undo moveaxis and the padding: padded index p is grid index p - 1.
        order = np.argsort(np.array([axis] + [d for d in range(3) if d != axis]))
        pos = pos[:, order] - 1.0
        out.append(grid.origin_array + (pos + 0.5) * grid.voxel)
    return np.concatenate(out, axis=0) if out else np.zeros((0, 3))
