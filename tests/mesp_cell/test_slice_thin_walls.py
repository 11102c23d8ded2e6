"""`mesp slice` on a wall thinner than the narrowest line: refused with the size that prints
it, and that size, followed, prints it within the limit."""

from __future__ import annotations

import json
import re
from pathlib import Path

import meshio
import pytest

from slicer.toolpath.thin_features import EXCESS_LIMIT
from tests.mesp_cell.test_slice_cli import mesp
from tests.slicer.conftest import box_mesh

pytestmark = pytest.mark.slow


def test_a_thin_wall_is_refused_and_the_named_size_prints_it(tmp_path: Path) -> None:
    """A 20 x 0.4 x 6 mm wall sliced flat at 1 mm: each layer a 0.4 mm strip under a
    narrowest line of about 0.9 mm (before: printed with about 2.3x its volume, one note)."""
    mesh = box_mesh(n=(10, 1, 3), size=(20.0, 0.4, 6.0))
    model = tmp_path / "wall.vtu"
    meshio.write(model, meshio.Mesh(mesh.vertices, [("tetra", mesh.tets)]))
    common = ["--planar", "--layer-height", "1.0", "--no-baselines", "--quiet"]
    refused = mesp("slice", str(model), "--out", str(tmp_path / "thin"), *common)
    assert refused.returncode == 2, refused.stderr
    (line,) = refused.stderr.strip().splitlines()
    assert line.startswith("mesp: error: wall.vtu has walls about 0.4")
    assert "thinner than the narrowest line" in line and "--scale-to" in line
    assert not (tmp_path / "thin" / "toolpath.npz").exists()  # refused before any toolpath
    marked = json.loads((tmp_path / "thin" / "report.json").read_text())["toolpath"]
    assert marked["too_thin"]["excess_share"] > EXCESS_LIMIT and marked["too_thin"]["layers"]
    size = re.search(r"--scale-to (\d+)", line)
    assert size is not None
    printed = mesp("slice", str(model), "--out", str(tmp_path / "fit"), *common,
                   "--scale-to", size.group(1))
    assert printed.returncode == 0, printed.stderr
    report = json.loads((tmp_path / "fit" / "report.json").read_text())["toolpath"]
    assert report["too_thin"]["excess_share"] <= EXCESS_LIMIT
    assert abs(report["volume_error"]) <= EXCESS_LIMIT
