"""Telemetry MCAP: readable JSON messages with schemas, rate and size bounds, tracking error."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mesp_cell.messages import ExtruderState, RobotState, StreamEvent
from mesp_cell.telemetry import JobRecorder, json_schema, read_counts


def _robot(t: float, sample: int, tcp: tuple[float, float, float]) -> RobotState:
    return RobotState(t, int(t * 100), (0.0,) * 6, (0.0,) * 6, tcp, "streaming", "j1", sample,
                      10, -1, True, False, "", 0.0)


def _extruder(t: float) -> ExtruderState:
    return ExtruderState(t, int(t * 100), 6.57, 6.5, 10.0 * t, True, True, 0, "")


def test_messages_read_back_with_schemas_and_tracking_error(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    plan_tcp = np.zeros((10, 3))
    rec = JobRecorder(tmp_path / "t.mcap", plan_tcp, record_hz=0)
    for k in range(50):
        rec.record(_robot(1000.0 + 0.01 * k, k % 10, (3.0, 4.0, 0.0)))
        rec.record(_extruder(1000.0 + 0.01 * k))
    rec.record(StreamEvent("j1", "done", "", 9, 1000.5))
    rec.record_plan(np.arange(10.0), np.zeros((10, 6)), plan_tcp, np.ones(10, bool), 1000.0)
    rec.close()
    counts = read_counts(tmp_path / "t.mcap")
    assert counts == {"/robot/state": 50, "/extruder/state": 50, "/robot/event": 1,
                      "/plan/trajectory": 10}
    with (tmp_path / "t.mcap").open("rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(topics=["/robot/state"]):
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            assert "tracking_error_mm" in json.loads(schema.data)["properties"]
            data = json.loads(message.data)
            assert data["tracking_error_mm"] == 5.0
            assert message.log_time == int(data["t"] * 1e9)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert meta["mesp"]["dropped_over_size_cap"] == "0"


KINDS = {"number": (int, float), "integer": (int,), "boolean": (bool,), "string": (str,),
         "array": (list,)}


def test_every_message_matches_its_channel_schema(tmp_path: Path) -> None:
    """What Foxglove checks to decode a json channel: the fields its JSON schema declares."""
    from mcap.reader import make_reader

    rec = JobRecorder(tmp_path / "s.mcap", np.zeros((3, 3)), record_hz=0)
    rec.record(_robot(5.0, 1, (1.0, 2.0, 3.0)))
    rec.record(_extruder(5.0))
    rec.record(StreamEvent("j1", "done", "", 2, 5.1))
    rec.record_plan(np.arange(3.0), np.zeros((3, 6)), np.zeros((3, 3)), np.ones(3, bool), 5.0)
    rec.close()
    with (tmp_path / "s.mcap").open("rb") as f:
        for schema, _channel, message in make_reader(f).iter_messages():
            props = json.loads(schema.data)["properties"]
            data = json.loads(message.data)
            assert set(data) == set(props), schema.name
            for key, value in data.items():
                kind = props[key]["type"]
                assert isinstance(value, KINDS[kind]), (schema.name, key)
                assert kind == "boolean" or not isinstance(value, bool), (schema.name, key)


def test_rate_and_size_bounds(tmp_path: Path) -> None:
    rec = JobRecorder(tmp_path / "r.mcap", None, record_hz=10)
    kept = sum(rec.record(_robot(0.001 * k, -1, (0.0, 0.0, 0.0))) for k in range(1000))
    assert kept == 10  # 1 s of 1 kHz states at 10 Hz
    rec.close()
    capped = JobRecorder(tmp_path / "c.mcap", None, record_hz=0, max_mb=0.01)
    kept = sum(capped.record(_extruder(0.01 * k)) for k in range(1000))
    assert 10 < kept < 100 and capped.dropped["cap"] == 1000 - kept
    assert capped.record(StreamEvent("j1", "stopped", "estop", 3, 20.0))  # events still kept
    capped.close()
    assert (tmp_path / "c.mcap").stat().st_size < 20_000


def test_schema_types_follow_the_dataclass() -> None:
    props = json_schema(ExtruderState)["properties"]
    assert props["rate"] == {"type": "number"} and props["running"] == {"type": "boolean"}
    assert props["seq"] == {"type": "integer"} and props["detail"] == {"type": "string"}
    assert json_schema(RobotState)["properties"]["q"]["type"] == "array"
