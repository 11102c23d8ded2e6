"""The states the cell's nodes publish on the bus: a node's lifecycle, the robot's mode, how a
stream ended.

``Status`` enums (``core.status``): the values are the strings the messages have always carried,
so a recorded bag and the console read them unchanged, and each member says what it means.
"""

from __future__ import annotations

from core.status import Status


class NodeState(Status):
    """A node's lifecycle (``nodes.lifecycle.LifecycleNode.state``, in its heartbeat)."""

    UNCONFIGURED = "unconfigured", "started; devices not opened yet"
    INACTIVE = "inactive", "devices open; not serving the bus"
    ACTIVE = "active", "serving the bus"
    FINALIZED = "finalized", "shut down; devices released"
    FAILED = "failed", "a worker died or a step failed; the launcher restarts it"


class RobotMode(Status):
    """What the robot node is doing (``messages.RobotState.mode``)."""

    IDLE = "idle", "holding still, ready for a stream or a move"
    MOVING = "moving", "on a checked point-to-point move (home, approach)"
    STREAMING = "streaming", "streaming a job's trajectory"
    STOPPED = "stopped", "a stream or move stopped early; holding still"
    FAULT = "fault", "the arm is disconnected or protectively stopped"

    @property
    def at_rest(self) -> bool:
        """Not moving: a stream or a move has ended (to the end or early)."""
        return self in (RobotMode.IDLE, RobotMode.STOPPED)


class StreamEnd(Status):
    """How a stream or a move ended (``messages.StreamEvent.kind``)."""

    DONE = "done", "the last sample of the trajectory was sent"
    STOPPED = "stopped", "stopped early; the reason says why"
    MOVED = "moved", "a point-to-point move reached its target"
