"""The twin's ink against its plan at a time scale: the real twin, switcher and extruder plant.

The kinematic twin streams a plan of random deposition pulses (on 2-6 s, off 0.5-2 s of
simulated time) and switches the screw ``lead_s`` ahead, as the robot node does, through the
``Switcher``; the extruder plant runs in its own process on the shared clock file, as the
emulator does. Each switch reaches it after a random wall-clock latency (the bus and Modbus on
a loaded host) and the servo loop is descheduled now and then (``--stall-ms``). Printed: the
plant's ink against the plan's (rate x deposition time) per run, and the median, for switches
timed by the twin's own time (``sim_now``, the product) and by the shared clock (``--decided
clock``, the timing the product had before).

    PYTHONPATH=$PWD python bench/bench_twin_ink.py --scale 40 --latency-ms 60 --runs 3
    PYTHONPATH=$PWD python bench/bench_twin_ink.py --scale 40 --latency-ms 60 --decided clock
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import random
import statistics
import tempfile
import threading
import time
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np

RATE = 5.0  # mm^3/s, the set-point
LEAD_S = 0.2  # s, the switches' lead (the plant's tau)
DT = 0.002  # s, the servo period


def _plant(path: str, scale: float, conn: Connection) -> None:
    """The extruder plant on the shared clock, stepped every 5 ms of wall time, taking
    (verb, rate) switches from ``conn``; ("quit",) returns its totaliser."""
    from mesp_cell.drivers import registers as R
    from mesp_cell.drivers.extruder_plant import ExtruderPlant, PlantParams
    from mesp_cell.drivers.sim_clock import SimClock

    plant = ExtruderPlant(PlantParams(tau_s=LEAD_S, watchdog_s=0.0, time_scale=scale),
                          time.monotonic(), SimClock(scale, path, reset=True))
    conn.send("ready")
    while True:
        if not conn.poll(0.005):
            plant.step(time.monotonic())
            continue
        msg = conn.recv()
        now = time.monotonic()
        if msg[0] == "quit":
            plant.step(now)
            conn.send(plant.volume)
            return
        if msg[0] == "start":
            plant.set_rate(msg[1], now)
            plant.command(R.CMD_RUN, now)
        else:
            plant.command(0, now)
        conn.send("ok")


def run(scale: float, pulses: int, latency_ms: float, stall_ms: float, seed: int,
        twin_time: bool) -> tuple[float, float]:
    """(ink, planned ink), nominal mm^3, of one stream of ``pulses`` pulses."""
    rng = random.Random(seed)  # the plan and the stalls (servo thread)
    latency_rng = random.Random(seed + 1)  # the switches' latency (switcher thread)
    path = str(Path(tempfile.mkdtemp()) / "sim.clock")
    ctx = mp.get_context("spawn")  # this process has threads: no fork
    link, plant_end = ctx.Pipe()
    proc = ctx.Process(target=_plant, args=(path, scale, plant_end))
    proc.start()
    try:
        return _stream(scale, pulses, latency_ms, stall_ms, rng, latency_rng, path, link,
                       twin_time)
    finally:
        proc.kill()
        proc.join()


def _stream(scale: float, pulses: int, latency_ms: float, stall_ms: float,
            rng: random.Random, latency_rng: random.Random, path: str, link: Connection,
            twin_time: bool) -> tuple[float, float]:
    """``run`` with the plant's process started: stream the plan, return (ink, planned)."""
    from mesp_cell.drivers.robot_base import ServoConfig
    from mesp_cell.drivers.robot_twin import KinematicTwin
    from mesp_cell.drivers.sim_clock import SimClock
    from mesp_cell.drivers.stream import ServoStream, StreamPlan
    from mesp_cell.nodes.extruder_switch import Switcher

    assert link.recv() == "ready"
    gaps = [rng.uniform(0.5, 2.0) if i % 2 == 0 else rng.uniform(2.0, 6.0)
            for i in range(2 * pulses)]
    t = np.concatenate([[0.0], np.cumsum(gaps), [sum(gaps) + 1.0]])
    extrude = np.arange(len(t)) % 2 == 1  # on after each off gap
    extrude[-1] = False
    q = np.tile(np.array([0.0, -1.5, 1.5, -1.5, -1.57, 0.0]), (len(t), 1))
    none = np.zeros(0, np.int64)
    plan = StreamPlan(DT, t, q, extrude, none, none, np.zeros(0, bool), none, 0, np.eye(4),
                      np.ones(len(t)))
    clock = SimClock(scale, path)
    twin = KinematicTwin(ServoConfig(dt=DT, time_scale=scale, overrun_s=0.3), q0=q[0],
                         clock=clock)
    twin.connect()
    lock = threading.Lock()

    def send(verb: str, rate: float) -> str:
        time.sleep(latency_rng.uniform(0.0, latency_ms) / 1000.0)
        with lock:
            link.send((verb, rate))
            link.recv()
        return ""

    switcher = Switcher(send, clock.now, scale, clock, twin.sim_now if twin_time else None)
    stopping = threading.Event()
    sender = threading.Thread(target=switcher.run, args=(stopping,))
    sender.start()
    K = plan.samples
    on_k = np.asarray(plan.extrude[np.arange(K)], dtype=bool)
    lead_n = round(LEAD_S / DT)
    state = {"on": False}

    def on_sample(k: int) -> None:
        on = bool(on_k[min(k + lead_n, K - 1)])
        if on != state["on"]:
            state["on"] = on
            switcher.put("start" if on else "stop", RATE if on else 0.0, RATE if on else -RATE)
        if stall_ms and rng.random() < 5e-4:
            time.sleep(rng.uniform(0.0, stall_ms) / 1000.0)  # the servo thread descheduled

    try:
        ServoStream(twin, plan, 0, on_sample=on_sample).run()
        time.sleep(max(latency_ms / 1000.0, 0.05) + 0.2)  # the last switch lands
    finally:
        stopping.set()
        sender.join()
    with lock:
        link.send(("quit",))
        ink = float(link.recv())
    return ink, float(np.count_nonzero(on_k)) * DT * RATE


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=40.0, help="time scale of the twin")
    ap.add_argument("--pulses", type=int, default=20)
    ap.add_argument("--latency-ms", type=float, default=60.0,
                    help="each switch reaches the plant after U(0, this) ms of wall time")
    ap.add_argument("--stall-ms", type=float, default=0.0,
                    help="the servo loop is descheduled for U(0, this) ms, 1 in 2000 periods")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--decided", choices=["twin", "clock"], default="twin",
                    help="time a switch by the twin's own time (product) or the shared clock")
    a = ap.parse_args()
    errors = []
    for seed in range(a.runs):
        t0 = time.monotonic()
        ink, planned = run(a.scale, a.pulses, a.latency_ms, a.stall_ms, seed,
                           a.decided == "twin")
        errors.append(100.0 * (ink / planned - 1.0))
        print(f"run {seed}: ink {ink:8.2f} of {planned:8.2f} mm^3 ({errors[-1]:+.3f} %), "
              f"{time.monotonic() - t0:.1f} s wall")
    print(f"decided by {a.decided}, {a.scale:g}x, latency <= {a.latency_ms:g} ms, stalls <= "
          f"{a.stall_ms:g} ms: median {statistics.median(errors):+.3f} %, worst "
          f"{max(errors, key=abs):+.3f} %")


if __name__ == "__main__":
    main()
