"""Runtime benchmarks: bus latency of state messages, and servo-loop period jitter.

1. Bus: a child process publishes ``RobotState`` messages (the largest state stream) at
   ``--rate`` Hz over a zenoh peer link on loopback; this process subscribes and measures the
   one-way latency with CLOCK_MONOTONIC (shared by processes on one host). Target p99 <= 2 ms.
2. Servo loop: ``ServoStream`` on the twin backend at 500 Hz in real time, period jitter
   |period - 2 ms|. Target p99 <= 0.5 ms.

    .venv/bin/python bench/bench_bus.py [--seconds 3] [--rate 500] [--backend twin|mujoco]
        [--rt 80]   (SCHED_FIFO for the servo loop, as on the real cell)
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from mesp_cell.bus.session import Bus, BusConfig
from mesp_cell.drivers.extruder_emulator import free_port
from mesp_cell.messages import RobotState


def _publisher(hub: str, n: int, rate: float, ready: mp.Event) -> None:  # type: ignore[valid-type]
    bus = Bus(BusConfig(cell="bench", connect=(hub,)), "robot")
    ready.wait(10)  # type: ignore[attr-defined]
    time.sleep(0.5)  # let the subscription propagate
    period = 1.0 / rate
    q = (0.0, -90.0, 90.0, -90.0, -90.0, 0.0)
    next_t = time.monotonic()
    for i in range(n):
        bus.publish("state", RobotState(time.monotonic(), i, q, (0.0,) * 6, (400.0, 0.0, 100.0),
                                        "streaming", "bench", i, n, i // 4, True, False, "", 0.0))
        next_t += period
        time.sleep(max(0.0, next_t - time.monotonic()))
    time.sleep(0.3)
    bus.close()


def bench_bus(seconds: float, rate: float) -> dict[str, float]:
    hub = f"tcp/127.0.0.1:{free_port()}"
    bus = Bus(BusConfig(cell="bench", listen=(hub,)), "monitor")
    n = int(seconds * rate)
    lat = np.full(n, np.nan)

    def on(msg: RobotState) -> None:
        lat[msg.seq] = time.monotonic() - msg.t

    bus.subscribe("robot", "state", RobotState, on)
    ctx = mp.get_context("spawn")  # never fork a process that holds a zenoh session
    ready = ctx.Event()
    proc = ctx.Process(target=_publisher, args=(hub, n, rate, ready))
    proc.start()
    ready.set()
    proc.join(seconds + 30)
    bus.close()
    got = lat[np.isfinite(lat)] * 1000.0
    if got.size == 0:
        raise SystemExit("no state message arrived")
    return {"messages": float(n), "received": float(got.size),
            "p50_ms": float(np.percentile(got, 50)), "p99_ms": float(np.percentile(got, 99)),
            "max_ms": float(got.max())}


def bench_servo(seconds: float, backend: str, rt: int = 0) -> dict[str, float]:
    import tempfile

    from core.artifacts import save_npz
    from mesp_cell.drivers.robot_base import ServoConfig
    from mesp_cell.drivers.robot_twin import KinematicTwin, mujoco_twin
    from mesp_cell.drivers.stream import ServoStream, StreamPlan

    K = int(seconds * 100) + 1
    t = np.arange(K) / 100.0
    home = np.radians([0.0, -100.0, 100.0, -90.0, -90.0, 0.0])
    q = home + 0.2 * np.sin(2 * np.pi * t / t[-1])[:, None]
    wp = np.where(np.arange(K) % 4 == 0, np.arange(K) // 4, -1).astype(np.int32)
    arrays = {"t": t, "q": q, "qd": np.gradient(q, t, axis=0), "tcp": np.zeros((K, 3)),
              "waypoint": wp, "alpha": np.full(K, 90.0), "extrude": np.ones(K, bool),
              "base_T": np.eye(4), "tool_T": np.eye(4), "model_T": np.eye(4)}
    with tempfile.TemporaryDirectory() as d:
        save_npz(Path(d) / "trajectory.npz", arrays)
        plan = StreamPlan.load(Path(d) / "trajectory.npz", 0.002)
    servo = ServoConfig(realtime_priority=rt)
    driver = KinematicTwin(servo, q0=home) if backend == "twin" else mujoco_twin(servo, q0=home)
    driver.connect()
    result = ServoStream(driver, plan, 0).run()
    jitter = np.abs(result.periods - servo.dt) * 1000.0
    return {"periods": float(jitter.size), "p50_ms": float(np.percentile(jitter, 50)),
            "p99_ms": float(np.percentile(jitter, 99)), "max_ms": float(jitter.max()),
            "mean_period_ms": float(result.periods.mean() * 1000.0)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--rate", type=float, default=500.0, help="state messages per second")
    ap.add_argument("--backend", default="twin", choices=("twin", "mujoco"))
    ap.add_argument("--rt", type=int, default=0,
                    help="SCHED_FIFO priority of the servo loop (0 = normal scheduling)")
    args = ap.parse_args()
    bus = bench_bus(args.seconds, args.rate)
    print(f"bus latency RobotState @ {args.rate:g} Hz: "
          f"{bus['received']:.0f}/{bus['messages']:.0f} received, p50 {bus['p50_ms']:.3f} ms, "
          f"p99 {bus['p99_ms']:.3f} ms, "
          f"max {bus['max_ms']:.3f} ms (target p99 <= 2 ms)")
    servo = bench_servo(args.seconds, args.backend, args.rt)
    sched = f"SCHED_FIFO {args.rt}" if args.rt else "normal scheduling"
    print(f"servo loop 500 Hz on the {args.backend} backend ({sched}): "
          f"{servo['periods']:.0f} periods, "
          f"mean {servo['mean_period_ms']:.4f} ms, jitter p50 {servo['p50_ms']:.3f} ms, "
          f"p99 {servo['p99_ms']:.3f} ms, max {servo['max_ms']:.3f} ms (target p99 <= 0.5 ms)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
