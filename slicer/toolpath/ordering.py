"""Print order of the lines of one layer component.

Contours (boundary-conformal loops) are printed outside-in: by increasing distance from the
boundary, so the outer wall that defines the part's shape is laid first and every later loop
is placed against an already printed neighbour; loops at the same level go nearest-neighbour.
(``build`` passes the distance from the outer loop as the level of a band fitted between two
boundaries: outer wall first, then across the band to the inner wall, so that consecutive
lines are neighbours and join.)
A closed loop starts at its point nearest to the nozzle, unless it hosts the short open line
beside it (``splice.py``: a fitted band's extra line), which is then printed with it in one
path. Stripes are printed as a path
cover (``_order_cover``): every line is an edge between its two end nodes and joins pair
nearby ends, each end at most once and never closing a cycle, so the chains of lines cover
the component with few extrusion starts. Ends that need a join most (fewest options) choose
first, then augmenting paths free ends for joins (a matched end hands its partner on), then
2-opt exchanges shorten the joins (each deposits a connector, which widens the spacing of
the volume match). Measured on the socket (bench/run.py): its disc-like stripe layers 1-17
had 253 starts with a greedy zig-zag, 107 with the cover (max per component 37 -> 18,
stripe width error p90 14.5 -> 14.3 %, connector volume 13.1 -> 12.9 %). The rest are mostly
forced: where a stripe ends at a branch point inside the region (a Y), one of the three
branches must end a chain, and those ends have no other end within the join reach.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from core.tolerance import tol
from slicer.toolpath.join_crossing import JoinCrossing
from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.resample import line_index
from slicer.toolpath.splice import Splice, find_splices, spliced_points

AUGMENT_DEPTH = 2  # longest chain of re-matched joins tried to free an end for a join
SHORTEN_SWEEPS = 4  # passes of 2-opt exchanges that shorten the joins at an equal count


class Piece(NamedTuple):
    """One line in print order.

    points: (k,) int64, point indices into the SurfaceLines, in print order (a closed loop
        repeats its start point at the end so that it is printed all the way round).
    line: int, the line id.
    """

    points: NDArray[np.int64]
    line: int


def _piece(
    lines: SurfaceLines, start: int, stop: int, line: int, pos: NDArray[np.float64]
) -> tuple[Piece, NDArray[np.float64]]:
    """Best way to enter line ``line`` from ``pos``: returns the piece and its end point."""
    idx = np.arange(start, stop, dtype=np.int64)
    pts = lines.points[start:stop]
    if lines.closed[line]:
        roll = int(np.argmin(np.linalg.norm(pts - pos, axis=1)))
        idx = np.roll(idx, -roll)
        idx = np.append(idx, idx[0])
    elif np.linalg.norm(pts[-1] - pos) < np.linalg.norm(pts[0] - pos):
        idx = idx[::-1]
    return Piece(idx, line), lines.points[idx[-1]]


def _entry_distance(
    lines: SurfaceLines, start: NDArray[np.int64], stop: NDArray[np.int64],
    cand: NDArray[np.int64], pos: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Distance from ``pos`` to the entry of each candidate line (closed: nearest point)."""
    d_first = np.linalg.norm(lines.points[start[cand]] - pos, axis=1)
    d_last = np.linalg.norm(lines.points[stop[cand] - 1] - pos, axis=1)
    out = np.minimum(d_first, d_last)
    for j in np.flatnonzero(lines.closed[cand]):
        c = cand[j]
        out[j] = np.linalg.norm(lines.points[start[c]:stop[c]] - pos, axis=1).min()
    return out


