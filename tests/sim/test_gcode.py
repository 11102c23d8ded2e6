"""G-code import: modes, units, E bookkeeping, layers, paths, widths."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.stages import Pattern
from sim.gcode import GcodeOptions, align_to_bounds, parse_gcode, read_gcode

VOLUMETRIC = GcodeOptions(filament_diameter_mm=0.0, rate_mm3_s=6.0)


def test_absolute_moves_two_layers_and_travel() -> None:
    text = """
    ; a Cura-like file in volumetric E
    G21
    G90
    M82
    G92 E0
    G0 F3000 X0 Y0 Z0.5
    ;TYPE:WALL-OUTER
    G1 F600 X10 Y0 E5.0        ; 10 mm, 5 mm^3 -> W H = 0.5
    G1 X10 Y10 E10.0
    G0 X20 Y20                 ; travel, no deposition
    ;TYPE:FILL
    G1 X30 Y20 E13.0           ; 10 mm, 3 mm^3
    G0 Z1.0
    G1 X20 Y20 E18.0           ; layer 2, 10 mm, 5 mm^3
    """
    tp = parse_gcode(text, VOLUMETRIC)
    assert len(tp) == 3 + 2 + 2  # per path: start point + one point per move
    assert tp.path.tolist() == [0, 0, 0, 1, 1, 2, 2]
    assert tp.layer.tolist() == [0, 0, 0, 0, 0, 1, 1]
    assert np.allclose(tp.position[0], [0, 0, 0.5]) and np.allclose(tp.position[-1], [20, 20, 1])
    assert np.allclose(tp.height, 0.5)
    assert np.allclose(tp.width[:3], 1.0)  # 5 mm^3 / (10 mm * 0.5 mm)
    assert np.allclose(tp.width[3:5], 0.6)
    assert tp.pattern[:3].tolist() == [Pattern.CONTOUR] * 3
    assert tp.pattern[3:].tolist() == [Pattern.STRIPE] * 4
    # Speed "volume": the cell's constant rate delivers exactly the G-code's volume.
    assert np.allclose(tp.speed * tp.width * tp.height, 6.0)
    assert np.allclose(tp.normal, [0, 0, 1])


def test_relative_modes_inches_and_e_reset_agree_with_absolute() -> None:
    absolute = """G21 G90 M82
    G0 X0 Y0 Z0.2
    G1 X5 E1.0
    G1 X5 Y5 E2.0
    G92 E0
    G1 X0 Y5 E1.0
    """
    relative = """G20
    G91
    M83
    G0 X0 Y0 Z0.0078740157
    G1 X0.19685039 E0.039370079
    G1 Y0.19685039 E0.039370079
    G1 X-0.19685039 E0.039370079
    """
    a = parse_gcode(absolute, VOLUMETRIC)
    b = parse_gcode(relative, VOLUMETRIC)
    assert np.allclose(a.position, b.position, atol=1e-6)
    assert np.allclose(a.width, b.width, rtol=1e-5)
    assert np.allclose(a.width, 1.0 / (5.0 * 0.2))


def test_filament_diameter_and_feedrate_speed() -> None:
    text = "G1 Z0.2 F1200\nG1 X10 E1.0\n"
    opts = GcodeOptions(filament_diameter_mm=1.75, speed="feedrate")
    tp = parse_gcode(text, opts)
    volume = np.pi / 4 * 1.75**2
    assert tp.width[-1] == pytest.approx(volume / (10 * 0.2))
    assert np.allclose(tp.speed, 20.0)


def test_arc_is_linearised_on_its_circle() -> None:
    text = "G1 Z0.3\nG1 X10 Y0\nG3 X0 Y10 I-10 J0 E15.7\n"  # quarter circle r = 10
    tp = parse_gcode(text, GcodeOptions(filament_diameter_mm=0.0, arc_step_mm=0.5))
    r = np.linalg.norm(tp.position[:, :2], axis=1)
    assert np.allclose(r, 10.0)
    assert len(tp) > 30
    assert tp.width.mean() == pytest.approx(15.7 / (np.pi * 5 * 0.3), rel=0.01)


def test_errors_and_file_reading(tmp_path: Path) -> None:
    with pytest.raises(InputError):
        parse_gcode("G0 X1 Y1\nG1 X2 Y2\n")  # no E at all
    with pytest.raises(InputError):
        read_gcode(tmp_path / "missing.gcode")
    f = tmp_path / "part.gcode"
    f.write_text("G1 Z0.2\nG1 X4 E0.2\n")
    assert len(read_gcode(f)) == 2


def test_align_to_model_bounds() -> None:
    tp = parse_gcode("G1 X100 Y100 Z0.5\nG1 X110 Y100 E5\nG1 X110 Y104 E7\n", VOLUMETRIC)
    bounds = np.array([[-5.0, -2.0, 3.0], [5.0, 2.0, 9.0]])
    out = align_to_bounds(tp, bounds)
    lo, hi = out.position.min(axis=0), out.position.max(axis=0)
    assert np.allclose(0.5 * (lo[:2] + hi[:2]), [0.0, 0.0])
    assert lo[2] - out.height[0] == pytest.approx(3.0)


def test_modal_coordinates_and_several_g_words_on_a_line() -> None:
    tp = parse_gcode("G21 G91 M83\nG1 Z0.2\nG1 X5 E1\nY5 E1\n", VOLUMETRIC)
    assert np.allclose(tp.position, [[0, 0, 0.2], [5, 0, 0.2], [5, 5, 0.2]])
    assert tp.path.tolist() == [0, 0, 0]


def test_absurd_gcode_is_refused_by_line() -> None:
    import pytest

    from core.errors import InputError
    from sim.gcode import parse_gcode

    ok = "G21\nG90\nM83\nG1 Z0.3\nG1 X0 Y0\nG1 X4 Y0 E0.2\n"
    for extra, needle in (("G1 X1e30 E0.2\n", "line 7: X1e\\+30"),
                          ("G2 X4 Y1 I1e12 J0 E0.2\n", "I1e\\+12"),
                          ("G1 X0 Y4 E1e30\n", "width")):
        with pytest.raises(InputError, match=needle):
            parse_gcode(ok + extra)
