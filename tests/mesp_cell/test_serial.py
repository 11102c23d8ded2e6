"""The serial line-protocol extruder driver against the emulator on a pty."""

from __future__ import annotations

import time

import pytest

from mesp_cell.drivers.extruder_base import ExtruderLinkError
from mesp_cell.drivers.extruder_emulator import SerialEmulatorThread
from mesp_cell.drivers.extruder_plant import PlantParams
from mesp_cell.drivers.extruder_serial import SerialExtruder
from mesp_cell.messages import FAULT_ESTOP


def test_serial_driver_commands_and_status() -> None:
    with SerialEmulatorThread(PlantParams(tau_s=0.05)) as emu:
        d = SerialExtruder(emu.path)
        d.connect()
        d.start(6.57)
        for _ in range(8):
            d.heartbeat()
            time.sleep(0.03)
        r = d.read()
        assert r.running and r.rate == pytest.approx(6.57, rel=0.02) and r.volume > 0
        d.set_rate(3.0)
        assert d.read().rate_set == pytest.approx(3.0)
        d.estop()
        assert d.read().fault & FAULT_ESTOP and not d.read().running
        d.reset()
        assert d.read().fault == 0
        d.stop()
        d.close()


def test_silent_line_is_retried_then_fails() -> None:
    with SerialEmulatorThread() as emu:
        d = SerialExtruder(emu.path, timeout=0.05, retries=2, retry_delay=0.01)
        d.connect()
        emu.respond = False
        with pytest.raises(ExtruderLinkError, match="after 3 attempts"):
            d.read()
        emu.respond = True
        assert d.read().fault == 0  # the line recovered: the next exchange works
        d.close()


def test_loop_url_without_a_controller_fails_cleanly() -> None:
    d = SerialExtruder("loop://", timeout=0.05, retries=1, retry_delay=0.01)
    with pytest.raises(ExtruderLinkError, match="answered 'HB 1'"):
        d.heartbeat()  # the loopback echoes the command: not a valid answer
