"""Who may send what: motion from the supervisor or the operator, e-stop resets from the
operator only, extruder switching from the robot too, nothing from an unproven sender."""

from __future__ import annotations

from mesp_cell.bus.signing import Role, Signer
from mesp_cell.command_policy import sender_refusal
from mesp_cell.messages import Command

SUP = Signer("supervisor", Role.NODE)
OP = Signer("console-1", Role.OPERATOR)
ROBOT = Signer("robot", Role.NODE)
OTHER = Signer("recorder", Role.NODE)


def ok(kind: str, verb: str, who: Signer | None, params: dict[str, str] | None = None) -> bool:
    return sender_refusal(kind, Command.make(verb), who, params or {}) == ""


def test_motion_and_job_commands() -> None:
    for verb in ("load", "move", "stream", "stop"):
        assert ok("RobotNode", verb, SUP) and ok("RobotNode", verb, OP)
        assert not ok("RobotNode", verb, OTHER) and not ok("RobotNode", verb, None)
    for verb in ("pause", "resume", "abort", "ready"):
        assert ok("SupervisorNode", verb, OP) and not ok("SupervisorNode", verb, SUP)
    assert ok("SlicerNode", "slice", SUP) and not ok("SlicerNode", "slice", OTHER)


def test_estop_reset_is_the_operators() -> None:
    for kind in ("RobotNode", "ExtruderNode"):
        assert ok(kind, "reset", OP)
        assert not ok(kind, "reset", SUP) and not ok(kind, "reset", ROBOT)
    why = sender_refusal("RobotNode", Command.make("reset"), SUP, {})
    assert why == "reset is accepted only from the operator, not from node supervisor"


def test_extruder_switching_and_renamed_nodes() -> None:
    assert ok("ExtruderNode", "start", ROBOT) and ok("ExtruderNode", "set_rate", ROBOT)
    assert not ok("ExtruderNode", "clear", ROBOT)
    arm = Signer("arm", Role.NODE)
    assert ok("ExtruderNode", "start", arm, {"robot": "arm"})
    assert not ok("ExtruderNode", "start", ROBOT, {"robot": "arm"})
    assert ok("ExtruderNode", "start", Signer("robot", Role.OPERATOR), {"robot": "arm"})
    assert ok("ExtruderNode", "status", OTHER) and ok("RobotNode", "status", OTHER)
    assert not ok("RobotNode", "status", None)
