"""Stripe-layer perimeter: clipping lines by a distance field, the perimeter loop."""

from __future__ import annotations

import numpy as np

from slicer.toolpath.isolines import iso_lines
from slicer.toolpath.mapback import interpolate
from slicer.toolpath.perimeter import clip_lines, perimeter_loop
from slicer.toolpath.resample import line_index, line_lengths
from tests.slicer.toolpath.pattern_meshes import disc

R = 10.0


def _radial_distance() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Disc of radius R with the exact flat boundary distance R - r per vertex."""
    v, f = disc(R, 0.7, jitter=0.2, seed=3)
    return v, f, R - np.linalg.norm(v[:, :2], axis=1)


def test_clipped_chords_end_on_the_threshold() -> None:
    v, f, d = _radial_distance()
    xs = np.array([-6.0, -2.5, 0.3, 4.0])
    chords = iso_lines(v, f, v[:, 0], xs)
    thr = 2.0
    out = clip_lines(chords, v, f, d, thr)
    # points consistent with their face / barycentrics, all at or beyond the threshold
    assert np.allclose(interpolate(v, f, out.face, out.bary), out.points, atol=1e-9)
    d_pt = interpolate(d, f, out.face, out.bary)
    assert d_pt.min() >= thr - 1e-9
    # one open piece per chord, its ends exactly on the threshold
    assert out.n_lines == len(xs) and not out.closed.any()
    idx = line_index(out)
    ends = np.concatenate([idx.start, idx.stop - 1])
    assert np.allclose(d_pt[ends], thr, atol=1e-9)
    # length: the chord of the circle r = R - thr (up to the boundary's polygon)
    x_of = out.points[idx.start, 0]
    expect = 2 * np.sqrt((R - thr) ** 2 - x_of ** 2)
    assert np.allclose(np.sort(line_lengths(out)), np.sort(expect), rtol=0.02)


def test_a_dropped_middle_splits_a_line() -> None:
    v, f, _ = _radial_distance()
    chord = iso_lines(v, f, v[:, 0], np.array([0.0]))
    # distance from the line x = 0 ... clipped where |y| < 3: two pieces remain
    dist = np.abs(v[:, 1])
    out = clip_lines(chord, v, f, dist, 3.0)
    assert out.n_lines == 2
    ys = out.points[:, 1]
    assert np.all(np.abs(ys) >= 3.0 - 1e-9)
    assert {bool(np.all(ys[out.line == k] > 0)) for k in range(2)} == {True, False}


def test_closed_loops_kept_whole_or_opened() -> None:
    v, f, d = _radial_distance()
    loops = iso_lines(v, f, d, np.array([3.0]))
    assert loops.n_lines == 1 and loops.closed[0]
    kept = clip_lines(loops, v, f, d, 2.0)  # wholly inside: unchanged, still closed
    assert kept.n_lines == 1 and kept.closed[0] and len(kept.points) == len(loops.points)
    assert clip_lines(loops, v, f, d, 4.0).n_lines == 0  # wholly outside: gone
    # clipped by a half plane: open, all remaining points at x >= 1
    cut = clip_lines(loops, v, f, v[:, 0] - 1.0, 0.0)
    assert cut.n_lines >= 1 and not cut.closed.any()
    assert cut.points[:, 0].min() >= 1.0 - 1e-9
    # the kept arc: the part of the circle r = R - 3 with x >= 1 (split at most at the seam)
    arc = 2 * (R - 3.0) * np.arccos(1.0 / (R - 3.0))
    assert abs(line_lengths(cut).sum() - arc) < 0.02 * arc


def test_perimeter_loop_half_a_spacing_inside() -> None:
    v, f, d = _radial_distance()
    loop = perimeter_loop(v, f, d, 3.0)
    assert loop.n_lines == 1 and loop.closed[0]
    r = np.linalg.norm(loop.points[:, :2], axis=1)
    assert np.allclose(R - r, 1.5, atol=0.05)
    assert perimeter_loop(v, f, d, 2.5 * R).n_lines == 0  # narrower than half a spacing
