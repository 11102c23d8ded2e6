"""The robot's extruder switches: sent in order, what a fast twin's latency moved recorded."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from mesp_cell.nodes import print_ledger
from mesp_cell.nodes.extruder_switch import Switcher


class Clock:
    """A flow clock the test moves by hand."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def run_switches(time_scale: float, tmp_path: Path) -> tuple[list[tuple[str, float]], Clock]:
    clock = Clock()
    sent: list[tuple[str, float]] = []
    stopping = threading.Event()

    def send(verb: str, rate: float) -> str:
        clock.t += 0.1  # each request takes 0.1 s of the flow's clock
        sent.append((verb, rate))
        if verb == "stop" and len(sent) == 4:
            stopping.set()
        return "" if verb != "set_rate" else "refused"

    sw = Switcher(send, clock, time_scale)
    sw.put("stop", 5.0, -5.0, tmp_path)
    sw.put("start", 5.0, 5.0, tmp_path)
    sw.put("set_rate", 6.0, 1.0, tmp_path)  # refused: nothing recorded
    sw.put("stop", 0.0)  # a safety stop: not recorded
    sw.run(stopping)
    return sent, clock


def test_switches_go_in_order_and_a_fast_twin_records_their_excess(tmp_path: Path) -> None:
    print_ledger.Ledger(tmp_path, fresh=True).close()
    sent, _ = run_switches(40.0, tmp_path)
    assert [v for v, _ in sent] == ["stop", "start", "set_rate", "stop"]
    printed = print_ledger.read(tmp_path)
    # the stop was 0.1 s late (+5 x 0.1 of ink), the start 0.2 s (queued behind it: -5 x 0.2),
    # each less what real time would have moved (1 / 40 of it)
    assert printed.switches == 2
    assert printed.switch_mm3 == pytest.approx((0.5 - 1.0) * (1 - 1 / 40))


def test_real_time_records_nothing(tmp_path: Path) -> None:
    print_ledger.Ledger(tmp_path, fresh=True).close()
    run_switches(1.0, tmp_path)
    assert print_ledger.read(tmp_path).switches == 0
