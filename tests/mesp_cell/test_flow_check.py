"""The measured-flow check: a first-order response within the band passes, a slip does not."""

from __future__ import annotations

import math

import pytest

from mesp_cell.messages import FAULT_STALL, ExtruderState
from mesp_cell.nodes.flow_check import PERSIST, FlowCheck, FlowResponse

C = 6.0
RESPONSE = FlowResponse(tau_s=0.2, band=0.05, time_scale=1.0, latency_s=0.05)


def state(rate_set: float, rate: float, running: bool = True, fault: int = 0) -> ExtruderState:
    return ExtruderState(0.0, 0, rate_set, rate, 0.0, running, True, fault, "")


def follow(check: FlowCheck, steps: list[tuple[float, float]], t0: float = 0.0,
           dt: float = 0.01, gain: float = 1.0) -> tuple[float, list[str]]:
    """Feed a first-order screw (tau 0.2 s) following set-points ``(until_s, rate)``,
    delivering ``gain`` x; returns the end time and the check's answers."""
    t, rate, out = t0, 0.0, []
    for until, target in steps:
        while t < until:
            t += dt
            rate = gain * target + (rate - gain * target) * math.exp(-dt / RESPONSE.tau_s)
            check.update(t, state(target, rate, running=target > 0))
            out.append(check.mismatch())
    return t, out


def test_settle_time_is_the_response_to_the_band_plus_latency() -> None:
    assert RESPONSE.settle_s == pytest.approx(0.2 * math.log(20) + 0.05)
    assert FlowResponse(0.2, time_scale=10.0, latency_s=0.0).settle_s == pytest.approx(
        0.2 * math.log(20) / 10)
    with pytest.raises(ValueError):
        FlowResponse(0.0)


def test_a_screw_that_follows_passes_through_start_steps_and_stop() -> None:
    check = FlowCheck(RESPONSE)
    _, out = follow(check, [(0.5, 0.0), (2.0, C), (3.0, 0.5 * C), (4.0, C), (5.0, 0.0)])
    assert not any(out)


def test_a_slipping_screw_is_a_mismatch_once_the_start_is_allowed_for() -> None:
    check = FlowCheck(RESPONSE)
    _, out = follow(check, [(0.5, 0.0), (2.5, C)], gain=0.5)
    first = next(i for i, why in enumerate(out) if why) - 50  # samples since the start
    # not during the start-up allowance, then within a few states of it
    assert first * 0.01 >= RESPONSE.settle_s - 0.01
    assert first * 0.01 <= RESPONSE.settle_s + 0.3
    assert "measured flow" in out[-1] and "mm^3/s" in out[-1]


def test_one_bad_reading_is_not_a_fault_and_too_much_flow_is() -> None:
    check = FlowCheck(RESPONSE)
    t, _ = follow(check, [(2.0, C)])
    check.update(t + 0.01, state(C, 0.0))
    assert PERSIST > 1 and check.mismatch() == ""
    check.update(t + 0.02, state(C, C))
    assert check.mismatch() == ""
    for i in range(PERSIST):
        check.update(t + 0.03 + 0.01 * i, state(C, 1.5 * C))
    assert check.mismatch()


def test_a_motor_commanded_off_must_settle_to_zero() -> None:
    check = FlowCheck(RESPONSE)
    t, _ = follow(check, [(2.0, C)])
    for i in range(100):  # off, yet the measured rate stays up: a screw that does not stop
        check.update(t + 0.01 * (i + 1), state(C, C, running=False))
    assert check.mismatch()
    check.update(t + 2.0, state(C, 0.0, running=False, fault=FAULT_STALL))
    assert check.mismatch() == ""
