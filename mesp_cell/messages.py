"""Typed messages of the cell bus (frozen dataclasses, encoded by ``mesp_cell.bus.codec``).

Units on the bus follow design.md: mm, s, deg. Times ``t`` are ``time.time()`` seconds of the
sender (the same clock for processes on one host). Large artifacts never travel on the bus: a
command names a job directory file by path and sha256 (``path``, ``sha256``).

Topics (key ``mesp/<cell>/<node>/<topic>``):
    ``<node>/heartbeat`` Heartbeat, 2 Hz; ``<node>/alive`` liveliness token.
    ``robot/state`` RobotState, 100 Hz; ``robot/event`` StreamEvent; ``robot/waypoint``
    WaypointReached. ``extruder/state`` ExtruderState, 100 Hz. ``supervisor/progress``
    JobProgress, 5 Hz while printing. ``<node>/cmd`` queryable taking Command, replying Reply.
    ``estop/estop`` EStop (any sender; robot and extruder stop on receipt).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from mesp_cell.bus.codec import register

# Extruder fault bits (the same bits as the controller's fault register, drivers/REGISTERS.md).
FAULT_WATCHDOG = 1 << 0
FAULT_STALL = 1 << 1
FAULT_OVERLOAD = 1 << 2
FAULT_ESTOP = 1 << 3
FAULT_LINK = 1 << 8  # host-side: the driver lost the link to the controller
FAULT_NAMES = {FAULT_WATCHDOG: "watchdog", FAULT_STALL: "stall", FAULT_OVERLOAD: "overload",
               FAULT_ESTOP: "e-stop", FAULT_LINK: "link"}


def fault_text(bits: int) -> str:
    """The fault bits as words ("e-stop latched at the controller (0x8)"); "" if none."""
    if not bits:
        return ""
    names = [n for bit, n in FAULT_NAMES.items() if bits & bit]
    unknown = bits & ~sum(FAULT_NAMES)
    words = " + ".join(names + ([f"unknown {unknown:#x}"] if unknown else []))
    return f"{words} latched at the controller ({bits:#x})"


@register(1)
@dataclass(frozen=True)
class Heartbeat:
    """A node's periodic sign of life.

    Attributes:
        node: node name. state: lifecycle state (unconfigured/inactive/active/finalized).
        seq: counter, +1 per beat. pid: OS process id. t: s, send time.
    """

    node: str
    state: str
    seq: int
    pid: int
    t: float


@register(2)
@dataclass(frozen=True)
class RobotState:
    """State of the arm as the robot node sees it.

    Attributes:
        t: s, send time. seq: counter.
        q: (6,) deg, joint positions. qd: (6,) deg/s, joint velocities.
        tcp: (3,) mm, nozzle tip in the robot base frame.
        mode: "idle" | "moving" | "streaming" | "stopped" | "fault".
        job_id: job being streamed ("" if none). sample: index of the last commanded servo
        sample of the trajectory (-1 if none). samples: number of samples of the loaded trajectory.
        waypoint: last toolpath waypoint passed (-1 if none).
        connected: link to the controller (or twin) up. protective_stop: controller reports one.
        stop_reason: why the last stream ended ("" if none). stop_t: s, when it ended.
    """

    t: float
    seq: int
    q: tuple[float, ...]
    qd: tuple[float, ...]
    tcp: tuple[float, ...]
    mode: str
    job_id: str
    sample: int
    samples: int
    waypoint: int
    connected: bool
    protective_stop: bool
    stop_reason: str
    stop_t: float


@register(3)
@dataclass(frozen=True)
class ExtruderState:
    """State of the extruder as the extruder node reads it from its controller.

    Attributes:
        t: s, send time. seq: counter.
        rate_set: mm^3/s, commanded rate. rate: mm^3/s, measured rate.
        volume: mm^3, totaliser (volume extruded since power-up).
        running: the motor is commanded on. connected: link to the controller up.
        fault: fault bits (``FAULT_*``); 0 = healthy. detail: text of the last fault ("" if none).
    """

    t: float
    seq: int
    rate_set: float
    rate: float
    volume: float
    running: bool
    connected: bool
    fault: int
    detail: str


@register(4)
@dataclass(frozen=True)
class WaypointReached:
    """The robot passed a deposition waypoint while the extruder was confirmed running.

    Attributes:
        job_id: job. waypoint: toolpath waypoint index. layer: its layer. sample: servo sample
        index of the trajectory. t: s.
    """

    job_id: str
    waypoint: int
    layer: int
    sample: int
    t: float


@register(5)
@dataclass(frozen=True)
class StreamEvent:
    """End of a trajectory stream.

    Attributes:
        job_id: job. kind: "done" (last sample sent) | "stopped" (stopped early).
        reason: why it stopped ("" when done). sample: last sample sent. t: s.
    """

    job_id: str
    kind: str
    reason: str
    sample: int
    t: float


@register(6)
@dataclass(frozen=True)
class JobProgress:
    """Progress of the job being printed.

    Attributes:
        job_id: job. state: job state. layer: current layer. layers: layer count.
        waypoint: last printed waypoint. waypoints: waypoint count. percent: 0..100 of samples.
        eta_s: s, estimated time to completion. volume: mm^3 extruded in this job. t: s.
    """

    job_id: str
    state: str
    layer: int
    layers: int
    waypoint: int
    waypoints: int
    percent: float
    eta_s: float
    volume: float
    t: float


@register(7)
@dataclass(frozen=True)
class EStop:
    """Emergency stop: every motion and extrusion stops at once.

    Attributes:
        source: who sent it. reason: why. t: s.
    """

    source: str
    reason: str
    t: float


@register(8)
@dataclass(frozen=True)
class Command:
    """A request to a node's ``cmd`` queryable.

    Attributes:
        verb: what to do (node specific, see docs/runtime.md). job_id: job concerned ("" if none).
        args: JSON object text of small scalar arguments (numbers in mm, s, deg, mm^3/s).
        path: artifact path for by-reference transfer ("" if none). sha256: its digest.
    """

    verb: str
    job_id: str = ""
    args: str = "{}"
    path: str = ""
    sha256: str = ""

    def arg(self, name: str, default: Any = None) -> Any:
        """One argument from ``args`` (``default`` if absent)."""
        return json.loads(self.args or "{}").get(name, default)

    @staticmethod
    def make(verb: str, job_id: str = "", path: str = "", sha256: str = "", **args: Any) -> Command:
        """Build a command with keyword arguments."""
        return Command(verb, job_id, json.dumps(args), path, sha256)


@register(9)
@dataclass(frozen=True)
class Reply:
    """The answer to a ``Command``.

    Attributes:
        ok: the command was accepted/done. reason: one line why not ("" when ok).
        data: JSON object text of results.
    """

    ok: bool
    reason: str = ""
    data: str = "{}"

    def value(self, name: str, default: Any = None) -> Any:
        """One result from ``data``."""
        return json.loads(self.data or "{}").get(name, default)

    @staticmethod
    def done(**data: Any) -> Reply:
        """A successful reply with results."""
        return Reply(True, "", json.dumps(data))

    @staticmethod
    def refuse(reason: str) -> Reply:
        """A refusal with a one-line reason."""
        return Reply(False, " ".join(reason.split()), "{}")
