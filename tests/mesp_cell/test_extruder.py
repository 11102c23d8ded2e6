"""The emulated extruder's physics, the register map, and the Modbus driver against it."""

from __future__ import annotations

import math
import time

import pytest

from mesp_cell.drivers import registers as R
from mesp_cell.drivers.extruder_base import ExtruderLinkError
from mesp_cell.drivers.extruder_emulator import EmulatorThread
from mesp_cell.drivers.extruder_modbus import ModbusExtruder
from mesp_cell.drivers.extruder_plant import ExtruderPlant, PlantParams
from mesp_cell.messages import FAULT_ESTOP, FAULT_STALL, FAULT_WATCHDOG


def test_first_order_flow_and_totaliser_are_exact() -> None:
    p = PlantParams(tau_s=0.2, gain=1.25, watchdog_s=0.0)
    plant = ExtruderPlant(p, 0.0)
    plant.set_rate(6.0, 0.0)
    plant.command(R.CMD_RUN, 0.0)
    for t in (0.013, 0.1, 0.37, 0.5):  # uneven steps: the integration is exact anyway
        plant.step(t)
    T = 0.5
    assert plant.rate == pytest.approx(6.0 * (1 - math.exp(-T / 0.2)), rel=1e-12)
    volume = 6.0 * (T - 0.2 * (1 - math.exp(-T / 0.2)))
    assert plant.volume == pytest.approx(volume, rel=1e-12)
    assert plant.true_volume == pytest.approx(1.25 * volume, rel=1e-12)


def test_a_scaled_plant_runs_its_flow_on_the_twin_clock_and_its_watchdog_on_the_wall() -> None:
    # time_scale 40: 0.05 wall s are 2 simulated s of flow (tau 0.2 s), but the host
    # watchdog (0.5 s) still counts wall seconds.
    plant = ExtruderPlant(PlantParams(tau_s=0.2, watchdog_s=0.5, time_scale=40.0), 0.0)
    plant.set_rate(6.0, 0.0)
    plant.command(R.CMD_RUN, 0.0)
    plant.step(0.05)
    T = 2.0
    assert plant.rate == pytest.approx(6.0 * (1 - math.exp(-T / 0.2)), rel=1e-12)
    assert plant.volume == pytest.approx(6.0 * (T - 0.2 * (1 - math.exp(-T / 0.2))), rel=1e-12)
    plant.step(0.45)  # 18 simulated s, 0.45 wall s without a heartbeat: still running
    assert plant.running and plant.fault == 0
    plant.step(0.51)
    assert not plant.running and plant.fault & FAULT_WATCHDOG
    with pytest.raises(ValueError):
        PlantParams(time_scale=0.0)


def test_watchdog_stall_estop_and_reset() -> None:
    plant = ExtruderPlant(PlantParams(watchdog_s=0.5), 0.0)
    plant.set_rate(5.0, 0.0)
    plant.command(R.CMD_RUN, 0.0)
    plant.host_heartbeat(1, 0.3)
    plant.step(0.7)
    assert plant.running and plant.fault == 0
    plant.step(0.81)  # no heartbeat since 0.3 s
    assert not plant.running and plant.fault & FAULT_WATCHDOG
    plant.command(R.CMD_RUN, 0.9)
    assert not plant.running  # a latched fault refuses to run
    plant.command(R.CMD_RESET | R.CMD_RUN, 0.9)
    assert plant.running and plant.fault == 0
    plant.set_stall(True, 1.0)
    plant.host_heartbeat(2, 1.0)
    plant.step(1.01)
    assert plant.fault & FAULT_STALL
    plant.command(R.CMD_ESTOP, 1.1)
    assert plant.fault & FAULT_ESTOP and not plant.running


def test_register_packing() -> None:
    for v in (0.0, 6.57, -1.5, 1e6):
        assert R.regs_to_float(R.float_to_regs(v)) == pytest.approx(v, rel=1e-7)
    assert R.regs_to_u32(R.u32_to_regs(123456789)) == 123456789
    assert R.u32_to_regs(2**32 + 5) == [0, 5]


def test_modbus_driver_runs_the_emulator() -> None:
    with EmulatorThread(PlantParams(tau_s=0.05)) as emu:
        d = ModbusExtruder("127.0.0.1", emu.port)
        d.connect()
        d.start(6.57)
        for _ in range(20):
            d.heartbeat()
            time.sleep(0.02)
        r = d.read()
        assert r.running and r.fault == 0 and r.rate == pytest.approx(6.57, rel=0.02)
        assert r.volume == pytest.approx(emu.plant.volume, abs=0.5)
        d.stop()
        assert not d.read().running
        d.estop()
        assert d.read().fault & FAULT_ESTOP
        d.reset()
        assert d.read().fault == 0
        d.close()


def test_short_disconnect_is_retried_long_one_fails_safe() -> None:
    with EmulatorThread(PlantParams()) as emu:
        d = ModbusExtruder("127.0.0.1", emu.port, retries=5, retry_delay=0.05, watchdog_ms=200)
        d.connect()
        d.start(5.0)
        d.inject(R.INJECT_DISCONNECT, 0.5)
        r = d.read()  # retries span 0.05 + 0.1 + 0.2 + 0.4 + 0.8 s > 0.5 s
        assert d.attempts_failed > 0
        assert r.fault & FAULT_WATCHDOG  # no heartbeat got through: the controller stopped
        assert not r.running
        d.reset()
        d.retries = 2
        d.inject(R.INJECT_DISCONNECT, 0)  # until cleared
        with pytest.raises(ExtruderLinkError, match="after 3 attempts"):
            d.read()
        assert not emu.plant.running
