"""Stripe ordering as a path cover: joins pair line ends, each once, never closing a cycle."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from slicer.toolpath.lines import SurfaceLines
from slicer.toolpath.linking import Joiner, Lifter, link_pieces, mesh_graph
from slicer.toolpath.ordering import Piece, _acyclic, _match_ends, order_lines

from .test_build import disc_mesh
from .test_linking import _locate


def _polylines(v: np.ndarray, f: np.ndarray, ends: list[tuple[tuple[float, float],
                                                             tuple[float, float]]]
               ) -> SurfaceLines:
    """Straight open lines between the given (x, y) end pairs on the flat mesh (v, f)."""
    pts, line = [], []
    for i, (a, b) in enumerate(ends):
        t = np.linspace(0.0, 1.0, 12)[:, None]
        xy = (1 - t) * np.array(a) + t * np.array(b)
        pts.append(np.column_stack([xy, np.zeros(len(xy))]))
        line.append(np.full(len(xy), i))
    p = np.concatenate(pts)
    face, bary = _locate(p, v, f)
    return SurfaceLines(p, face, bary, np.concatenate(line).astype(np.int32),
                        np.zeros(len(ends), bool))


def _chains(lines: SurfaceLines, pieces: list[Piece], reach: float) -> int:
    gaps = [np.linalg.norm(lines.points[q.points[0]] - lines.points[p.points[-1]])
            for p, q in itertools.pairwise(pieces)]
    return 1 + int(np.sum(np.array(gaps) > reach))


def _optimum(n: int, edges: list[tuple[int, int]]) -> int:
    """Largest acyclic matching by exhaustive search (tiny instances only)."""
    best = 0
    partner = np.full(2 * n, -1, dtype=np.int64)

    def rec(k: int, count: int) -> None:
        nonlocal best
        if count + len(edges) - k <= best:
            return
        if k == len(edges):
            best = count
            return
        a, b = edges[k]
        if partner[a] < 0 and partner[b] < 0:
            partner[a], partner[b] = b, a
            if _acyclic(partner, n):
                rec(k + 1, count + 1)
            partner[a] = partner[b] = -1
        rec(k + 1, count)

    rec(0, 0)
    return best


@pytest.fixture(scope="module")
def disc() -> tuple[np.ndarray, np.ndarray]:
    return disc_mesh(12.0, 1.0)


def test_ends_with_one_option_are_joined_first(disc: tuple[np.ndarray, np.ndarray]) -> None:
    """Four ends in a row 1.1, 1.0, 1.1 mm apart (reach 1.5): joining the closest pair (the
    middle one) would strand both outer ends; the cover joins the outer pairs: 2 chains."""
    v, f = disc
    row = [-1.6, -0.5, 0.5, 1.6]
    far = [150.0, 110.0, 70.0, 30.0]
    ends = [((x, -1.0), (9 * np.cos(np.radians(a)), 9 * np.sin(np.radians(a))))
            for x, a in zip(row, far, strict=True)]
    lines = _polylines(v, f, ends)
    reach = np.full(len(lines.points), 1.5)
    pieces = order_lines(lines, np.array([-9.0, 0.0, 0.0]), reach=reach)
    assert sorted(p.line for p in pieces) == [0, 1, 2, 3]
    assert _chains(lines, pieces, 1.5) == 2
    lifter = Lifter(v, np.tile([0.0, 0.0, 1.0], (len(v), 1)))
    width = np.full(len(lines.points), 0.5)
    joiner = Joiner(lines, v, f, mesh_graph(v, f), width, lifter, 3.0)
    pieces = order_lines(lines, np.array([-9.0, 0.0, 0.0]), reach=reach,
                         can_join=joiner.can_join)
    linked = link_pieces(lines, pieces, v, f, mesh_graph(v, f), width, lifter, 0.9, 3.0,
                         joiner)
    assert linked.extrusion_starts == 2


def test_two_stripes_with_both_ends_close_make_one_chain(
        disc: tuple[np.ndarray, np.ndarray]) -> None:
    """Joining both pairs of ends would close a loop: one join, one chain, each line once."""
    v, f = disc
    lines = _polylines(v, f, [((-3.0, 0.0), (3.0, 0.0)), ((-3.0, 1.0), (3.0, 1.0))])
    pieces = order_lines(lines, np.array([-5.0, 0.0, 0.0]), reach=np.full(len(lines.points),
                                                                          1.5))
    assert sorted(p.line for p in pieces) == [0, 1]
    assert _chains(lines, pieces, 1.5) == 1
    # the second stripe runs back: a zig-zag
    d0 = lines.points[pieces[0].points[-1]] - lines.points[pieces[0].points[0]]
    d1 = lines.points[pieces[1].points[-1]] - lines.points[pieces[1].points[0]]
    assert d0 @ d1 < 0


def test_a_vetoed_join_is_not_used(disc: tuple[np.ndarray, np.ndarray]) -> None:
    v, f = disc
    lines = _polylines(v, f, [((-3.0, 0.0), (3.0, 0.0)), ((-3.0, 1.0), (3.0, 1.0))])
    reach = np.full(len(lines.points), 1.5)
    asked: list[tuple[int, int]] = []

    def no_left_join(a: int, b: int) -> bool:
        asked.append((a, b))
        return lines.points[a, 0] > 0  # only the right ends (x = 3) may be joined

    pieces = order_lines(lines, np.array([-5.0, 0.0, 0.0]), reach=reach, can_join=no_left_join)
    assert asked
    assert _chains(lines, pieces, 1.5) == 1
    assert lines.points[pieces[0].points[-1], 0] == pytest.approx(3.0)  # joined on the right
    assert lines.points[pieces[1].points[0], 0] == pytest.approx(3.0)


def _greedy_shortest_first(n: int, edges: list[tuple[int, int]]) -> int:
    """Joins of the plain greedy: shortest first, skipping used ends and cycles."""
    partner = np.full(2 * n, -1, dtype=np.int64)
    count = 0
    for a, b in edges:
        if partner[a] < 0 and partner[b] < 0:
            partner[a], partner[b] = b, a
            if _acyclic(partner, n):
                count += 1
            else:
                partner[a] = partner[b] = -1
    return count


def test_matching_is_acyclic_and_near_maximum_on_small_sets() -> None:
    optimal, total = 0, 60
    for seed in range(total):
        rng = np.random.default_rng(seed)
        n = 7
        ends = rng.uniform(0.0, 6.0, (2 * n, 2))
        d = np.linalg.norm(ends[:, None] - ends[None], axis=2)
        edges = sorted(((a, b) for a in range(2 * n) for b in range(a + 1, 2 * n)
                        if a % n != b % n and d[a, b] < 1.8), key=lambda e: d[e])
        cand: list[list[int]] = [[] for _ in range(2 * n)]
        for a, b in edges:
            cand[a].append(b)
            cand[b].append(a)
        partner = _match_ends(n, cand, lambda a, b: True,
                              lambda a, b: float(d[a, b]))  # noqa: B023
        assert _acyclic(partner, n)
        joined = np.flatnonzero(partner >= 0)
        assert np.array_equal(partner[partner[joined]], joined)  # symmetric
        assert all((min(a, int(partner[a])), max(a, int(partner[a]))) in set(edges)
                   for a in joined)
        count = joined.size // 2
        best = _optimum(n, edges)
        assert best - 1 <= count <= best
        assert count >= _greedy_shortest_first(n, edges)
        optimal += count == best
    assert optimal >= 0.9 * total


def test_random_stripes_are_each_printed_once(disc: tuple[np.ndarray, np.ndarray]) -> None:
    v, f = disc
    rng = np.random.default_rng(5)
    starts = rng.uniform(-6.0, 6.0, (25, 2))
    ang = rng.uniform(0, 2 * np.pi, 25)
    ends = [((float(s[0]), float(s[1])),
             (float(s[0] + 2.5 * np.cos(a)), float(s[1] + 2.5 * np.sin(a))))
            for s, a in zip(starts, ang, strict=True)]
    lines = _polylines(v, f, ends)
    reach = np.full(len(lines.points), 1.5)
    pieces = order_lines(lines, np.zeros(3), reach=reach)
    assert sorted(p.line for p in pieces) == list(range(25))
    for p in pieces:  # whole lines, forwards or backwards
        assert len(p.points) == 12 and abs(int(p.points[-1]) - int(p.points[0])) == 11
    # no more chains than joining the nearest free ends first would leave
    pts_end = np.array([[lines.points[12 * i], lines.points[12 * i + 11]] for i in range(25)])
    flat = pts_end.reshape(-1, 3)
    dd = np.linalg.norm(flat[:, None] - flat[None], axis=2)
    pairs = sorted(((a, b) for a in range(50) for b in range(a + 1, 50)
                    if a // 2 != b // 2 and dd[a, b] <= 1.5), key=lambda e: dd[e])
    partner = np.full(50, -1)
    comp = list(range(25))

    def root(i: int) -> int:
        while comp[i] != i:
            i = comp[i]
        return i

    greedy = 0
    for a, b in pairs:
        if partner[a] < 0 and partner[b] < 0 and root(a // 2) != root(b // 2):
            partner[a], partner[b] = b, a
            comp[root(a // 2)] = root(b // 2)
            greedy += 1
    assert _chains(lines, pieces, 1.5) <= 25 - greedy