def _join_candidates(ends: NDArray[np.float64], radius: NDArray[np.float64], n: int,
                     alive: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64],
                                                        NDArray[np.float64]]:
    """Pairs of ends of different live lines closer than the mean of their reaches.

    Returns (a (k,) int64, b (k,) int64, d (k,) float64 mm), sorted by distance d.
    """
    if len(ends) < 2:
        z = np.zeros(0, dtype=np.int64)
        return z, z, np.zeros(0)
    pairs = cKDTree(ends).query_pairs(r=float(radius.max()), output_type="ndarray")
    if pairs.size == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z, np.zeros(0)
    a, b = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    d = np.linalg.norm(ends[a] - ends[b], axis=1)
    keep = (d <= 0.5 * (radius[a] + radius[b])) & (a % n != b % n) & alive[a % n] & alive[b % n]
    a, b, d = a[keep], b[keep], d[keep]
    order = np.argsort(d, kind="stable")
    return a[order], b[order], d[order]


def _acyclic(partner: NDArray[np.int64], n: int) -> bool:
    """True if the joins ``partner`` (end -> end or -1; end e belongs to line e % n) link the
    lines into chains only (no cycle). Union-find over plain lists: called for every trial
    change of the matching, on a few hundred ends."""
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in enumerate(partner.tolist()):
        if b <= a:  # free (-1) or seen from its other end
            continue
        ra, rb = find(a % n), find(b % n)
        if ra == rb:
            return False
        parent[ra] = rb
    return True


def _match_ends(n: int, cand: list[list[int]], can_join: Callable[[int, int], bool],
                length: Callable[[int, int], float] | None = None) -> NDArray[np.int64]:
    """Acyclic matching of line ends (``cand[e]``: ends joinable to end e, nearest first).

    Fewest-options-first greedy (an end with one candidate takes it before a neighbour with
    many options does; with ``length``, the plain shortest-first greedy too, and the one
    with more joins is kept), then augmenting paths of up to ``AUGMENT_DEPTH`` steps from
    every free end u: u takes a matched v whose partner w re-matches in turn; every accepted
    change is acyclic and adds one join. With ``length`` (end, end) -> mm, ``_shorten``
    then shortens the joins at an equal count. ``can_join`` (end, end) vetoes a join
    (cached). The exhaustive optimum is reached on most small random instances
    (tests/slicer/toolpath/test_ordering.py), never more than one join short.

    Returns:
        (2n,) int64, the partner end of each end, -1 where free.
    """
    partner = np.full(2 * n, -1, dtype=np.int64)
    veto: set[tuple[int, int]] = set()

    def ok(a: int, b: int) -> bool:
        key = (min(a, b), max(a, b))
        if key in veto:
            return False
        if not can_join(a, b):
            veto.add(key)
            return False
        return True

    parent = np.arange(n, dtype=np.int64)

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = int(parent[i])
        return i

    def options(e: int) -> int:
        root = find(e % n)
        return sum(1 for c in cand[e] if partner[c] < 0 and find(c % n) != root)

    # the end with the fewest options left goes first (a heap with lazy updates: counts only
    # fall, so a popped count that is stale is pushed again); it takes its nearest free end
    # of another chain
    heap = [(len(cand[e]), e) for e in range(2 * n) if cand[e]]
    heapq.heapify(heap)
    while heap:
        count, e = heapq.heappop(heap)
        if partner[e] >= 0:
            continue
        now = options(e)
        if now == 0:
            continue
        if now != count:
            heapq.heappush(heap, (now, e))
            continue
        root = find(e % n)
        for c in cand[e]:
            if partner[c] < 0 and find(c % n) != root and ok(e, c):
                partner[e], partner[c] = c, e
                parent[root] = find(c % n)
                for x in cand[e] + cand[c]:  # their neighbours lost an option
                    if partner[x] < 0:
                        heapq.heappush(heap, (options(x), x))
                break
    if length is not None:
        # the plain greedy (shortest joins first) wins on some layouts: keep the better start
        alt = np.full(2 * n, -1, dtype=np.int64)
        parent[:] = np.arange(n)
        pairs = sorted({(min(a, b), max(a, b)) for a in range(2 * n) for b in cand[a]},
                       key=lambda ab: length(*ab))
        for a, b in pairs:
            ra, rb = find(a % n), find(b % n)
            if alt[a] < 0 and alt[b] < 0 and ra != rb and ok(a, b):
                alt[a], alt[b] = b, a
                parent[ra] = rb
        if np.count_nonzero(alt >= 0) > np.count_nonzero(partner >= 0):
            partner = alt

    def augment(u: int, trial: NDArray[np.int64], used: set[int], depth: int) -> bool:
        """Alternating path from free end u: u takes v, v's old partner w goes on."""
        for v in cand[u]:
            if v in used or v % n == u % n:
                continue
            w = int(trial[v])
            if w < 0:
                t = trial.copy()
                t[u], t[v] = v, u
                if _acyclic(t, n) and ok(u, v):
                    trial[:] = t
                    return True
                continue
            if depth == 0 or w in used:
                continue
            t = trial.copy()
            t[u], t[v], t[w] = v, u, -1
            if augment(w, t, used | {u, v}, depth - 1) and ok(u, v):
                trial[:] = t
                return True
        return False

    improved = True
    while improved:
        improved = False
        for u in range(2 * n):
            if partner[u] >= 0 or not cand[u]:
                continue
            trial = partner.copy()
            if augment(u, trial, {u}, AUGMENT_DEPTH):
                partner = trial
                improved = True
    if length is not None:
        partner = _shorten(partner, n, cand, length, ok)
    return partner


