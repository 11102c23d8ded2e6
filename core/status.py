"""Status enums: the outcomes that leave their package (report.json, the job store, the bus).

Each is a ``StrEnum`` whose values are the strings files and reports have always held, so a
saved job loads unchanged and a member compares equal to its string; each member carries the
one line that says what it means (``message``, the message table of MuJoCo's and rclpy's
status enums). The planner's verdict has its own enum beside the planner
(``planner.status.PlanStatus``).
"""

from __future__ import annotations

from enum import StrEnum
from typing import Self


class Status(StrEnum):
    """Base: ``NAME = "stored value", "what it means"``."""

    message: str

    def __new__(cls, value: str, message: str = "") -> Self:
        member = str.__new__(cls, value)
        member._value_ = value
        member.message = message
        return member


class JobState(Status):
    """Where a job is in the cell (``mesp_cell.jobs``; the ``state`` column of its store)."""

    SUBMITTED = "submitted", "waiting to be sliced"
    SLICED = "sliced", "the toolpath is made; waiting to be planned"
    PLANNED = "planned", "the trajectory is made; waiting for the ready check"
    READY_CHECK = "ready_check", "waiting for the operator to confirm the cell is ready"
    PRINTING = "printing", "the arm is printing"
    PAUSED = "paused", "paused by the operator; resume or abort"
    INTERRUPTED = "interrupted", "a node or link failed mid-print; resumable from its checkpoint"
    DONE = "done", "printed to the end"
    FAILED = "failed", "refused, or a stage failed; the reason is recorded"
    ABORTED = "aborted", "aborted by the operator"

    @property
    def final(self) -> bool:
        """No transition leaves this state."""
        return self in (JobState.DONE, JobState.FAILED, JobState.ABORTED)


class DepositionStatus(Status):
    """The outcome of the simulated deposition (``sim.deposition.Deposit.status``)."""

    OK = "ok", "every commanded volume found room in the grid"
    OVERFULL = "overfull", "some ink found no free voxel and is missing from the deposit"
