"""Emulated extruder controller: a pymodbus TCP server over an ``ExtruderPlant``.

Run as a process (``python -m mesp_cell.drivers.extruder_emulator --port 0``; it prints
``listening <host> <port>`` on stdout once it accepts connections) or in a thread
(``EmulatorThread``) in tests. The register map is ``registers.py``; registers 100-101 inject
faults: a disconnect closes every connection and the listening socket for the set time, a
stall latches the stall fault, a freeze holds every request unanswered (the connections stay
open, the plant runs on), a slip makes the screw turn at half its set-point without a fault.
The physics loop steps the plant every ``cycle_s`` while the screw runs; at rest it sleeps
until a write or an injection's end (at most ``REST_CYCLE_S``): every request steps the plant
first and the flow's integral is exact, so only the running screw's watchdog needs the cycle.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import socket
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from mesp_cell.drivers import registers as R
from mesp_cell.drivers.extruder_plant import ExtruderPlant, PlantParams
from mesp_cell.drivers.sim_clock import SimClock


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that is free on ``host`` now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


#: s, the longest the physics loop sleeps while the screw is off.
REST_CYCLE_S = 0.1


class ModbusEmulator:
    """The emulator's asyncio server; ``run()`` serves until ``stop()``."""

    def __init__(self, params: PlantParams, host: str = "127.0.0.1", port: int = 0,
                 cycle_s: float = 0.005, clock: SimClock | None = None) -> None:
        self.plant = ExtruderPlant(params, time.monotonic(), clock)
        self.host = host
        self.port = port or free_port(host)
        self.cycle_s = cycle_s
        self.regs = [0] * R.SIZE
        self.regs[R.WATCHDOG_MS] = int(params.watchdog_s * 1000)
        self._inject_until = 0.0
        self._frozen_until = 0.0  # monotonic s until which requests go unanswered
        self._stop: asyncio.Event | None = None
        self._written: asyncio.Event | None = None  # set by a write: the physics loop wakes
        self._server: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.ready = threading.Event()

    # -- register access -------------------------------------------------------------------
    def _publish_state(self) -> None:
        p, r = self.plant, self.regs
        r[R.STATUS] = p.status_word()
        r[R.FAULT] = p.fault
        r[R.RATE : R.RATE + 2] = R.float_to_regs(p.rate)
        r[R.VOLUME : R.VOLUME + 2] = R.u32_to_regs(round(p.volume * 100))
        r[R.CTRL_HEARTBEAT] = p.cycles

    def _apply_writes(self, address: int, values: Sequence[int]) -> None:
        now = time.monotonic()
        touched = set(range(address, address + len(values)))
        for i, v in enumerate(values):
            self.regs[address + i] = int(v) & 0xFFFF
        if self._written is not None:
            self._written.set()
        if touched & {R.RATE_SET, R.RATE_SET + 1}:
            self.plant.set_rate(R.regs_to_float(self.regs[R.RATE_SET : R.RATE_SET + 2]), now)
        if R.HOST_HEARTBEAT in touched:
            self.plant.host_heartbeat(self.regs[R.HOST_HEARTBEAT], now)
        if R.WATCHDOG_MS in touched:
            self.plant.watchdog_s = self.regs[R.WATCHDOG_MS] / 1000.0
        if R.COMMAND in touched:
            self.plant.command(self.regs[R.COMMAND], now)
            self.regs[R.COMMAND] &= ~R.CMD_RESET & 0xFFFF  # RESET acts on the edge
        if R.INJECT in touched or R.INJECT_TIME in touched:
            self._inject(self.regs[R.INJECT], self.regs[R.INJECT_TIME] / 10.0)

    def _inject(self, kind: int, seconds: float) -> None:
        now = time.monotonic()
        self._inject_until = now + seconds if seconds > 0 else float("inf")
        self.plant.set_stall(kind == R.INJECT_STALL, now)
        self.plant.set_slip(0.5 if kind == R.INJECT_SLIP else 1.0, now)
        self._frozen_until = self._inject_until if kind == R.INJECT_FREEZE else 0.0
        if kind == R.INJECT_DISCONNECT and self._loop is not None:
            self._loop.call_soon(lambda: asyncio.ensure_future(self._disconnect(seconds)))

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      current_registers: list[int],
                      set_values: list[int] | list[bool] | None) -> None:
        while time.monotonic() < self._frozen_until:  # frozen: hold the request unanswered
            await asyncio.sleep(0.01)
        self.plant.step(time.monotonic())
        if set_values is not None:
            self._apply_writes(address, [int(v) for v in set_values])
        self._publish_state()
        n = len(current_registers)
        current_registers[:] = self.regs[start_address : start_address + n]

    # -- serving ---------------------------------------------------------------------------
    def _make_server(self) -> Any:
        from pymodbus.server import ModbusTcpServer
        from pymodbus.simulator import DataType, SimData, SimDevice

        device = SimDevice(
            id=1, simdata=[SimData(0, count=R.SIZE, values=0, datatype=DataType.REGISTERS)],
            action=self._action,
        )
        return ModbusTcpServer(device, address=(self.host, self.port))

    async def _disconnect(self, seconds: float) -> None:
        if self._server is not None:
            await self._server.shutdown()
            self._server = None
        await asyncio.sleep(seconds if seconds > 0 else 3600.0)
        if self._stop is not None and not self._stop.is_set():
            self.regs[R.INJECT] = 0
            self._server = self._make_server()
            await self._server.serve_forever(background=True)

    async def _physics(self) -> None:
        assert self._stop is not None
        written = self._written = asyncio.Event()
        while not self._stop.is_set():
            written.clear()
            now = time.monotonic()
            self.plant.step(now)
            if self._inject_until and now >= self._inject_until:
                self._inject_until = 0.0
                self.plant.set_stall(False, now)
                self.plant.set_slip(1.0, now)
            if self.plant.running:
                await asyncio.sleep(self.cycle_s)
                continue
            rest = REST_CYCLE_S
            if self._inject_until:
                rest = min(rest, max(self.cycle_s, self._inject_until - now))
            try:
                await asyncio.wait_for(written.wait(), rest)
            except TimeoutError:
                pass

    async def serve(self) -> None:
        """Serve until ``stop()``."""
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        self._server = self._make_server()
        await self._server.serve_forever(background=True)
        self.ready.set()
        physics = asyncio.ensure_future(self._physics())
        await self._stop.wait()
        physics.cancel()
        if self._server is not None:
            await self._server.shutdown()

    def stop(self) -> None:
        """Stop serving (thread-safe)."""
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)