def _shorten(partner: NDArray[np.int64], n: int, cand: list[list[int]],
             length: Callable[[int, int], float], ok: Callable[[int, int], bool],
             sweeps: int = SHORTEN_SWEEPS) -> NDArray[np.int64]:
    """Same number of joins, shorter in total: 2-opt exchanges of two joins (a, b), (c, d)
    for (a, c), (b, d) and moves of a join (a, b) to a nearer free end c, kept when acyclic.
    Every join deposits a connector, and its volume widens the line spacing of the volume
    match, so at an equal count of starts shorter joins are better."""
    partner = partner.copy()
    cand_set = [set(c) for c in cand]
    for _ in range(sweeps):
        changed = False
        for a in np.flatnonzero(partner >= 0).tolist():
            b = int(partner[a])
            if b < 0:
                continue
            for c in cand[a]:
                if c == b or c % n == a % n:
                    continue
                d = int(partner[c])
                t = partner.copy()
                if d < 0:  # a leaves b for the free end c
                    if length(a, c) >= length(a, b) - tol.merge:
                        continue
                    t[b], t[a], t[c] = -1, c, a
                else:
                    if d == a or d not in cand_set[b] or d % n == b % n:
                        continue
                    if length(a, c) + length(b, d) >= length(a, b) + length(c, d) - tol.merge:
                        continue
                    t[a], t[c], t[b], t[d] = c, a, d, b
                if _acyclic(t, n) and ok(a, c) and (d < 0 or ok(b, d)):
                    partner = t
                    changed = True
                    break
        if not changed:
            break
    return partner


