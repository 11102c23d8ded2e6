"""The robot's own link that stops the screw, against the emulated controller."""

from __future__ import annotations

import time

import pytest

from mesp_cell.drivers import registers as R
from mesp_cell.drivers.extruder_emulator import EmulatorThread
from mesp_cell.drivers.extruder_modbus import ModbusExtruder
from mesp_cell.drivers.extruder_plant import PlantParams
from mesp_cell.drivers.screw_stop import ScrewStop


def test_the_screw_stops_at_once_without_the_extruder_node() -> None:
    with EmulatorThread(PlantParams(tau_s=0.05)) as emu:
        host = ModbusExtruder("127.0.0.1", emu.port)
        host.connect()
        host.start(5.0)
        assert emu.plant.running
        stop = ScrewStop("127.0.0.1", emu.port)
        try:
            host.close()  # the extruder node is gone; the watchdog (500 ms) would be next
            t = time.time()
            stop.trigger("extruder process lost")
            end = time.monotonic() + 2.0
            while emu.plant.running and time.monotonic() < end:
                time.sleep(0.001)
            assert not emu.plant.running
            assert stop.last_t - t < 0.1
            assert not emu.plant.fault  # a stop, not the watchdog's fault
        finally:
            stop.close()


def test_a_frozen_controller_costs_the_stop_at_most_its_timeout() -> None:
    with EmulatorThread(PlantParams()) as emu:
        stop = ScrewStop("127.0.0.1", emu.port, timeout=0.05)
        try:
            ModbusExtruder("127.0.0.1", emu.port).inject(R.INJECT_FREEZE, 1.0)
            t = time.monotonic()
            stop.trigger("test")
            stop.trigger("again")  # a second trigger while the first write hangs
            time.sleep(0.4)
            assert stop.last_t == 0.0  # not confirmed while frozen
            assert time.monotonic() - t < 1.0
        finally:
            stop.close()


@pytest.mark.parametrize("kind", [R.INJECT_SLIP])
def test_a_slipping_screw_shows_only_in_the_measured_rate(kind: int) -> None:
    with EmulatorThread(PlantParams(tau_s=0.05)) as emu:
        host = ModbusExtruder("127.0.0.1", emu.port)
        host.connect()
        host.start(4.0)
        host.inject(kind, 2.0)
        time.sleep(0.4)
        r = host.read()
        assert r.running and not r.fault
        assert r.rate == pytest.approx(2.0, rel=0.05)
        host.close()
