"""The bus messages' shared tables: the extruder fault bits in words."""

from __future__ import annotations

from mesp_cell.messages import FAULT_ESTOP, FAULT_LINK, FAULT_STALL, ExtruderState, fault_text
from mesp_cell.nodes.interlock import fault_reason


def test_no_fault_is_no_text() -> None:
    assert fault_text(0) == ""


def test_fault_bits_are_named() -> None:
    assert fault_text(FAULT_ESTOP) == "e-stop latched at the controller (0x8)"
    text = fault_text(FAULT_ESTOP | FAULT_STALL | 1 << 12)
    assert text.startswith("stall + e-stop + unknown 0x1000") and text.endswith("(0x100a)")


def test_an_extruder_e_stop_stops_the_stream_as_an_e_stop() -> None:
    """The extruder's state can reach the robot before the e-stop message itself; the
    stream's reason then still names the e-stop."""
    ext = ExtruderState(0.0, 1, 0.0, 0.0, 0.0, False, True, FAULT_ESTOP, fault_text(FAULT_ESTOP))
    assert "e-stop" in fault_reason(ext)
    link = ExtruderState(0.0, 1, 0.0, 0.0, 0.0, False, False, FAULT_LINK, "the link failed")
    assert fault_reason(link) == "extruder fault: the link failed"
