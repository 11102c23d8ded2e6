"""Split a closed surface where its parts touch, so each part is a closed manifold shell.

A closed surface whose parts touch along an edge or at a point (an assembly's bodies, the
boundary of a tet mesh whose parts meet) has edges used by 4 or more faces and vertices
shared by separate fans of faces. ``split_pinches`` gives each fan its own copy of such a
vertex, pairing the faces around a crowded edge by the wedge of solid they bound
(``_radial_pairs``); ``bisect_crowded`` splits edges whose two ends both parts share, so
the split can part them. ``separate_shells`` does both, in rounds. Used on fTetWild's wrap
(``slicer.winding_repair``) and, before the shells are joined, on a non-manifold input
(``slicer.repair``).
"""

from __future__ import annotations

import numpy as np

from core.tolerance import tol

# Copies of a vertex where parts touch are moved apart by this fraction of the bounding-box
# diagonal (far above the merge tolerance, far below fTetWild's envelope).
SPLIT_OFFSET_FAC = 1e-5
# Rounds of bisecting crowded edges (one edge per face each round) before the surface is
# left as it is and ``load_surface`` judges it.
BISECT_ROUNDS = 4
# Faces around a crowded edge closer in angle than this (rad) lie in one half-plane.
TIE_RAD = 1e-9


def non_manifold_edges(faces: np.ndarray) -> int:
    """Edges of the (m, 3) ``faces`` used by 3 or more faces."""
    return int(np.count_nonzero(_edge_uses(faces) > 2))


def open_edges(faces: np.ndarray) -> int:
    """Edges of the (m, 3) ``faces`` used by one face."""
    return int(np.count_nonzero(_edge_uses(faces) == 1))


