"""Polylines lying on a triangle mesh: the common output of every toolpath pattern."""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray


class SurfaceLines(NamedTuple):
    """Polylines lying on a triangle mesh (the mesh they were extracted on).

    points: (P, 3) float64, mm, on the mesh.
    face:   (P,) int32, index of the triangle containing each point.
    bary:   (P, 3) float64, barycentric coordinates of the point in that triangle (sum 1).
    line:   (P,) int32, polyline id; the points of one line are consecutive, in order.
    closed: (L,) bool, line i is a closed loop (its first point is not repeated at the end).
    """

    points: NDArray[np.float64]
    face: NDArray[np.int32]
    bary: NDArray[np.float64]
    line: NDArray[np.int32]
    closed: NDArray[np.bool_]

    @property
    def n_lines(self) -> int:
        """Number of polylines L."""
        return int(self.closed.shape[0])


def empty_lines() -> SurfaceLines:
    """A SurfaceLines with no points and no lines."""
    return SurfaceLines(
        points=np.zeros((0, 3)),
        face=np.zeros(0, dtype=np.int32),
        bary=np.zeros((0, 3)),
        line=np.zeros(0, dtype=np.int32),
        closed=np.zeros(0, dtype=bool),
    )


def merge_lines(parts: Sequence[SurfaceLines], face_maps: Sequence[NDArray[np.integer]]
                ) -> SurfaceLines:
    """Concatenate lines extracted on sub-meshes, renumbering lines and mapping faces back.

    face_maps[i]: (m_i,) int, the face index in the whole mesh of each face of part i.
    """
    if not parts:
        return empty_lines()
    offsets = np.cumsum([0] + [p.n_lines for p in parts[:-1]])
    return SurfaceLines(
        points=np.concatenate([p.points for p in parts]),
        face=np.concatenate([np.asarray(fm)[p.face] for p, fm in zip(parts, face_maps,
                                                                   strict=True)]
                            ).astype(np.int32),
        bary=np.concatenate([p.bary for p in parts]),
        line=np.concatenate([p.line + o for p, o in zip(parts, offsets, strict=True)]
                            ).astype(np.int32),
        closed=np.concatenate([p.closed for p in parts]).astype(bool),
    )
