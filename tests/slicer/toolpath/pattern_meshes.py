"""Tiny layer meshes for the toolpath pattern tests: discs, annuli, a plate with two
holes and two tube walls joined by a bridge, flat or lifted."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import Delaunay


def disc(radius: float, h: float, inner: float = 0.0, jitter: float = 0.0, seed: int = 0
         ) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """Flat disc (inner = 0) or annulus in z = 0 with edge length about h (mm).

    Interior points lie on a hexagonal lattice (optionally jittered by ``jitter`` * h), the
    boundary circles are sampled at spacing h.
    """
    rng = np.random.default_rng(seed)
    rows = np.arange(-radius, radius + h, h * np.sqrt(3) / 2)
    pts = []
    for i, y in enumerate(rows):
        xs = np.arange(-radius, radius + h, h) + (0.5 * h if i % 2 else 0.0)
        pts.append(np.column_stack([xs, np.full_like(xs, y)]))
    p = np.concatenate(pts)
    p = p + jitter * h * rng.uniform(-1, 1, p.shape)
    r = np.linalg.norm(p, axis=1)
    p = p[(r < radius - 0.5 * h) & (r > inner + 0.5 * h)]
    rings = [radius] + ([inner] if inner > 0 else [])
    for rr in rings:
        n = max(int(np.ceil(2 * np.pi * rr / h)), 6)
        a = np.linspace(0, 2 * np.pi, n, endpoint=False)
        p = np.concatenate([p, rr * np.column_stack([np.cos(a), np.sin(a)])])
    tri = Delaunay(p).simplices
    cen = p[tri].mean(axis=1)
    keep = np.linalg.norm(cen, axis=1) > inner
    tri = tri[keep]
    return flat_mesh(p, tri)


def eccentric_annulus(radius: float = 20.0, hole: float = 6.0, offset: float = 4.0,
                      h: float = 0.6) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """A flat disc (edge about h, jittered) with a hole of radius ``hole`` at x = offset:
    a band radius - hole - offset wide at +x, radius - hole + offset at -x (mm)."""
    v, f = disc(radius, h, jitter=0.2)
    centre = v[f].mean(axis=1)[:, :2]
    f = f[np.linalg.norm(centre - [offset, 0.0], axis=1) > hole]
    used, inv = np.unique(f, return_inverse=True)
    return v[used], inv.reshape(-1, 3).astype(np.int32)


def flat_mesh(p: NDArray[np.float64], tri: NDArray[np.integer]
              ) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """The triangles ``tri`` of the 2-D points ``p`` as a mesh in z = 0: unused points
    dropped, faces counter-clockwise (normal +z)."""
    used, inv = np.unique(tri, return_inverse=True)
    v = np.column_stack([p[used], np.zeros(len(used))])
    f = inv.reshape(-1, 3).astype(np.int32)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    flip = np.cross(b - a, c - a)[:, 2] < 0
    f[flip] = f[flip][:, [0, 2, 1]]
    return v, f


def dome(v: NDArray[np.float64], height: float, radius: float) -> NDArray[np.float64]:
    """Lift flat vertices onto a smooth bump z = height * (1 - r^2 / radius^2)."""
    out = v.copy()
    r2 = (v[:, :2] ** 2).sum(axis=1)
    out[:, 2] = height * (1.0 - r2 / radius**2)
    return out


def sliver_disc(radius: float, h: float, squeeze: float = 0.97
                ) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """A flat disc where some interior vertices are slid almost onto a neighbour.

    Every moved vertex goes ``squeeze`` of the way along one of its edges, which leaves needle
    and sliver triangles (angles near 0 and 180 deg) like those of marching tetrahedra while the
    mesh stays valid (no inverted faces: moves that would invert are undone).
    """
    v, f = disc(radius, h)
    from slicer.toolpath.surface import boundary_vertices

    bnd = boundary_vertices(f, len(v))
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    target = np.full(len(v), -1)
    target[e[:, 0]] = e[:, 1]
    moved = (np.arange(len(v)) % 5 == 0) & ~bnd & (target >= 0)
    # never move two ends of one edge
    both = moved[e[:, 0]] & moved[e[:, 1]]
    moved[e[both, 1]] = False
    out = v.copy()
    out[moved] = v[moved] + squeeze * (v[target[moved]] - v[moved])
    a, b, c = out[f[:, 0]], out[f[:, 1]], out[f[:, 2]]
    bad = np.cross(b - a, c - a)[:, 2] <= 0
    out[f[bad].ravel()] = v[f[bad].ravel()]
    return out, f


def plate_with_holes(width: float = 44.0, height: float = 20.0, radius: float = 8.0,
                     centre_x: float = 11.0, h: float = 0.6,
                     centres: tuple[tuple[float, float], ...] | None = None,
                     ) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """Flat rectangle width x height (mm, centred at the origin) with two round holes of
    ``radius`` at x = +-centre_x: thin bands above and below the holes, and a solid
    junction between them that is no band; or the holes at ``centres`` (mm). Edge length
    about h; faces normal +z."""
    at = centres if centres is not None else ((-centre_x, 0.0), (centre_x, 0.0))
    rng = np.random.default_rng(0)
    xs = np.arange(-width / 2, width / 2 + 1e-9, h)
    ys = np.arange(-height / 2, height / 2 + 1e-9, h)
    gx, gy = np.meshgrid(xs, ys)
    p = np.column_stack([gx.ravel(), gy.ravel()])
    inner = (np.abs(p[:, 0]) < width / 2 - 1e-6) & (np.abs(p[:, 1]) < height / 2 - 1e-6)
    p = p + 0.1 * h * rng.uniform(-1, 1, p.shape) * inner[:, None]
    keep = np.ones(len(p), dtype=bool)
    rings = []
    for cx, cy in at:
        keep &= np.hypot(p[:, 0] - cx, p[:, 1] - cy) > radius + 0.3 * h
        a = np.linspace(0, 2 * np.pi, int(2 * np.pi * radius / h), endpoint=False)
        rings.append(np.column_stack([cx + radius * np.cos(a), cy + radius * np.sin(a)]))
    p = np.concatenate([p[keep], *rings])
    tri = Delaunay(p).simplices
    centre = p[tri].mean(axis=1)
    solid = np.ones(len(tri), dtype=bool)
    for cx, cy in at:
        solid &= np.hypot(centre[:, 0] - cx, centre[:, 1] - cy) > radius
    return flat_mesh(p, tri[solid])


def rings_with_bridge(ring_radius: float = 14.0, wall: float = 2.4, centre_x: float = 26.0,
                      bridge: float = 14.0, h: float = 0.5
                      ) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """Two tubes' walls joined by a solid bridge, flat in z = 0 (the aorta's plaque junction
    in miniature): rings of outer radius ``ring_radius`` and ``wall`` thick at
    x = +-centre_x, and a rectangle ``bridge`` tall spanning between the rings. Edge length
    about h; faces normal +z."""
    inner = ring_radius - wall
    xs = np.arange(-centre_x - ring_radius, centre_x + ring_radius + 1e-9, h)
    ys = np.arange(-ring_radius, ring_radius + 1e-9, h)
    gx, gy = np.meshgrid(xs, ys)
    p = np.column_stack([gx.ravel(), gy.ravel()])
    p = p + 0.1 * h * np.random.default_rng(1).uniform(-1, 1, p.shape)
    circles = []
    for cx in (-centre_x, centre_x):
        for rr in (ring_radius, inner):
            a = np.linspace(0, 2 * np.pi, int(2 * np.pi * rr / h), endpoint=False)
            circles.append(np.column_stack([cx + rr * np.cos(a), rr * np.sin(a)]))

    def solid(q: NDArray[np.float64]) -> NDArray[np.bool_]:
        d = [np.hypot(q[:, 0] - cx, q[:, 1]) for cx in (-centre_x, centre_x)]
        in_ring = (d[0] < ring_radius) | (d[1] < ring_radius)
        in_bridge = (np.abs(q[:, 0]) < centre_x) & (np.abs(q[:, 1]) < 0.5 * bridge)
        return (in_ring | in_bridge) & (d[0] > inner) & (d[1] > inner)

    margin = solid(p) & np.all([np.abs(np.hypot(p[:, 0] - cx, p[:, 1]) - rr) > 0.3 * h
                                for cx in (-centre_x, centre_x)
                                for rr in (ring_radius, inner)], axis=0)
    p = np.concatenate([p[margin], *circles])
    tri = Delaunay(p).simplices
    return flat_mesh(p, tri[solid(p[tri].mean(axis=1))])


def ribbed_block(rib: float = 2.0, hole: tuple[float, float] = (6.0, 5.0), cols: int = 3,
                 block: float = 16.0, h: float = 0.5
                 ) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """A flat grid of ribs ``rib`` wide (mm) between two rows of ``cols`` rectangular holes
    ``hole`` (x, y mm), a rim ``rib`` wide round them, and a solid square block ``block``
    wide on their right (the octagonal pocket's honeycomb beside its solid boss, in
    miniature): walls about one W wide joined to a part many W wide. Square cells of
    side h (dimensions multiples of h), each split into two faces; normal +z."""
    hx, hy = hole
    height = 3 * rib + 2 * hy
    width = (cols + 1) * rib + cols * hx + block
    nx, ny = round(width / h), round(height / h)
    xs, ys = np.linspace(0.0, width, nx + 1), np.linspace(0.0, height, ny + 1)
    gx, gy = np.meshgrid(xs, ys)
    p = np.column_stack([gx.ravel(), gy.ravel()])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    a = (j * (nx + 1) + i).ravel()
    cells = np.column_stack([a, a + 1, a + nx + 2, a + nx + 1])
    centre = p[cells].mean(axis=1)
    solid = np.ones(len(cells), dtype=bool)
    for c in range(cols):
        x0 = rib + c * (hx + rib)
        for y0 in (rib, 2 * rib + hy):
            solid &= ~((centre[:, 0] > x0) & (centre[:, 0] < x0 + hx)
                       & (centre[:, 1] > y0) & (centre[:, 1] < y0 + hy))
    cells = cells[solid]
    tri = np.concatenate([cells[:, [0, 1, 2]], cells[:, [0, 2, 3]]])
    return flat_mesh(p, tri)
