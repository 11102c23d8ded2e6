"""Message encoding and key expressions."""

from __future__ import annotations

import dataclasses

import pytest

from core.errors import InputError
from mesp_cell.bus.codec import CodecError, decode, encode
from mesp_cell.bus.keys import key, parse_key
from mesp_cell.messages import (
    Command,
    EStop,
    ExtruderState,
    Heartbeat,
    JobProgress,
    Reply,
    RobotState,
    StreamEvent,
    WaypointReached,
)

SAMPLES = [
    Heartbeat("robot", "active", 7, 1234, 1.5),
    RobotState(1.0, 2, (0.1, -90.0, 90.0, -90.0, -90.0, 0.0), (0.0,) * 6, (400.0, 0.0, 100.0),
               "streaming", "job-0001", 15, 1321, 4, True, False, "", 0.0),
    ExtruderState(1.0, 3, 6.57, 6.5, 123.25, True, True, 0, ""),
    WaypointReached("j", 12, 1, 240, 2.0),
    StreamEvent("j", "stopped", "extruder process lost — ünïcode", 400, 3.0),
    JobProgress("j", "printing", 1, 3, 20, 60, 33.3, 1.7, 12.0, 4.0),
    EStop("console", "test", 5.0),
    Command.make("start", "j", rate=6.57),
    Reply.done(samples=10),
]


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_roundtrip_is_exact(msg: object) -> None:
    data = encode(msg)
    assert decode(data) == msg
    assert decode(data, type(msg)) == msg


def test_state_messages_are_compact() -> None:
    # 2 header + 8 t + 8 seq + 3 tuples (4 + 8 n) + strings + flags: well under 300 bytes.
    assert len(encode(SAMPLES[1])) < 300
    assert len(encode(SAMPLES[2])) < 60


def test_corrupt_or_foreign_payloads_are_refused() -> None:
    data = encode(SAMPLES[2])
    with pytest.raises(CodecError):
        decode(data[:-3])
    with pytest.raises(CodecError):
        decode(data + b"x")
    with pytest.raises(CodecError):
        decode(b"\xff\xff" + data[2:])
    with pytest.raises(CodecError):
        decode(data, RobotState)
    with pytest.raises(TypeError):
        encode(dataclasses.make_dataclass("X", [("a", int)])(1))


def test_command_arguments_and_reply_values() -> None:
    cmd = decode(encode(Command.make("stream", "j", start=5, lead_s=0.3)), Command)
    assert cmd.arg("start") == 5 and cmd.arg("lead_s") == 0.3 and cmd.arg("none", 1) == 1
    reply = Reply.refuse("robot   is\\nbusy")
    assert not reply.ok and "\n" not in reply.reason


def test_keys() -> None:
    assert key("sim", "robot", "state") == "mesp/sim/robot/state"
    assert key("sim", "*", "alive") == "mesp/sim/*/alive"
    assert parse_key("mesp/sim/robot/state").node == "robot"
    for bad in ("Sim", "a/b", "", "x y"):
        with pytest.raises(InputError):
            key(bad, "robot", "state")
    with pytest.raises(ValueError):
        parse_key("other/sim/robot/state")