class EmulatorThread:
    """An emulator serving from a daemon thread (for tests and calibration dry runs)."""

    def __init__(self, params: PlantParams | None = None, host: str = "127.0.0.1") -> None:
        self.emulator = ModbusEmulator(params or PlantParams(), host=host)
        self._thread = threading.Thread(target=lambda: asyncio.run(self.emulator.serve()),
                                        daemon=True, name="extruder-emulator")

    @property
    def port(self) -> int:
        return self.emulator.port

    @property
    def plant(self) -> ExtruderPlant:
        return self.emulator.plant

    def __enter__(self) -> EmulatorThread:
        self._thread.start()
        if not self.emulator.ready.wait(10.0):
            raise RuntimeError("the extruder emulator did not start")
        return self

    def __exit__(self, *exc: object) -> None:
        self.emulator.stop()
        self._thread.join(5.0)


def write_truth(plant: ExtruderPlant, path: str) -> None:
    """The plant's hidden truth as JSON: delivered and totalised volume, mm^3."""
    from core.artifacts import write_json

    plant.step(time.monotonic())
    write_json(Path(path), {"true_volume_mm3": plant.true_volume, "volume_mm3": plant.volume,
                            "gain": plant.params.gain})


def main(argv: Sequence[str] | None = None) -> int:
    """Process entry point."""
    ap = argparse.ArgumentParser(prog="extruder_emulator", description=__doc__)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=0, help="TCP port (0 = a free one)")
    ap.add_argument("--tau", type=float, default=0.2, help="flow time constant, s")
    ap.add_argument("--gain", type=float, default=1.0, help="hidden true/nominal rate ratio")
    ap.add_argument("--startup-tau", type=float, default=0.0,
                    help="s, lag of the delivered flow behind the screw's (start-up transient)")
    ap.add_argument("--truth", default="",
                    help="file the hidden truth (delivered volume, mm^3) is written to, for "
                         "test benches; nothing on the link reports it")
    ap.add_argument("--watchdog", type=float, default=0.5, help="host watchdog, s (0 = off)")
    ap.add_argument("--time-scale", type=float, default=1.0,
                    help="the flow and totaliser run this many times faster than real time")
    ap.add_argument("--clock", default="",
                    help="file of the simulated cell's clock, shared with the robot twin (it "
                         "pauses the flow while the twin lags); reset at start")
    args = ap.parse_args(argv)
    logging.getLogger("pymodbus").setLevel(logging.ERROR)
    if not args.time_scale > 0:
        ap.error(f"--time-scale {args.time_scale} must be > 0")
    emu = ModbusEmulator(PlantParams(tau_s=args.tau, gain=args.gain, watchdog_s=args.watchdog,
                                     time_scale=args.time_scale,
                                     startup_tau_s=args.startup_tau),
                         host=args.host, port=args.port,
                         clock=SimClock(args.time_scale, args.clock or None, reset=True))

    async def run() -> None:
        from mesp_cell.nodes.lifecycle import watch_parent

        orphaned = threading.Event()
        watch_parent(orphaned)
        task = asyncio.ensure_future(emu.serve())
        while not emu.ready.is_set():
            await asyncio.sleep(0.01)
        print(f"listening {emu.host} {emu.port}", flush=True)
        while not task.done():
            if orphaned.is_set():
                emu.stop()
            if args.truth:
                write_truth(emu.plant, args.truth)
            await asyncio.sleep(0.2)
        await task
        if args.truth:
            write_truth(emu.plant, args.truth)

    try:
        asyncio.run(run())
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())


