"""Status enums keep the strings files hold, and say what each member means."""

from __future__ import annotations

import json

import pytest

from core.status import DepositionStatus, JobState, Status


@pytest.mark.parametrize("enum", [JobState, DepositionStatus])
def test_every_member_has_a_message(enum: type[Status]) -> None:
    for member in enum:
        assert member.message and member.message[0].islower(), member


def test_values_are_the_stored_strings() -> None:
    # the job store's state column and report.json hold these strings: saved jobs load
    assert [str(s) for s in JobState] == [
        "submitted", "sliced", "planned", "ready_check", "printing", "paused", "interrupted",
        "done", "failed", "aborted"]
    assert [str(s) for s in DepositionStatus] == ["ok", "overfull"]
    assert JobState("ready_check") is JobState.READY_CHECK
    assert json.loads(json.dumps({"state": JobState.PAUSED})) == {"state": "paused"}
    assert JobState.DONE == "done" and "done" in {JobState.DONE}
    with pytest.raises(ValueError):
        JobState("finished")


def test_final_states() -> None:
    assert {s for s in JobState if s.final} == {"done", "failed", "aborted"}
