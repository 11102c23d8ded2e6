"""PrusaSlicer as the commercial baseline (sim.commercial, `mesp inspect --baseline prusaslicer`).

The slicer runs for real on tiny solids (a fraction of a second each); every test that needs
it skips, with the reason, when prusa-slicer is not installed (`make baselines`).
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.errors import InputError
from core.stages import Toolpath
from sim import commercial
from sim.baseline import VOLUME_MATCHING_BETA
from sim.commercial import (
    GCODE_FILE,
    STL_FILE,
    CommercialResult,
    PrusaConfig,
    prusa_settings,
    slice_with_prusaslicer,
)
from sim.deposition import EllipseMorphology
from sim.gcode import GcodeOptions, align_to_bounds, parse_gcode
from slicer.extrusion import load_profile

HAVE_PRUSASLICER = shutil.which(commercial.DEFAULT_EXECUTABLE) is not None
needs_prusaslicer = pytest.mark.skipif(
    not HAVE_PRUSASLICER,
    reason="prusa-slicer is not installed (make baselines, or apt-get install prusa-slicer)")

CUBE_MM = 10.0
H = 0.5


def _segment_volume(tp: Toolpath) -> float:
    """mm^3 the toolpath asks for: sum of segment length x H x W inside each path."""
    seg = np.linalg.norm(np.diff(tp.position, axis=0), axis=1)
    same = (tp.path[1:] == tp.path[:-1]) & tp.extrude[1:]
    return float(np.sum((seg * tp.width[1:] * tp.height[1:])[same]))


@pytest.fixture(scope="module")
def cube() -> trimesh.Trimesh:
    """A 10 mm cube away from the origin, so alignment has something to undo."""
    box = trimesh.creation.box(extents=[CUBE_MM] * 3)
    box.apply_translation([13.0, -4.0, 9.0])
    return box


@pytest.fixture(scope="module")
def printed(cube: trimesh.Trimesh, tmp_path_factory: pytest.TempPathFactory
            ) -> CommercialResult:
    if not HAVE_PRUSASLICER:
        pytest.skip("prusa-slicer is not installed (make baselines)")
    out = tmp_path_factory.mktemp("prusa")
    return slice_with_prusaslicer(cube.vertices, cube.faces, load_profile("ecoflex-0030"),
                                  PrusaConfig(layer_height_mm=H), out)


def test_settings_follow_the_profile_overlap_rule() -> None:
    """H = beta h_f and W = beta w_f at the one speed; PrusaSlicer's width adds its round ends."""
    prof = load_profile("ecoflex-0030")
    bounds = np.array([[0.0, 0.0, 0.0], [30.0, 10.0, 8.0]])
    for beta in (VOLUME_MATCHING_BETA, 0.7):
        s = prusa_settings(prof, PrusaConfig(layer_height_mm=0.6, beta=beta), bounds)
        w_f, h_f = (float(a[0]) for a in prof.filament_size(np.array([s.speed_mm_s])))
        assert beta * h_f == pytest.approx(0.6, rel=1e-3)
        assert s.line_spacing_mm == pytest.approx(beta * w_f, rel=1e-9)
        assert s.extrusion_width_mm - s.line_spacing_mm == pytest.approx(0.6 * (1 - math.pi / 4))
        # The ink per mm (W H times the multiplier) is the filament's section at v: the
        # G-code's volume rate at the feed v is the cell's constant rate C.
        ink = s.line_spacing_mm * 0.6 * s.extrusion_multiplier
        assert ink * s.speed_mm_s == pytest.approx(prof.rate_mm3_s, rel=0.02)
        assert s.nozzle_diameter_mm >= max(s.extrusion_width_mm, 0.6)
        assert s.bed_size_mm >= 30.0 + 2 * 20.0 and s.max_print_height_mm > 8.0
    opts = s.options()
    assert opts[opts.index("--fill-density") + 1] == "100%"
    assert opts[opts.index("--skirts") + 1] == "0" and "--no-support-material" in opts
    assert opts[opts.index("--infill-speed") + 1] == opts[opts.index("--perimeter-speed") + 1]


def test_slab_middle_alignment_is_half_a_layer_below_the_tops() -> None:
    """G-code Z is the layer top; deposition centres filaments on the tip: lower by H / 2."""
    text = "G1 X100 Y100 Z0.5\nG1 X110 Y100 E5\nG1 Z1.0\nG1 X100 Y100 E10\n"
    tp = parse_gcode(text, GcodeOptions(filament_diameter_mm=0.0))
    bounds = np.array([[-5.0, -2.0, 3.0], [5.0, 2.0, 4.0]])
    tops = align_to_bounds(tp, bounds)
    mids = align_to_bounds(tp, bounds, slab_middle=True)
    assert np.allclose(np.unique(tops.position[:, 2]), [3.5, 4.0])
    assert np.allclose(np.unique(mids.position[:, 2]), [3.25, 3.75])
    assert np.allclose(mids.position[:, :2], tops.position[:, :2])


