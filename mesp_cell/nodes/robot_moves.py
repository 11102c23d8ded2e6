"""The robot node's moves: home or to a trajectory sample on a checked safe path.

``move`` (args ``to``: "home" | "sample", ``sample``) goes there on the path ``planner.entry``
checks against the cell model: retract along the nozzle axis out of the gel, transfer above
it, plunge along the target's axis; refused with its reason when the model finds none. The
gel level is the loaded job's (``fit_gel`` on its toolpath), else the cell's own fill. A move
runs in the node's motion thread and ends with a ``StreamEvent`` ("moved" or "stopped").
Mixed into ``RobotNode``, which owns the state it uses.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mesp_cell.drivers.robot_base import RobotDriver, ServoConfig
from mesp_cell.drivers.stream import ServoStream, StreamPlan
from mesp_cell.messages import Command, Reply, StreamEvent
from mesp_cell.nodes.idle_pace import Pace
from mesp_cell.nodes.interlock import Interlock
from mesp_cell.states import RobotMode, StreamEnd

log = logging.getLogger("mesp.robot")


class RobotMoves:
    """Point-to-point moves of ``RobotNode`` (which sets these in ``on_configure``)."""

    driver: RobotDriver
    servo: ServoConfig
    cell: Any  # planner.cell.Cell of this robot
    home: np.ndarray
    reach: Any
    plan: StreamPlan | None
    mode: str
    _abort_move: threading.Event
    _in_motion: threading.Event
    pace: Pace
    _motion: threading.Thread | None

    interlock: Interlock
    spawn: Callable[[Any, str], threading.Thread]
    _event: Callable[[StreamEvent], None]

    def _reach(self, job_dir: Path | None) -> Any:
        """The planner's reachability model of this cell, gel filled as the job's plan
        filled it (``fit_gel`` on the job's toolpath), or the cell's own fill."""
        from planner.placement import fit_gel
        from planner.reach import Reach

        cell = self.cell
        if job_dir is not None and (job_dir / "toolpath.npz").is_file():
            from core.stages import Toolpath

            cell = fit_gel(cell, Toolpath.load(job_dir))
        return Reach(cell)

    def _safe_path(self, target: np.ndarray) -> tuple[StreamPlan | None, str]:
        """A servo plan from the current joints to ``target`` on a checked safe path
        (``planner.entry.safe_move``), or None and the reason there is none; None and ""
        when the robot is already there."""
        from planner import entry

        q0 = np.asarray(self.driver.joints(), dtype=float)
        if np.abs(q0 - target).max() < 1e-4:
            return None, ""
        if self.reach is None:
            self.reach = self._reach(None)
        reach = self.reach
        move = entry.safe_move(reach, q0, target, entry.safe_heights(reach), tolerate_start=True)
        if not move.ok:
            return None, f"no safe path: {move.reason}"
        timing = entry.time_move(reach, move)
        dt = self.servo.dt
        # hold the target a little at the end: the servo (lookahead) settles onto it
        hold = np.ceil(max(0.2, 2.0 * self.servo.lookahead_s) / dt) * dt
        tool_T = self.plan.tool_T if self.plan is not None else self.cell.tool.tool_T
        return StreamPlan.of_path(dt, timing.t, move.q, tool_T, hold), ""

    def _start_move(self, cmd: Command) -> Reply:
        to = cmd.arg("to", "home")
        if to == "home":
            target = self.home
        elif to == "sample":
            if self.plan is None:
                return Reply.refuse("no trajectory loaded")
            k = int(cmd.arg("sample", 0))
            if not 0 <= k < self.plan.samples:
                return Reply.refuse(f"sample {k} outside the trajectory")
            target = self.plan.q_at(k)
        else:
            return Reply.refuse(f"unknown move target '{to}'")
        path, why = self._safe_path(np.asarray(target, dtype=float))
        if why:
            return Reply.refuse(why)
        self._abort_move.clear()

        def guard(k: int) -> str:
            if self.interlock.estopped:
                return self.interlock.estopped
            return "move interrupted" if self._abort_move.is_set() else ""

        def run() -> None:
            self.mode = RobotMode.MOVING
            self.pace.wake()  # the state shows the move at once (``idle_pace``)
            log.info("move of %s to %s (%d servo samples)", cmd.job_id, to,
                     0 if path is None else path.samples)
            ok, why = False, "move interrupted"
            try:
                if path is None:
                    ok = not self._abort_move.is_set()
                else:
                    result = ServoStream(self.driver, path, 0, guard).run()
                    ok, why = result.done, result.reason or why
            except Exception as exc:  # the end event must go out whatever happened
                log.exception("move failed")
                why = f"move failed: {exc}"
            finally:
                self.mode = RobotMode.IDLE if ok else RobotMode.STOPPED
                self._in_motion.clear()
                self.pace.wake()
            log.info("move of %s to %s %s", cmd.job_id, to, "done" if ok else why)
            self._event(StreamEvent(cmd.job_id, StreamEnd.MOVED if ok else StreamEnd.STOPPED,
                                    "" if ok else why, -1, time.time()))

        self._in_motion.set()
        self._motion = self.spawn(run, "move")
        return Reply.done()