def _order_cover(lines: SurfaceLines, start_pos: NDArray[np.float64],
                 reach: NDArray[np.float64],
                 can_join: Callable[[int, int], bool] | None = None,
                 closed_first: bool = False, spacing: float | None = None) -> list[Piece]:
    """Stripes as a path cover: lines are edges between their two end nodes; joins pair
    ends (``_match_ends``: each end at most once, never closing a cycle) so that the chains
    of lines cover the component with few starts. ``can_join(point_a, point_b)`` (point
    indices of two line ends) may veto a join, e.g. one without a short on-surface
    connector. The chains are printed nearest-neighbour first (each entered at its nearer
    end; closed lines at their nearest point). ``closed_first``: a closed line (a stripe
    layer's perimeter loop) before the chains, left next to a chain end. With ``spacing``
    (mm, the lines' spacing), a join whose connector would cross another line is left out
    (``join_crossing``).
    """
    idx = line_index(lines)
    n = lines.n_lines
    alive = idx.stop > idx.start
    if not np.any(alive):
        return []
    first, last = idx.start, np.maximum(idx.stop - 1, idx.start)
    end_point = np.concatenate([first, last]).astype(np.int64)  # end e: line e % n
    ends = lines.points[end_point]
    radius = reach[end_point]
    open_alive = alive & ~lines.closed
    a_c, b_c, d_c = _join_candidates(ends, radius, n, open_alive)
    cand: list[list[int]] = [[] for _ in range(2 * n)]
    dist: dict[tuple[int, int], float] = {}
    for a, b, d in zip(a_c.tolist(), b_c.tolist(), d_c.tolist(), strict=True):  # nearest first
        cand[a].append(b)
        cand[b].append(a)
        dist[(min(a, b), max(a, b))] = d
    crossing = JoinCrossing(lines, spacing) if spacing is not None else None

    def joinable(a: int, b: int) -> bool:
        pa, pb = int(end_point[a]), int(end_point[b])
        if crossing is not None and crossing.crosses(pa, pb):
            return False
        return can_join is None or can_join(pa, pb)

    partner = _match_ends(n, cand, joinable, lambda a, b: dist[(min(a, b), max(a, b))])
    # chains: from each free end of an open line, walk line -> join -> line
    chains: list[list[Piece]] = []
    seen = np.zeros(n, dtype=bool)
    for e in np.flatnonzero(np.r_[open_alive, open_alive] & (partner < 0)).tolist():
        if seen[e % n]:
            continue
        chain: list[Piece] = []
        cur = e
        while cur >= 0:
            line = cur % n
            seen[line] = True
            ids = np.arange(idx.start[line], idx.stop[line], dtype=np.int64)
            chain.append(Piece(ids if cur < n else ids[::-1], line))
            cur = int(partner[(cur + n) % (2 * n)])
        chains.append(chain)
    closed_todo = np.flatnonzero(alive & lines.closed)
    # nearest-neighbour order over chains (by their ends) and closed lines
    pos = np.asarray(start_pos, dtype=np.float64)
    heads = np.array([lines.points[c[0].points[0]] for c in chains]).reshape(-1, 3)
    tails = np.array([lines.points[c[-1].points[-1]] for c in chains]).reshape(-1, 3)
    todo = np.ones(len(chains), dtype=bool)
    pieces: list[Piece] = []
    first_loop = closed_first
    while todo.any() or closed_todo.size:
        best, best_d, flip = -1, np.inf, False
        if todo.any():
            left = np.flatnonzero(todo)
            dh = np.linalg.norm(heads[left] - pos, axis=1)
            dt = np.linalg.norm(tails[left] - pos, axis=1)
            k = int(np.argmin(np.minimum(dh, dt)))
            best, best_d, flip = int(left[k]), float(min(dh[k], dt[k])), bool(dt[k] < dh[k])
        if first_loop and closed_todo.size and todo.any():
            # one loop first, entered (and left) where it comes closest to a chain end, so
            # the connector from it into the chains is short enough to extrude; further
            # loops (around holes) follow nearest-neighbour among the chains
            first_loop = False
            left = np.flatnonzero(todo)
            chain_ends = np.concatenate([heads[left], tails[left]])
            gaps = [cKDTree(lines.points[idx.start[c]:idx.stop[c]]).query(chain_ends)[0]
                    for c in closed_todo.tolist()]
            k = int(np.argmin([g.min() for g in gaps]))
            line = int(closed_todo[k])
            piece, pos = _piece(lines, int(idx.start[line]), int(idx.stop[line]), line,
                                chain_ends[int(np.argmin(gaps[k]))])
            pieces.append(piece)
            closed_todo = np.delete(closed_todo, k)
            continue
        if closed_todo.size:
            dc = _entry_distance(lines, idx.start, idx.stop, closed_todo, pos)
            k = int(np.argmin(dc))
            if dc[k] < best_d:
                line = int(closed_todo[k])
                piece, pos = _piece(lines, int(idx.start[line]), int(idx.stop[line]), line, pos)
                pieces.append(piece)
                closed_todo = np.delete(closed_todo, k)
                continue
        todo[best] = False
        chain = chains[best]
        if flip:
            chain = [Piece(p.points[::-1], p.line) for p in chain[::-1]]
        pieces.extend(chain)
        pos = lines.points[chain[-1].points[-1]]
    return pieces


