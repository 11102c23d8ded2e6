"""Coverage of a layer by W-wide bands: analytic cases on a flat 10 x 10 mm square."""

from __future__ import annotations

import numpy as np
import pytest

from core.stages import Layers, Toolpath
from slicer.toolpath.coverage import layer_coverage as _coverage


def layer_coverage(layers: Layers, tp: Toolpath) -> object:
    """Dense sampling: the analytic shares below hold to about +-0.5 %."""
    return _coverage(layers, tp, samples_per_w2=100.0, max_samples=20_000)


def square_layers(size: float = 10.0, n: int = 10) -> Layers:
    """A flat square [0, size]^2 at z = 0, one layer, triangulated on an n x n grid."""
    x, y = np.meshgrid(np.linspace(0, size, n + 1), np.linspace(0, size, n + 1), indexing="ij")
    v = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.column_stack([a, b, c]),
                            np.column_stack([a, c, d])]).astype(np.int32)
    return Layers(vertices=v, faces=faces, face_layer=np.zeros(len(faces), dtype=np.int32),
                  vertex_height=np.full(len(v), 0.6),
                  vertex_direction=np.tile([0.0, 0.0, 1.0], (len(v), 1)))


def lines_toolpath(ys: np.ndarray, width: float, size: float = 10.0, one_path: bool = False,
                   lift: float = 0.0) -> Toolpath:
    """Straight lines along x at heights ``ys`` (each its own path, or one zig-zag path)."""
    pos, path = [], []
    xs = np.linspace(0.0, size, 31)
    for k, y in enumerate(ys):
        line = xs if k % 2 == 0 or not one_path else xs[::-1]
        pos.append(np.column_stack([line, np.full_like(line, y), np.full_like(line, lift)]))
        path.append(np.full(len(line), 0 if one_path else k))
    p = np.concatenate(pos)
    n = len(p)
    return Toolpath(position=p, normal=np.tile([0.0, 0.0, 1.0], (n, 1)),
                    layer=np.zeros(n, dtype=np.int32),
                    path=np.concatenate(path).astype(np.int32), height=np.full(n, 0.6),
                    width=np.full(n, width), speed=np.full(n, 10.0),
                    extrude=np.ones(n, dtype=bool), pattern=np.ones(n, dtype=np.int8))


def test_lines_spaced_one_width_cover_the_square_once() -> None:
    w = 1.0
    cov = layer_coverage(square_layers(), lines_toolpath(np.arange(0.5, 10.0, w), w))
    assert cov.gap[0] < 0.01
    assert cov.overlap[0] < 0.01
    assert cov.pattern[0] == 1
    assert cov.area[0] == pytest.approx(100.0)


@pytest.mark.parametrize("spacing", [1.25, 1.5])
def test_wider_spacing_leaves_the_analytic_gap(spacing: float) -> None:
    w = 1.0
    ys = np.arange(0.5 * spacing, 10.0, spacing)
    cov = layer_coverage(square_layers(), lines_toolpath(ys, w))
    # the bands clipped to the square
    covered = np.clip(ys + w / 2, 0, 10) - np.clip(ys - w / 2, 0, 10)
    bare = 1.0 - covered.sum() * 10.0 / 100.0
    assert cov.gap[0] == pytest.approx(bare, abs=0.015)
    assert cov.overlap[0] < 0.01


def test_closer_spacing_covers_twice_the_analytic_share() -> None:
    w, spacing = 1.0, 0.8
    ys = np.arange(0.5, 10.0 - 0.4, spacing)
    cov = layer_coverage(square_layers(), lines_toolpath(ys, w))
    # each of the len(ys) - 1 neighbour pairs overlaps by (w - spacing) over 10 mm
    assert cov.overlap[0] == pytest.approx((len(ys) - 1) * (w - spacing) * 10.0 / 100.0,
                                           abs=0.02)


def test_one_zigzag_path_counts_each_line_as_its_own_pass() -> None:
    w = 1.0
    single = layer_coverage(square_layers(), lines_toolpath(np.arange(0.5, 10.0, 0.8), w,
                                                            one_path=True))
    separate = layer_coverage(square_layers(), lines_toolpath(np.arange(0.5, 10.0, 0.8), w))
    # the same as separate lines but near the turns, where one path's ends within 2 W of arc
    # length of each other are one pass
    assert separate.overlap[0] > 0.15
    assert single.overlap[0] == pytest.approx(separate.overlap[0], abs=0.03)


def test_a_lifted_path_still_covers_the_layer_under_it() -> None:
    w = 1.0
    cov = layer_coverage(square_layers(), lines_toolpath(np.arange(0.5, 10.0, w), w, lift=0.3))
    assert cov.gap[0] < 0.01


def test_a_layer_without_waypoints_is_bare_and_reported() -> None:
    w = 1.0
    tp = lines_toolpath(np.arange(0.5, 10.0, w), w)
    two = square_layers()
    lifted = two.vertices + np.array([0.0, 0.0, 1.0])
    layers = Layers(vertices=np.concatenate([two.vertices, lifted]),
                    faces=np.concatenate([two.faces, two.faces + len(two.vertices)]),
                    face_layer=np.repeat(np.array([0, 1], dtype=np.int32), len(two.faces)),
                    vertex_height=np.full(2 * len(two.vertices), 0.6),
                    vertex_direction=np.tile([0.0, 0.0, 1.0], (2 * len(two.vertices), 1)))
    cov = layer_coverage(layers, tp)
    assert cov.gap[1] == 1.0
    summary = cov.summary()
    assert summary["unprinted_layers"] == 1
    assert summary["unprinted_area_fraction"] == pytest.approx(0.5)


def test_the_same_toolpath_gives_the_same_numbers() -> None:
    tp = lines_toolpath(np.arange(0.6, 10.0, 1.2), 1.0)
    a, b = layer_coverage(square_layers(), tp), layer_coverage(square_layers(), tp)
    assert a.gap[0] == b.gap[0] and a.overlap[0] == b.overlap[0]
