"""The states nodes publish: wire values unchanged, a message for every member."""

from __future__ import annotations

from mesp_cell.bus.codec import decode, encode
from mesp_cell.messages import StreamEvent
from mesp_cell.states import NodeState, RobotMode, StreamEnd


def test_every_member_says_what_it_means() -> None:
    for enum in (NodeState, RobotMode, StreamEnd):
        for member in enum:
            assert member.message and member.message[0].islower()


def test_wire_values_are_the_old_strings() -> None:
    assert [str(m) for m in RobotMode] == ["idle", "moving", "streaming", "stopped", "fault"]
    assert StreamEnd.DONE == "done" and NodeState.ACTIVE == "active"
    back = decode(encode(StreamEvent("j", StreamEnd.STOPPED, "why", 3, 1.0)), StreamEvent)
    assert back.kind == StreamEnd.STOPPED and StreamEnd(back.kind) is StreamEnd.STOPPED


def test_at_rest() -> None:
    assert {m for m in RobotMode if m.at_rest} == {RobotMode.IDLE, RobotMode.STOPPED}