class SerialEmulatorThread:
    """The same plant behind the serial line protocol (``extruder_serial.py``) on a pty.

    ``path`` is the device the host opens. ``respond`` can be set False to make the emulated
    controller go silent (a dead line) for fault tests.
    """

    def __init__(self, params: PlantParams | None = None) -> None:
        import os

        self.plant = ExtruderPlant(params or PlantParams(), time.monotonic())
        self._master, slave = os.openpty()
        self.path = os.ttyname(slave)
        self._slave = slave
        self.respond = True
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True, name="serial-emulator")

    def _answer(self, line: str) -> str:
        now = time.monotonic()
        p = self.plant
        p.step(now)
        words = line.split()
        if not words:
            return "ERR empty"
        cmd, args = words[0].upper(), words[1:]
        try:
            if cmd == "RUN":
                p.set_rate(float(args[0]), now)
                p.command(R.CMD_RUN, now)
            elif cmd == "RATE":
                p.set_rate(float(args[0]), now)
            elif cmd == "STOP":
                p.command(0, now)
            elif cmd == "ESTOP":
                p.command(R.CMD_ESTOP, now)
            elif cmd == "RESET":
                p.command(R.CMD_RESET, now)
            elif cmd == "HB":
                p.host_heartbeat(int(args[0]), now)
            elif cmd == "STAT?":
                return (f"STAT {int(p.running)} {p.rate_set:.6g} {p.rate:.6g} {p.volume:.6f} "
                        f"{p.fault} {p.cycles}")
            else:
                return f"ERR unknown command {cmd}"
        except (IndexError, ValueError):
            return f"ERR bad arguments for {cmd}"
        return "OK"

    def _serve(self) -> None:
        import os
        import select

        buf = b""
        while not self._stop.is_set():
            ready, _, _ = select.select([self._master], [], [], 0.01)
            self.plant.step(time.monotonic())
            if not ready:
                continue
            try:
                buf += os.read(self._master, 1024)
            except OSError:
                return
            while b"\n" in buf:
                raw, buf = buf.split(b"\n", 1)
                if self.respond:
                    os.write(self._master, (self._answer(raw.decode().strip()) + "\n").encode())

    def __enter__(self) -> SerialEmulatorThread:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        import os

        self._stop.set()
        self._thread.join(2.0)
        os.close(self._master)
        os.close(self._slave)