def order_lines(
    lines: SurfaceLines,
    start_pos: NDArray[np.float64],
    level: NDArray[np.float64] | None = None,
    level_step: float = 1.0,
    reach: NDArray[np.float64] | None = None,
    can_join: Callable[[int, int], bool] | None = None,
    closed_first: bool = False,
) -> list[Piece]:
    """Order all lines; contours by ``level`` (outside-in), then nearest neighbour.

    Args:
        lines: the component's lines (on the original layer).
        start_pos: (3,) float64, mm, the nozzle position before the first line.
        level: (L,) float64, mm, per-line distance from the boundary (contours) or None
            (stripes).
        level_step: mm, levels in the same interval [k, k + 1) * level_step form one ring;
            for stripes the lines' spacing (joins crossing another line are left out).
        reach: (P,) float64, mm, per point: the longest join that still extrudes. With it,
            stripes (level None) follow ``_order_cover``; without, pure nearest neighbour.
        can_join: (point a, point b) -> bool, whether two line ends may be joined by an
            extruding connector (``linking.Joiner.can_join``); None: any within reach.
        closed_first: stripes with ``reach``: a closed line (a perimeter loop) first.

    Returns:
        The pieces in print order.
    """
    if level is None and reach is not None:
        return _order_cover(lines, start_pos, reach, can_join, closed_first, level_step)
    idx = line_index(lines)
    n = lines.n_lines
    alive = idx.stop > idx.start
    if level is None:
        ring = np.zeros(n, dtype=np.int64)
    else:
        # contour k sits at (k + 1/2) * step: floor keeps rings apart (round would merge
        # 1.5 and 2.5 by rounding half to even)
        ring = np.floor(np.asarray(level) / max(level_step, tol.floor)).astype(np.int64)
    pos = np.asarray(start_pos, dtype=np.float64)
    splices: dict[int, Splice] = {}
    if level is not None and can_join is not None:
        splices = find_splices(lines, idx, np.asarray(level, dtype=np.float64), can_join)
        if splices:
            # start the component beside the first loop that hosts an open line, so the
            # loops printed before it end there and join it
            first = min(splices.values(), key=lambda sp: (ring[sp.loop], level[sp.loop]))
            pos = lines.points[first.near_first]
    done = ~alive
    pieces: list[Piece] = []
    for r in np.unique(ring[alive]):
        todo = np.flatnonzero(~done & (ring == r))
        while todo.size:
            dist = _entry_distance(lines, idx.start, idx.stop, todo, pos)
            k = int(np.argmin(dist))
            line = int(todo[k])
            piece: Piece | None
            piece, end = _piece(lines, int(idx.start[line]), int(idx.stop[line]), line, pos)
            sp = splices.get(line)
            if sp is not None and not done[sp.line] and can_join is not None:
                runs, last = spliced_points(lines, idx, sp, pos)
                prev = int(pieces[-1].points[-1]) if pieces else None
                # splice unless it breaks the join into the loop that its usual entry makes
                if (prev is None or can_join(prev, int(runs[0][0][0]))
                        or not can_join(prev, int(piece.points[0]))):
                    pieces.extend(Piece(run, lid) for run, lid in runs)
                    done[sp.line] = True
                    piece, end = None, lines.points[last]
            if piece is not None:
                pieces.append(piece)
            pos = end
            done[line] = True
            todo = todo[~done[todo]]
    return pieces


def line_levels(lines: SurfaceLines, point_value: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mean of a per-point value over each line, (L,) float64."""
    n = lines.n_lines
    count = np.bincount(lines.line, minlength=n)[:n]
    total = np.bincount(lines.line, weights=point_value, minlength=n)[:n]
    return total / np.maximum(count, 1)
