"""What an e-stop stopped, and when: the confirmation `mesp estop` and the console show.

After an ``EStop`` is published, the robot node latches it (its ``status`` answers the reason
and time), the extruder node stops the motor and latches ``FAULT_ESTOP`` in its state, and the
supervisor leaves the printing job ``interrupted``. ``confirm_estop`` waits for those three
signs, so the operator reads what actually stopped instead of "sent".
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

from mesp_cell.bus.session import Bus
from mesp_cell.jobs import JobStore
from mesp_cell.messages import FAULT_ESTOP, Command, ExtruderState


@dataclass(frozen=True)
class EStopConfirmation:
    """What the nodes reported after an e-stop.

    Attributes:
        sent_t: s since the epoch, when the e-stop was published.
        robot: the robot's latched reason ("" = not confirmed). robot_t: s, when it latched.
        robot_mode: the robot's motion mode after the stop.
        extruder: True when an extruder state showed the motor off with the e-stop latched.
        extruder_t: s, the send time of that state (0 = not confirmed).
        jobs: (job id, state) of the jobs that were printing when it was sent.
    """

    sent_t: float
    robot: str
    robot_t: float
    robot_mode: str
    extruder: bool
    extruder_t: float
    jobs: tuple[tuple[str, str], ...]

    @property
    def confirmed(self) -> bool:
        """Both the robot and the extruder confirmed the stop."""
        return bool(self.robot) and self.extruder

    def lines(self) -> list[str]:
        """One line per thing stopped, with the time it stopped (local clock, ms)."""
        def at(t: float) -> str:
            return time.strftime("%H:%M:%S", time.localtime(t)) + f".{int(t * 1000) % 1000:03d}"

        out = [f"e-stop sent at {at(self.sent_t)}"]
        out.append(f"robot: stopped and latched at {at(self.robot_t)} ({self.robot}; mode "
                   f"{self.robot_mode})" if self.robot else "robot: NOT confirmed")
        out.append(f"extruder: motor off, e-stop latched (state of {at(self.extruder_t)})"
                   if self.extruder else "extruder: NOT confirmed")
        out += [f"job {job}: {state}" for job, state in self.jobs]
        return out


def confirm_estop(bus: Bus, store: JobStore, cell: str, sent_t: float,
                  printing: tuple[str, ...], timeout: float = 2.0) -> EStopConfirmation:
    """Wait up to ``timeout`` s for the robot, the extruder and the supervisor to show the
    e-stop sent at ``sent_t``; ``printing`` are the jobs that were printing then."""
    seen: dict[str, ExtruderState] = {}
    got = threading.Event()

    def on_ext(msg: ExtruderState) -> None:
        if msg.t >= sent_t and msg.fault & FAULT_ESTOP and not msg.running:
            seen.setdefault("state", msg)
            got.set()

    bus.subscribe("extruder", "state", ExtruderState, on_ext)
    end = time.time() + timeout
    robot, robot_t, mode = "", 0.0, ""
    while time.time() < end and not robot:
        reply = bus.request("robot", Command.make("status"), max(0.2, end - time.time()))
        if reply.ok and reply.value("estopped"):
            robot = str(reply.value("estopped"))
            robot_t = float(reply.value("estop_t", 0.0))
            mode = str(reply.value("mode", ""))
        else:
            time.sleep(0.05)
    got.wait(max(0.0, end - time.time()))
    states: dict[str, str] = {}
    while True:
        states = {j: store.get(j).state for j in printing}
        if all(s != "printing" for s in states.values()) or time.time() >= end:
            break
        time.sleep(0.05)
    ext = seen.get("state")
    return EStopConfirmation(sent_t, robot, robot_t, mode, ext is not None,
                             ext.t if ext is not None else 0.0, tuple(states.items()))