def _edge_uses(faces: np.ndarray) -> np.ndarray:
    """(e,) int64: how many of the (m, 3) ``faces`` use each undirected edge."""
    edges = np.sort(np.asarray(faces)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    return uses


def split_pinches(vertices: np.ndarray, faces: np.ndarray, offset: float
                  ) -> tuple[np.ndarray, np.ndarray, int]:
    """Give each fan of faces around a vertex its own copy of it, so parts of a closed surface
    that touch along an edge or at a point become separate shells.

    Corners (face, vertex) are joined across edges used by exactly two faces; each connected
    set of corners is one vertex of the result. A vertex split into k copies has each copy
    moved ``offset`` (the input's unit) towards the centroid of its own faces, so the copies
    stay apart when vertices are merged by position again.

    Args:
        vertices: (n, 3) float64. faces: (m, 3) int, closed.

    Returns:
        (vertices (n', 3) float64, faces (m, 3) int64, vertices split).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    faces = np.asarray(faces, dtype=np.int64)
    m = len(faces)
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    corner_a = (np.arange(3 * m) // 3) * 3 + np.tile([0, 1, 2], m)  # corner of the start
    corner_b = (np.arange(3 * m) // 3) * 3 + np.tile([1, 2, 0], m)  # corner of the end
    _, edge_id, uses = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True,
                                 return_counts=True)
    edge_id = edge_id.ravel()
    manifold = np.flatnonzero(uses[edge_id] == 2)
    order = manifold[np.argsort(edge_id[manifold], kind="stable")]
    first, second = order[0::2], order[1::2]  # the two half-edges of each manifold edge
    patch = _patches(first // 3, second // 3, m)
    more_first, more_second = _radial_pairs(np.asarray(vertices, dtype=np.float64), faces,
                                            directed, edge_id, uses, patch)
    first = np.concatenate([first, more_first])
    second = np.concatenate([second, more_second])
    same = directed[first, 0] == directed[second, 0]  # same start vertex: a flipped neighbour
    # the corner of each end of `first` meets the corner of the same vertex in `second`
    rows = np.concatenate([corner_a[first], corner_b[first]])
    cols = np.concatenate([np.where(same, corner_a[second], corner_b[second]),
                           np.where(same, corner_b[second], corner_a[second])])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * m, 3 * m))
    _, label = connected_components(graph, directed=False)
    vertex_of = faces.ravel()
    _, first_corner, new_id = np.unique(label, return_index=True, return_inverse=True)
    original = vertex_of[first_corner]  # (n',) the input vertex of each new vertex
    copies = np.bincount(original, minlength=len(vertices))
    new_v = np.asarray(vertices, dtype=np.float64)[original].copy()
    split = np.flatnonzero(copies[original] > 1)
    if len(split):
        centres = np.asarray(vertices, dtype=np.float64)[faces].mean(axis=1)  # (m, 3)
        corner_face = np.arange(3 * m) // 3
        count = np.bincount(new_id, minlength=len(original))
        mean = np.column_stack([np.bincount(new_id, weights=centres[corner_face, k],
                                            minlength=len(original)) for k in range(3)])
        toward = mean / np.maximum(count, 1)[:, None] - new_v
        length = np.linalg.norm(toward, axis=1)
        new_v[split] += offset * toward[split] / np.maximum(length[split], tol.tiny)[:, None]
    return new_v, new_id.reshape(m, 3).astype(np.int64), int(np.count_nonzero(copies > 1))


def _patches(face_a: np.ndarray, face_b: np.ndarray, m: int) -> np.ndarray:
    """(m,) int label of each of ``m`` faces: the sets joined across manifold edges (faces
    ``face_a[i]`` and ``face_b[i]`` share one)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix((np.ones(len(face_a)), (face_a, face_b)), shape=(m, m))
    return np.asarray(connected_components(graph, directed=False)[1], dtype=np.int64)


def _radial_pairs(vertices: np.ndarray, faces: np.ndarray, directed: np.ndarray,
                  edge_id: np.ndarray, uses: np.ndarray, patch: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Around each edge of 3 or more faces, the pairs of half-edges whose faces bound the same
    wedge of solid. Faces sorted by angle around the edge each open a wedge (the solid lies
    ahead of them) or close one; openings and closings are matched like brackets, starting
    where the fewest wedges overlap, so wedges that overlap (shells pushed slightly into each
    other) nest instead of crossing, and the union (``slicer.shell_union``) merges them. An
    edge whose openings and closings do not balance (inconsistent winding) is left unpaired.
    Around an edge of 4 faces, where the other pairing joins faces of one ``patch`` (m,)
    (the face sets joined across manifold edges) and the nesting does not, two solids cross
    there (they overlap through the edge) and each keeps its own faces.
    Returns two (p,) int64 half-edge indices: the opening face's and its closing face's."""
    crowded = np.flatnonzero(uses[edge_id] > 2)
    if not len(crowded):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    edge = edge_id[crowded]
    lo = np.minimum(directed[crowded, 0], directed[crowded, 1])
    hi = np.maximum(directed[crowded, 0], directed[crowded, 1])
    axis = vertices[hi] - vertices[lo]
    axis /= np.maximum(np.linalg.norm(axis, axis=1), tol.tiny)[:, None]
    face = crowded // 3
    third = faces[face, (crowded % 3 + 2) % 3]
    radial = vertices[third] - vertices[lo]
    radial -= np.einsum("ij,ij->i", radial, axis)[:, None] * axis
    # per edge, angles measured from the radial direction of its first half-edge
    _, start, size = np.unique(edge, return_index=True, return_counts=True)
    group = np.searchsorted(edge[start], edge)
    ref_x = radial[start][group]
    ref_y = np.cross(axis, ref_x)
    angle = np.arctan2(np.einsum("ij,ij->i", radial, ref_y),
                       np.einsum("ij,ij->i", radial, ref_x))
    tri = vertices[faces[crowded // 3]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    # the solid lies on the side of increasing angle where the normal points against it
    opens = np.einsum("ij,ij->i", normal, np.cross(axis, radial)) < 0
    order = np.lexsort((angle, edge))
    begin = (np.cumsum(size) - size)[group[order]]  # first sorted position of each group
    count = size[group[order]]
    position = np.arange(len(crowded))
    after = begin + (position - begin + 1) % count
    # Two faces in one half-plane (solids touching face to face): the one closing the solid
    # behind it comes first, so the two solids stay apart.
    gap = np.abs(np.angle(np.exp(1j * (angle[order][after] - angle[order]))))
    swap = np.flatnonzero((gap < TIE_RAD) & opens[order] & ~opens[order][after])
    order[swap], order[after[swap]] = order[after[swap]], order[swap]
    crowded, opens, group = crowded[order], opens[order], group[order]
    step = np.where(opens, 1, -1)
    level = np.cumsum(step)
    level -= np.repeat(level[np.cumsum(size) - size] - step[np.cumsum(size) - size], size)
    balanced = np.bincount(group, weights=step, minlength=len(size)) == 0
    # start each edge's cycle just after its (first) lowest level: every level is then >= 0
    low = np.lexsort((position, level, group))[np.cumsum(size) - size]
    turned = (position - low[group] - 1) % count
    order = np.lexsort((turned, group))
    opens, step, group, crowded = opens[order], step[order], group[order], crowded[order]
    level = np.cumsum(step)
    level -= np.repeat(level[np.cumsum(size) - size] - step[np.cumsum(size) - size], size)
    # an opening from level k and the next closing back to k bound one wedge: sorted by
    # (edge, k, position) they follow each other
    outer = np.where(opens, level - 1, level)
    mine = np.flatnonzero(balanced[group])
    pairs = mine[np.lexsort((mine, outer[mine], group[mine]))]
    first, second = pairs[0::2], pairs[1::2]
    # edges of 4 faces: their two pairs follow each other
    head = np.flatnonzero((size[group[first]] == 4)
                          & (np.r_[-1, group[first][:-1]] != group[first]))
    own = patch[crowded[first] // 3] == patch[crowded[second] // 3]
    other = ((patch[crowded[first[head]] // 3] == patch[crowded[second[head + 1]] // 3])
             & (patch[crowded[first[head + 1]] // 3] == patch[crowded[second[head]] // 3]))
    cross = head[other & ~(own[head] & own[head + 1])]
    second[cross], second[cross + 1] = second[cross + 1], second[cross]
    return crowded[first], crowded[second]


def bisect_crowded(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split edges of 3 or more faces at their midpoints (each of their faces into two), at
    most one edge per face: of a face's crowded edges only the lowest-numbered is a candidate,
    and an edge is split where it is the candidate of all its faces (the lowest crowded edge
    always is, so repeated calls split them all); ``split_pinches`` then parts the midpoint
    where both ends of the edge are shared by the touching parts.

    Args:
        vertices: (n, 3) float64. faces: (m, 3) int.

    Returns:
        (vertices (n + e, 3) float64, faces (m + f, 3) int64).
    """
    faces = np.asarray(faces, dtype=np.int64)
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    _, edge_id, uses = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True,
                                 return_counts=True)
    edge_id = edge_id.ravel()
    crowded = uses[edge_id] > 2  # (3m,) per half-edge
    lowest = np.where(crowded, edge_id, len(uses)).reshape(-1, 3).min(axis=1)  # (m,) per face
    blocked = np.zeros(len(uses), dtype=bool)
    blocked[edge_id[crowded & (np.repeat(lowest, 3) != edge_id)]] = True
    chosen = np.flatnonzero(crowded & ~blocked[edge_id])
    if not len(chosen):
        return np.asarray(vertices, dtype=np.float64), faces
    edges, mid_of = np.unique(edge_id[chosen], return_inverse=True)
    first = np.searchsorted(edge_id[chosen][np.argsort(edge_id[chosen], kind="stable")],
                            edges)
    ends = directed[chosen[np.argsort(edge_id[chosen], kind="stable")][first]]
    mids = 0.5 * (vertices[ends[:, 0]] + vertices[ends[:, 1]])
    mid = len(vertices) + mid_of
    face, k = chosen // 3, chosen % 3
    a, b, c = faces[face, k], faces[face, (k + 1) % 3], faces[face, (k + 2) % 3]
    keep = np.ones(len(faces), dtype=bool)
    keep[face] = False
    halves = np.vstack([np.column_stack([a, mid, c]), np.column_stack([mid, b, c])])
    return (np.vstack([np.asarray(vertices, dtype=np.float64), mids]),
            np.vstack([faces[keep], halves]))


def separate_shells(vertices: np.ndarray, faces: np.ndarray, offset: float
                    ) -> tuple[np.ndarray, np.ndarray, int]:
    """``split_pinches``, then up to ``BISECT_ROUNDS`` rounds of ``bisect_crowded`` and
    ``split_pinches`` where parts touch along an edge whose ends they share: a closed surface
    of parts touching along edges or at points as separate closed shells.

    Args:
        vertices: (n, 3) float64. faces: (m, 3) int, closed, consistently wound.
        offset: how far each copy of a split vertex moves into its own faces (input units;
            0 keeps the copies where the vertex was).

    Returns:
        (vertices (n', 3) float64, faces (m', 3) int64, vertices split); non-manifold
        edges are left where the rounds do not resolve them.
    """
    out_v, out_f, pinches = split_pinches(vertices, faces, offset)
    for _ in range(BISECT_ROUNDS):  # touching along an edge whose ends the parts share
        if not non_manifold_edges(out_f):
            break
        out_v, out_f = bisect_crowded(out_v, out_f)
        out_v, out_f, more = split_pinches(out_v, out_f, offset)
        pinches += more
    return out_v, out_f, pinches
