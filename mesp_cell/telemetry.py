"""A print's telemetry as an MCAP file that Foxglove opens (``DIR/telemetry.mcap``).

Every bus message of the job goes to its own channel as JSON with a JSON schema derived from
the message dataclass (Foxglove decodes ``json`` channels with ``jsonschema`` schemas):

| topic | message | extra fields |
| --- | --- | --- |
| ``/robot/state`` | RobotState (q, qd deg; tcp mm) | ``tracking_error_mm`` (1) |
| ``/extruder/state`` | ExtruderState (rate, rate_set mm^3/s, volume mm^3 totaliser) | |
| ``/supervisor/progress`` | JobProgress | |
| ``/robot/event``, ``/estop`` (``/robot/waypoint``) | StreamEvent, EStop (WaypointReached) | |
| ``/plan/trajectory`` | the commanded trajectory: t_s, q deg, tcp mm, extrude | |

(1) |TCP - the TCP of the last commanded trajectory sample|, mm (-1 without one).
Log times are the senders' ``t`` (ns); the trajectory's are the recording's start + its t.
Size is bounded: robot and extruder states are kept at ``record_hz`` at most (0 = all), the
trajectory at ``MAX_PLAN_MESSAGES``, and once ``max_mb`` of message data is written further
states are dropped (events are kept); the file's ``mesp`` metadata record says how many.
"""

from __future__ import annotations

import dataclasses
import json
import typing
from pathlib import Path
from typing import IO, Any

import numpy as np

from mesp_cell.messages import (
    EStop,
    ExtruderState,
    JobProgress,
    RobotState,
    StreamEvent,
    WaypointReached,
)

TOPICS: dict[type, str] = {
    RobotState: "/robot/state", ExtruderState: "/extruder/state",
    JobProgress: "/supervisor/progress", StreamEvent: "/robot/event",
    WaypointReached: "/robot/waypoint", EStop: "/estop",
}
STATES = (RobotState, ExtruderState)
MAX_PLAN_MESSAGES = 20_000
_JSON = {float: {"type": "number"}, int: {"type": "integer"}, bool: {"type": "boolean"},
         str: {"type": "string"}}


def json_schema(cls: type, extra: dict[str, type] | None = None) -> dict[str, Any]:
    """The JSON schema of a bus message dataclass (plus ``extra`` fields)."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: hints[f.name] for f in dataclasses.fields(cls)} | (extra or {})
    props = {name: _JSON.get(hint, {"type": "array", "items": {"type": "number"}})
             for name, hint in fields.items()}
    return {"title": f"mesp.{cls.__name__}", "type": "object", "properties": props}


PLAN_SCHEMA = {"title": "mesp.TrajectorySample", "type": "object", "properties": {
    "t_s": {"type": "number"}, "sample": {"type": "integer"},
    "q_deg": {"type": "array", "items": {"type": "number"}},
    "tcp_mm": {"type": "array", "items": {"type": "number"}},
    "extrude": {"type": "boolean"}}}


class JobRecorder:
    """Writes one job's telemetry to an MCAP file (see the module doc).

    Args:
        path: the MCAP file. tcp_plan: (K, 3) float64, mm, the commanded TCP per trajectory
        sample (for the tracking error), or None. record_hz: states kept per second and type
        at most (0 = all). max_mb: message data written at most, MB.
    """

    def __init__(self, path: Path, tcp_plan: np.ndarray | None = None, record_hz: float = 20.0,
                 max_mb: float = 1024.0) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[bytes] = self.path.open("wb")
        self.writer = Writer(self._file, compression=CompressionType.ZSTD)
        self.writer.start(profile="", library="mesp-cell")
        self.tcp_plan = tcp_plan
        self.min_dt = 1.0 / record_hz if record_hz > 0 else 0.0
        self.max_bytes = int(max_mb * 1e6)
        self.bytes = 0
        self.counts: dict[str, int] = {}
        self.dropped = {"rate": 0, "cap": 0}
        self._last: dict[type, float] = {}
        self._channels: dict[str, int] = {}

    def _channel(self, topic: str, schema: dict[str, Any]) -> int:
        if topic not in self._channels:
            sid = self.writer.register_schema(name=schema["title"], encoding="jsonschema",
                                              data=json.dumps(schema).encode())
            self._channels[topic] = self.writer.register_channel(
                topic=topic, message_encoding="json", schema_id=sid)
        return self._channels[topic]

    def _write(self, topic: str, schema: dict[str, Any], fields: dict[str, Any],
               t: float) -> None:
        data = json.dumps(fields).encode()
        ns = int(t * 1e9)
        seq = self.counts.get(topic, 0)
        self.writer.add_message(channel_id=self._channel(topic, schema), log_time=ns,
                                data=data, publish_time=ns, sequence=seq)
        self.counts[topic] = seq + 1
        self.bytes += len(data)

    def record(self, msg: Any) -> bool:
        """Write one bus message; False if it was dropped (rate or size bound)."""
        cls = type(msg)
        if cls in STATES:
            if msg.t - self._last.get(cls, -np.inf) < self.min_dt:
                self.dropped["rate"] += 1
                return False
            if self.bytes >= self.max_bytes:
                self.dropped["cap"] += 1
                return False
            self._last[cls] = msg.t
        fields = dataclasses.asdict(msg)
        extra: dict[str, type] = {}
        if cls is RobotState:
            extra["tracking_error_mm"] = float
            fields["tracking_error_mm"] = self._tracking_error(msg)
        self._write(TOPICS[cls], json_schema(cls, extra), fields, msg.t)
        return True

    def _tracking_error(self, state: RobotState) -> float:
        """|TCP - commanded TCP of the last sent sample| (mm); -1 without a sample."""
        if self.tcp_plan is None or not 0 <= state.sample < len(self.tcp_plan):
            return -1.0
        return float(np.linalg.norm(np.asarray(state.tcp) - self.tcp_plan[state.sample]))

    def record_plan(self, t: np.ndarray, q: np.ndarray, tcp: np.ndarray, extrude: np.ndarray,
                    start: float) -> None:
        """Write the commanded trajectory (t (K,) s, q (K, 6) rad, tcp (K, 3) mm, extrude (K,)),
        at most ``MAX_PLAN_MESSAGES`` evenly spaced samples, logged at ``start`` + t."""
        step = max(1, -(-len(t) // MAX_PLAN_MESSAGES))
        q_deg = np.degrees(q)
        for k in range(0, len(t), step):
            self._write("/plan/trajectory", PLAN_SCHEMA,
                        {"t_s": float(t[k]), "sample": k, "q_deg": q_deg[k].round(4).tolist(),
                         "tcp_mm": tcp[k].round(4).tolist(), "extrude": bool(extrude[k])},
                        start + float(t[k]))

    def close(self) -> None:
        """Finish the file (summary, statistics, the ``mesp`` metadata record)."""
        self.writer.add_metadata("mesp", {
            "record_hz": str(1.0 / self.min_dt if self.min_dt else 0.0),
            "max_mb": str(self.max_bytes / 1e6), "dropped_by_rate": str(self.dropped["rate"]),
            "dropped_over_size_cap": str(self.dropped["cap"]),
            "messages": json.dumps(self.counts)})
        self.writer.finish()
        self._file.close()


def read_counts(path: Path) -> dict[str, int]:
    """Messages per topic of an MCAP file, counted by reading every message back."""
    from mcap.reader import make_reader

    counts: dict[str, int] = {}
    with Path(path).open("rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            json.loads(message.data)
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    return counts
