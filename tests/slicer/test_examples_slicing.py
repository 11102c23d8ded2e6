"""Issue 2 acceptance on the shipped examples, at a coarse mesh.

The socket (rim critical, ``top:45``) and the aorta arch (``bottom:30``: two tube ends and the
downward-facing strips of the arch) are tetrahedralised at 6 mm (fTetWild, 1 optimisation
pass where a job runs 10: a rougher mesh, on which the criteria still hold by a wide margin;
8 mm leaves the aorta's thin arch wall with flat, disconnected slivers) and sliced with
their job files' critical selectors. The criteria: final layer-height std at most 30 % of the
initial (the scalar harmonic G0) and coefficient of variation at most 0.20; every critical
region lies on one layer.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from slicer.config import MeshConfig, load_job
from slicer.field import FieldResult, compute_field
from slicer.layers import extract_layers
from slicer.mesh_io import load_surface
from slicer.tetrahedralize import tetrahedralize

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
EDGE_MM = 6.0
OPTIMIZE_ITERATIONS = 1

#: the regions the examples' critical selectors find (the socket's rim: two patches of ~3.7k
#: mm^2; the aorta: 18-330 mm^2), and the share of the selected area further regions may hold
#: (slivers at a cone's edge, ``assert_the_selected_regions``)
EXPECTED_REGIONS = {"socket": 2, "aorta": 5}
SLIVER_AREA = 0.05

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module", params=[("socket", EDGE_MM, 0), ("aorta", EDGE_MM, 0),
                                        ("socket", 4.0, 1)],
                ids=["socket", "aorta", "socket-refined"])
def sliced(request: pytest.FixtureRequest) -> tuple[str, FieldResult, list[dict[str, object]]]:
    """(example name, field result, critical-region report of the layer extraction).

    ``socket-refined``: fTetWild at 8 mm, then one red refinement with the boundary snapped
    (``[mesh] refine``, the default for large models): the same criteria hold on it.
    """
    example, edge, refine = request.param
    name = f"{example}-refined" if refine else example
    job = load_job(EXAMPLES / f"{example}.toml")
    mesh, stats = tetrahedralize(load_surface(EXAMPLES / f"{example}.stl"),
                                 MeshConfig(edge_length_mm=edge, refine=refine,
                                            optimize_iterations=OPTIMIZE_ITERATIONS))
    assert stats.refinements == refine
    res = compute_field(mesh, job.slicing)
    out = extract_layers(mesh, res, job.slicing)
    return name, res, list(out.critical_report)


def assert_the_selected_regions(name: str, res: FieldResult) -> None:
    """The job's selectors find at least the example's patches, and any further region is a
    sliver of the tet mesh's surface at the selector's cone edge (a few faces).

    fTetWild's surface differs from run to run, and faces whose normals sit at the cone's edge
    form patches of their own (patches of 1-2 faces, dropped below ``MIN_REGION_FACES``, in 4
    of 9 meshes of these examples; one of 3 faces would be kept as a region): the count of
    regions is not a property of the example, what they cover is.
    """
    areas = sorted((r.area for r in res.regions.regions), reverse=True)
    expected = EXPECTED_REGIONS[name.removesuffix("-refined")]
    assert len(areas) >= expected, (name, areas, res.regions.notes)
    assert sum(areas[expected:]) <= SLIVER_AREA * sum(areas), (name, areas)


def test_layer_height_is_controlled(
        sliced: tuple[str, FieldResult, list[dict[str, object]]]) -> None:
    name, res, _ = sliced
    # At 6 mm the iteration converges; on the refined mesh (~12k tets refined to ~100k) it is
    # still improving when the 30 iterations run out, as on the full-size socket (direct or
    # refined: O_align still changing by over 1 % per iteration at a 0.005 mm height std).
    allowed = ("converged", "max_iterations") if name.endswith("-refined") else ("converged",)
    assert res.status in allowed, (name, res.status, res.notes)
    assert_the_selected_regions(name, res)
    assert res.height.std <= 0.30 * res.height_initial.std, (name, res.report())
    assert res.height.cv <= 0.20, (name, res.report())
    # The iteration improves on its own start (the harmonic vector field) too.
    assert res.height_start is not None
    assert res.height.std < res.height_start.std, (name, res.report())
    assert res.trace.height_std[-1] == pytest.approx(res.height.std)


def test_each_critical_region_is_one_layer(
        sliced: tuple[str, FieldResult, list[dict[str, object]]]) -> None:
    name, res, critical = sliced
    assert len(critical) == len(res.regions.regions)
    assert all(bool(c["on_one_layer"]) for c in critical), (name, critical)
    for region in res.regions.regions:
        vals = res.g[region.vertices]
        assert float(vals.max() - vals.min()) == 0.0