def test_config_rejects_bad_values() -> None:
    with pytest.raises(InputError, match="layer height"):
        PrusaConfig(layer_height_mm=0.0)
    with pytest.raises(InputError, match="beta"):
        PrusaConfig(beta=1.5)
    with pytest.raises(InputError, match="limit of 2"):
        PrusaConfig(beta=0.5)  # would need extrusion multiplier pi > 2


def test_missing_prusaslicer_is_an_input_error(cube: trimesh.Trimesh, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(commercial, "DEFAULT_EXECUTABLE", "prusa-slicer-not-installed-xyz")
    with pytest.raises(InputError, match="not installed") as err:
        slice_with_prusaslicer(cube.vertices, cube.faces, EllipseMorphology(),
                               PrusaConfig(layer_height_mm=H), tmp_path)
    assert "make baselines" in err.value.fix
    assert not (tmp_path / GCODE_FILE).exists()


@needs_prusaslicer
def test_prusaslicer_failure_reports_its_message(cube: trimesh.Trimesh, tmp_path: Path) -> None:
    """A model PrusaSlicer cannot load: its own last stderr line is in the message."""
    stl = tmp_path / "empty.stl"
    stl.write_text("solid empty\nendsolid empty\n")
    settings = prusa_settings(EllipseMorphology(), PrusaConfig(layer_height_mm=H),
                              np.array([[0.0] * 3, [10.0] * 3]))
    with pytest.raises(InputError, match=r"PrusaSlicer failed on empty\.stl") as err:
        commercial.run_prusaslicer(stl, tmp_path / "x.gcode", settings,
                                   PrusaConfig(layer_height_mm=H))
    assert len(err.value.problem.split(": ", 1)[1]) > 0


@needs_prusaslicer
def test_files_version_and_report_info(printed: CommercialResult) -> None:
    assert printed.gcode_path.name == GCODE_FILE and printed.gcode_path.stat().st_size > 1000
    assert printed.stl_path.name == STL_FILE
    assert trimesh.load_mesh(printed.stl_path).is_watertight
    assert printed.version[0].isdigit()
    info = printed.info()
    assert info["kind"] == "prusaslicer" and info["settings"]["layer_height_mm"] == H


@needs_prusaslicer
def test_volume_matches_the_model(printed: CommercialResult, cube: trimesh.Trimesh) -> None:
    vol = _segment_volume(printed.toolpath)
    assert vol == pytest.approx(cube.volume, rel=0.04)


@needs_prusaslicer
def test_layers_are_planar_at_the_requested_height(printed: CommercialResult,
                                                   cube: trimesh.Trimesh) -> None:
    tp = printed.toolpath
    layers = np.unique(tp.layer)
    assert len(layers) == round(CUBE_MM / H)
    z_of = np.array([np.ptp(tp.position[tp.layer == k, 2]) for k in layers])
    assert np.all(z_of < 1e-6)  # each layer is one plane
    assert np.allclose(tp.height, H, atol=1e-4)
    # Each layer's filaments are centred on the middle of its slab, where its section was cut.
    mids = np.array([tp.position[tp.layer == k, 2][0] for k in layers])
    assert np.allclose(mids, cube.bounds[0, 2] + H * (layers - layers.min() + 0.5), atol=1e-3)
    assert np.allclose(tp.normal, [0.0, 0.0, 1.0])


@needs_prusaslicer
def test_print_lies_inside_the_model_bounds(printed: CommercialResult,
                                            cube: trimesh.Trimesh) -> None:
    p = printed.toolpath.position
    lo, hi = cube.bounds
    assert np.all(p >= lo - 1e-6) and np.all(p <= hi + 1e-6)
    # Centred: the perimeter sits the same distance inside on both sides of x and y.
    margin_lo, margin_hi = p.min(axis=0)[:2] - lo[:2], hi[:2] - p.max(axis=0)[:2]
    assert np.allclose(margin_lo, margin_hi, atol=1e-3)
    # Lines fill the section: half a line width or less from the walls, every layer.
    assert np.all(margin_lo < printed.settings.extrusion_width_mm)


@needs_prusaslicer
def test_speed_is_the_constant_rate_speed(printed: CommercialResult) -> None:
    """Imported at the cell's constant rate, the lines run at about the one configured v."""
    v = printed.settings.speed_mm_s
    assert np.median(printed.toolpath.speed) == pytest.approx(v, rel=0.05)
