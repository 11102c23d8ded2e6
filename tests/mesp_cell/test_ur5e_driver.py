"""The UR5e RTDE driver's call sequence, against a recording stand-in for ur-rtde."""

from __future__ import annotations

import sys
import types
from typing import Any

import numpy as np
import pytest

from mesp_cell.drivers.robot_base import ServoConfig
from mesp_cell.drivers.ur5e_rtde import UR5eRTDE


class Recorder:
    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple[Any, ...]]] = []


def fake_rtde(rec: Recorder, protective: bool = False) -> tuple[types.ModuleType, types.ModuleType]:
    class Control:
        def __init__(self, host: str, freq: float) -> None:
            rec.calls.append(("control", (host, freq)))

        def __getattr__(self, name: str) -> Any:
            def call(*args: Any) -> Any:
                rec.calls.append((name, args))
                return {"initPeriod": 0.0, "isConnected": True}.get(name, True)

            return call

    class Receive:
        def __init__(self, host: str, freq: float) -> None:
            pass

        def isConnected(self) -> bool:
            return True

        def isProtectiveStopped(self) -> bool:
            return protective

        def getActualQ(self) -> list[float]:
            return [0.0, -1.5, 1.5, -1.5, -1.5, 0.0]

        def getActualTCPPose(self) -> list[float]:
            return [0.4, 0.0, 0.1, 0.0, 3.14, 0.0]

        def disconnect(self) -> None:
            pass

    control, receive = types.ModuleType("rtde_control"), types.ModuleType("rtde_receive")
    control.RTDEControlInterface = Control  # type: ignore[attr-defined]
    receive.RTDEReceiveInterface = Receive  # type: ignore[attr-defined]
    return control, receive


def test_servo_stream_then_move_stops_servo_first(monkeypatch: pytest.MonkeyPatch) -> None:
    rec = Recorder()
    control, receive = fake_rtde(rec)
    monkeypatch.setitem(sys.modules, "rtde_control", control)
    monkeypatch.setitem(sys.modules, "rtde_receive", receive)
    tool = np.eye(4)
    tool[2, 3] = 250.0
    robot = UR5eRTDE("10.0.0.2", ServoConfig(lookahead_s=0.05, gain=500.0), tool_T=tool)
    robot.connect()
    assert rec.calls[0] == ("control", ("10.0.0.2", 500.0))
    assert ("setTcp", ([0.0, 0.0, 0.25, 0.0, 0.0, 0.0],)) in rec.calls
    assert ("setWatchdog", (10.0,)) in rec.calls
    t0 = robot.init_period()
    assert robot.servo_j(np.zeros(6))
    robot.wait_period(t0)
    servo = next(args for name, args in rec.calls if name == "servoJ")
    assert servo[3:] == (0.002, 0.05, 500.0)  # dt, lookahead, gain from the config
    assert robot.move_j(np.ones(6))
    names = [name for name, _ in rec.calls]
    assert names.index("servoStop") < names.index("moveJ")
    assert np.allclose(robot.tcp_mm(), [400.0, 0.0, 100.0])
    robot.kick_watchdog()
    assert names.count("kickWatchdog") == 0 and rec.calls[-1][0] == "kickWatchdog"
    robot.close()
    assert rec.calls[-1][0] == "disconnect"


def test_protective_stop_is_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    rec = Recorder()
    control, receive = fake_rtde(rec, protective=True)
    monkeypatch.setitem(sys.modules, "rtde_control", control)
    monkeypatch.setitem(sys.modules, "rtde_receive", receive)
    robot = UR5eRTDE("10.0.0.2", ServoConfig())
    robot.connect()
    assert robot.protective_stopped() and robot.connected()
