"""slicer.status: every member has its message; detailed texts keep the report's strings."""

from __future__ import annotations

import json

from slicer.status import (
    DeformStatus,
    FieldStatus,
    SolverStatus,
    ToolpathStatus,
    VolumeStatus,
)


def test_every_status_has_a_message_and_compares_equal_to_its_stored_string() -> None:
    for enum in (SolverStatus, FieldStatus, DeformStatus, VolumeStatus, ToolpathStatus):
        for member in enum:
            assert member.message and member == member.value
            assert json.dumps(member) == json.dumps(member.value)


def test_a_detail_is_appended_after_a_colon_and_the_kind_is_read_back() -> None:
    text = SolverStatus.FAILED.with_detail("amg: ValueError: x")
    assert text == "failed:amg: ValueError: x"
    assert SolverStatus.kind_of(text) is SolverStatus.FAILED
    assert SolverStatus.kind_of("ok") is SolverStatus.OK
    assert FieldStatus.SOLVER_FAILED.with_detail("vector:failed:non-finite") == (
        "solver_failed:vector:failed:non-finite")
    assert FieldStatus.CONVERGED.with_detail("") == "converged"
