"""The robot's ledger: what was printed, read back after any stop."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mesp_cell.nodes import print_ledger
from mesp_cell.nodes.print_ledger import Ledger


def test_an_empty_or_missing_ledger_printed_nothing(tmp_path: Path) -> None:
    printed = print_ledger.read(tmp_path)
    assert printed.last == (-1, -1) and printed.doubled == 0 and printed.stop == -1
    assert list(printed.missing(np.arange(3))) == [0, 1, 2]


def test_a_resumed_print_reads_back_in_order(tmp_path: Path) -> None:
    led = Ledger(tmp_path, fresh=True)
    led.stream(0, -1)
    for w in range(4):
        led.waypoint(w, 10 * w)
    led.stopped(33)
    led.close()
    printed = print_ledger.read(tmp_path)
    assert printed.last == (3, 30) and printed.stop == 33
    led = Ledger(tmp_path, fresh=False)
    led.stream(30, 3)  # a resume starts at the last waypoint's sample, after it
    for w in range(4, 6):
        led.waypoint(w, 10 * w)
    led.close()
    printed = print_ledger.read(tmp_path)
    assert list(printed.waypoints) == list(range(6)) and printed.stop == -1
    assert printed.doubled == 0 and printed.restreamed() == 0
    assert printed.missing(np.arange(6)).size == 0
    assert (tmp_path / print_ledger.NAME).stat().st_mode & 0o777 == 0o600


def test_doubles_retraces_and_a_torn_tail_are_seen(tmp_path: Path) -> None:
    led = Ledger(tmp_path, fresh=True)
    led.stream(0, -1)
    for w in range(4):
        led.waypoint(w, 10 * w)
    led.stream(5, 0)  # a resume from an older checkpoint: re-traces waypoints 1-3
    led.waypoint(3, 30)  # and reports 3 again
    led.close()
    with open(tmp_path / print_ledger.NAME, "ab") as f:
        f.write(b"\x00" * 7)  # a record cut short by a killed writer
    printed = print_ledger.read(tmp_path)
    assert printed.doubled == 1
    assert printed.restreamed() == 3
    assert Ledger(tmp_path, fresh=True).close() is None
    assert print_ledger.read(tmp_path).waypoints.size == 0


def test_switch_records_sum_and_leave_the_stop_alone(tmp_path: Path) -> None:
    led = Ledger(tmp_path, fresh=True)
    led.stream(0, -1)
    led.waypoint(0, 0)
    led.switch(-0.25, 0.04)  # a start 40 ms late on the flow's clock
    led.stopped(12)
    led.switch(0.125, 0.02)  # a stop's latency recorded after the stream stopped
    led.close()
    printed = print_ledger.read(tmp_path)
    assert printed.switches == 2 and printed.switch_mm3 == -0.125
    assert printed.stop == 12 and list(printed.waypoints) == [0]
