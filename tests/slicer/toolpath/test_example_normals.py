"""Waypoint normals on a real example's curved layers (hemisphere, coarse): no spikes.

Marching tetrahedra leave needle triangles (slivers) in the layers whose own normals are
arbitrary; printed along a path, a waypoint on one used to point up to 70 degrees away from
both its neighbours (issue 3: 55 such waypoints on the socket). Waypoint normals are now
blended from area-weighted vertex normals (mapback.point_normals).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from core.stages import Layers
from slicer.config import JobConfig, MeshConfig, load_job
from slicer.extrusion import load_profile
from slicer.field import compute_field
from slicer.layers import extract_layers
from slicer.mesh_io import load_surface
from slicer.tetrahedralize import tetrahedralize
from slicer.toolpath.layer_build import layer_pattern, layer_toolpath

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
SPIKE_DEG = 20.0  # a waypoint this far from the mean of its two neighbours is a spike ...
AGREE_DEG = 10.0  # ... when the two neighbours agree within this

pytestmark = pytest.mark.slow


def spikes(normal: np.ndarray) -> np.ndarray:
    """(N,) bool, waypoints whose unit normal deviates more than SPIKE_DEG from the mean of
    its two path neighbours while those agree within AGREE_DEG."""
    out = np.zeros(len(normal), dtype=bool)
    if len(normal) < 3:
        return out
    a, b, c = normal[:-2], normal[1:-1], normal[2:]
    agree = np.einsum("ij,ij->i", a, c) > np.cos(np.radians(AGREE_DEG))
    mean = a + c
    mean /= np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-12)
    dev = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", b, mean), -1.0, 1.0)))
    out[1:-1] = agree & (dev > SPIKE_DEG)
    return out


@pytest.fixture(scope="module")
def hemisphere_layers() -> Layers:
    """The hemisphere example at 4 mm (about 3.4k tets), layers 1.5 mm apart (13 layers)."""
    job = load_job(EXAMPLES / "hemisphere.toml")
    mesh, _ = tetrahedralize(load_surface(EXAMPLES / "hemisphere.stl"),
                             MeshConfig(edge_length_mm=4.0, optimize_iterations=2))
    slicing = replace(job.slicing, layer_height_mm=1.5)
    return extract_layers(mesh, compute_field(mesh, slicing), slicing).layers


def test_spike_detector() -> None:
    n = np.tile([0.0, 0.0, 1.0], (5, 1))
    n[2] = [np.sin(0.6), 0.0, np.cos(0.6)]  # 34 degrees off
    assert spikes(n).tolist() == [False, False, True, False, False]
    n[3] = n[2]  # a turn, not a spike: the neighbours of 2 no longer agree
    assert not spikes(n)[2]


def test_layers_have_slivers(hemisphere_layers: Layers) -> None:
    """The fixture exercises the case: needle triangles (quality < 0.01) in the layers."""
    tri = hemisphere_layers.vertices[hemisphere_layers.faces]
    edge2 = (np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2) ** 2).sum(axis=1)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    quality = 4.0 * np.sqrt(3.0) * area / np.maximum(edge2, 1e-12)  # 1 for equilateral
    assert np.count_nonzero(quality < 0.01) > 0


def test_no_normal_spikes_on_example_layers(hemisphere_layers: Layers) -> None:
    cfg = JobConfig().toolpath
    profile = load_profile("ecoflex-0030")
    total = 0
    for i in range(hemisphere_layers.layer_count):
        res = layer_toolpath(hemisphere_layers.layer(i), layer_pattern(i, cfg.first_pattern),
                             cfg, profile, measure_baselines=False)
        wp = res.waypoints
        assert np.allclose(np.linalg.norm(wp.normal, axis=1), 1.0)
        bad = np.flatnonzero(spikes(wp.normal))
        assert bad.size == 0, (i, bad[:5])
        total += len(wp.position)
    assert total > 400  # 556 waypoints at the time of writing
