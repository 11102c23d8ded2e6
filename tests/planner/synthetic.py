"""Synthetic toolpaths for planner tests and benchmarks (lines, spirals, a curved dome patch)."""

from __future__ import annotations

import numpy as np

from core.stages import Toolpath


def make_toolpath(
    position: np.ndarray, normal: np.ndarray, path: np.ndarray, layer: np.ndarray | None = None,
    speed: float = 10.0, height: float = 0.5,
) -> Toolpath:
    """A Toolpath with constant speed/height; width from C = 6.57 mm^3/s (paper eq. 4)."""
    n = len(position)
    normal = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    return Toolpath(
        position=position,
        normal=normal,
        layer=np.zeros(n, np.int32) if layer is None else layer,
        path=path.astype(np.int32),
        height=np.full(n, height),
        width=np.full(n, 6.57 / (height * speed)),
        speed=np.full(n, speed),
        extrude=np.ones(n, bool),
        pattern=np.zeros(n, np.int8),
    )


def lines(n_lines: int = 5, length: float = 60.0, step: float = 0.5, pitch: float = 4.0,
          z: float = 5.0) -> Toolpath:
    """Parallel straight lines in the x direction, normals +z, one path per line."""
    x = np.arange(0.0, length + 1e-9, step)
    pos, path = [], []
    for i in range(n_lines):
        xs = x if i % 2 == 0 else x[::-1]
        pos.append(np.stack([xs, np.full_like(xs, i * pitch), np.full_like(xs, z)], 1))
        path.append(np.full(len(xs), i))
    P = np.concatenate(pos)
    return make_toolpath(P, np.tile([0.0, 0.0, 1.0], (len(P), 1)), np.concatenate(path))


def spiral(turns: float = 10.0, radius: float = 25.0, height: float = 30.0,
           step: float = 0.5) -> Toolpath:
    """A helix (vase-mode wall), normals +z, one path."""
    length = turns * 2 * np.pi * radius
    n = int(length / step) + 1
    th = np.linspace(0.0, turns * 2 * np.pi, n)
    P = np.stack([radius * np.cos(th), radius * np.sin(th), height * th / th[-1]], 1)
    return make_toolpath(P, np.tile([0.0, 0.0, 1.0], (n, 1)), np.zeros(n, np.int32),
                         layer=(th // (2 * np.pi)).astype(np.int32))


def dome(radius: float = 40.0, cap: float = 15.0, rings: int = 8, step: float = 0.5) -> Toolpath:
    """Concentric rings on a spherical cap; normals are the sphere normals (curved layer)."""
    R = (radius**2 + cap**2) / (2 * cap)  # sphere radius through the rim and the apex
    pos, nrm, path = [], [], []
    for i in range(rings):
        r = radius * (i + 1) / rings
        n = max(int(2 * np.pi * r / step), 8)
        th = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        z = np.sqrt(R**2 - r**2) - (R - cap)
        P = np.stack([r * np.cos(th), r * np.sin(th), np.full(n, z)], 1)
        centre = np.array([0.0, 0.0, cap - R])
        pos.append(P)
        nrm.append(P - centre)
        path.append(np.full(n, i))
    return make_toolpath(np.concatenate(pos), np.concatenate(nrm), np.concatenate(path))


def big(n: int = 100_000, step: float = 0.4) -> Toolpath:
    """A long job: stacked spiral layers, about ``n`` waypoints."""
    per_turn = int(2 * np.pi * 30.0 / step)
    turns = max(n / per_turn, 1.0)
    return spiral(turns=turns, radius=30.0, height=min(60.0, 0.5 * turns), step=step)


def big_dome(n: int = 100_000, radius: float = 60.0, cap: float = 8.0,
             step: float = 0.3) -> Toolpath:
    """A curved dome patch of about ``n`` waypoints (concentric rings, sphere normals)."""
    rings = max(round(2 * n * step / (2 * np.pi * radius)), 1)
    return dome(radius=radius, cap=cap, rings=rings, step=step)


def rings(radius: float, heights: list[float], lean_deg: list[float], step: float = 1.0
          ) -> Toolpath:
    """Circles of ``radius`` at ``heights``, one path each; the normals of ring k lean
    ``lean_deg[k]`` from +z towards the axis (positive: a bowl-shaped layer, like the bottom
    of a cup) or away from it (negative)."""
    pos, nrm, path = [], [], []
    for i, (z, lean) in enumerate(zip(heights, lean_deg, strict=True)):
        n = max(int(2 * np.pi * radius / step), 8)
        th = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        radial = np.stack([np.cos(th), np.sin(th), np.zeros(n)], 1)
        a = np.radians(lean)
        pos.append(radius * radial + [0.0, 0.0, z])
        nrm.append(-np.sin(a) * radial + [0.0, 0.0, np.cos(a)])
        path.append(np.full(n, i))
    return make_toolpath(np.concatenate(pos), np.concatenate(nrm), np.concatenate(path))


def random_frames(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) random unit normals and (n, 3) unit tangents perpendicular to them."""
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    tangent = np.cross(normal, rng.normal(size=(n, 3)))
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    return normal, tangent
