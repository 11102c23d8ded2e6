"""The robot node's extruder switches, sent off the servo thread, their latency measured.

The servo loop decides on its clock when the extruder starts, stops or changes rate
(``lead_s`` ahead of deposition, ``FlowSync``); a bus request to the extruder node takes a few
ms of wall time, so ``Switcher`` sends them from its own thread, in order.

Each switch reaches the screw late by that latency. On the real cell (time scale 1) a few ms
move a few thousandths of a mm^3. A twin ``time_scale`` times faster than real time counts the
same wall-clock latency ``time_scale`` times over in simulated time, where the emulated
extruder's flow integrates: at 40x a 1.5 ms later start than stop cost 6 % of a short-path
job's ink, an ink no real cell would miss. So each switch's latency is measured on the clock
the extruder's flow runs on (the twin's shared clock; the wall clock on the real cell), and the
ink it moved beyond what the same switch would have moved in real time,
``-(new - old rate) x latency x (1 - 1 / time_scale)`` (nominal mm^3), is appended to the
job's ledger (``print_ledger.SWITCH``), where the print check takes it off the part's ink.
At time scale 1 that excess is zero and nothing is recorded.

On the twin the latency need not move any ink: the switcher holds the shared clock
(``SimClock.hold``) at the time the switch was decided until the extruder node acknowledged
it, so the emulated extruder takes it at that simulated time whatever the wall-clock latency
(on a loaded host, at time scale 1 too, where nothing is recorded); its latency measured on
that clock is then 0 and so is its excess (docs/robustness.md). A switch is timed by the
twin's own simulated time (``decided``), not by the shared clock: while an earlier switch
still holds the clock back, a later one read the held time, so a stop and the start after a
travel shorter than the latency landed together and the screw ran through the travel.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from mesp_cell.drivers.sim_clock import SimClock
from mesp_cell.nodes.print_ledger import Ledger

log = logging.getLogger("mesp.robot")

HOLD_KEY = "switch"  # the switches' hold on the twin's shared clock
HOLD_S = 1.0  # s of wall time a switch holds the clock at most (the bus request's timeout)
DUE_WAIT_S = 0.05  # s of wall time a switch waits at most for the shared clock to reach it
REWIND_S = 1.0  # s: a clock this far behind the latest reading was reset (a new emulator)


class Switch(NamedTuple):
    """One extruder command from a stream.

    Attributes:
        verb: "start" | "stop" | "set_rate". rate: mm^3/s, the rate sent.
        step: mm^3/s, the set-point change it makes (new - old; 0 for a safety stop).
        due: s on the flow's clock when the servo loop decided it.
        job_dir: the ledger's folder (None: not recorded, e.g. a safety stop).
    """

    verb: str
    rate: float
    step: float = 0.0
    due: float = 0.0
    job_dir: Path | None = None


class Switcher:
    """Sends ``Switch``es in order through ``send`` (verb, rate -> refusal reason or "").

    Args:
        send: the bus request to the extruder node; returns "" when done, else why not.
        clock: s, the clock the extruder's flow runs on (the twin's ``SimClock.now``; the
            wall clock on the real cell).
        time_scale: the twin's speed-up (1 on the real cell).
        sim_clock: the twin's shared clock, held at each switch's time until the extruder
            took it (None on the real cell).
        decided: s, the time a switch is decided at (the twin's own simulated time,
            ``KinematicTwin.sim_now``); default ``clock``.
    """

    def __init__(self, send: Callable[[str, float], str], clock: Callable[[], float],
                 time_scale: float, sim_clock: SimClock | None = None,
                 decided: Callable[[], float] | None = None) -> None:
        self.send, self._clock, self.time_scale = send, clock, float(time_scale)
        self.sim_clock = sim_clock
        self._decided = decided or clock
        self._queue: queue.Queue[Switch] = queue.Queue()
        self._latest = float("-inf")
        self._latest_due = float("-inf")
        self._pending: deque[float] = deque()  # due of each switch queued and not yet sent
        self._pending_lock = threading.Lock()

    def clock(self) -> float:
        """The flow's clock, never back: a twin that lags pulls the shared clock back to its
        own time, and the emulated flow holds until the clock passes where it was."""
        self._latest = _forward(self._latest, self._clock())
        return self._latest

    def put(self, verb: str, rate: float, step: float = 0.0,
            job_dir: Path | None = None) -> None:
        """Queue a switch decided now (thread-safe; returns at once); on the twin, hold the
        clock at now until it is sent."""
        with self._pending_lock:
            self._latest_due = _forward(self._latest_due, self._decided())
            sw = Switch(verb, rate, step, self._latest_due, job_dir)
            if self.sim_clock is not None:
                self._pending.append(sw.due)
                if len(self._pending) == 1:
                    self.sim_clock.hold(HOLD_KEY, sw.due, HOLD_S)
            self._queue.put(sw)

    def _sent(self) -> None:
        """The oldest queued switch was sent (or refused): hold at the next one, if any."""
        if self.sim_clock is None:
            return
        with self._pending_lock:
            if self._pending:
                self._pending.popleft()
            if self._pending:
                self.sim_clock.hold(HOLD_KEY, self._pending[0], HOLD_S)
            else:
                self.sim_clock.release(HOLD_KEY)

    def run(self, stopping: threading.Event) -> None:
        """Send queued switches until ``stopping`` is set (the node's thread)."""
        while not stopping.is_set():
            try:
                sw = self._queue.get(timeout=0.2)
            except queue.Empty:
                continue
            try:
                if sw.step:
                    self._await_due(sw.due)
                why = self.send(sw.verb, sw.rate)
                if why:
                    log.warning("extruder %s refused: %s", sw.verb, why)
                    continue
                # on the twin the hold lands it at ``due``: 0, or < 0 where the wait for the
                # clock timed out and the extruder took it early
                self._record(sw, self.clock() - sw.due)
            finally:
                self._sent()

    def _await_due(self, due: float) -> None:
        """On the twin, send a planned switch no earlier than its time: a twin running ahead of
        the shared clock (by at most its sleep batch, 1 ms of wall time) decides it before the
        clock gets there, and the hold then stops the clock at ``due`` until it is taken."""
        if self.sim_clock is None:
            return
        end = time.monotonic() + DUE_WAIT_S
        while self.sim_clock.now() < due and time.monotonic() < end:
            time.sleep(0.0002)

    def excess_mm3(self, step: float, latency: float) -> float:
        """Nominal mm^3 a switch of ``step`` mm^3/s, ``latency`` s late on the flow's clock,
        moved beyond what it would have moved in real time."""
        return -step * latency * (1.0 - 1.0 / self.time_scale)

    def _record(self, sw: Switch, latency: float) -> None:
        if sw.job_dir is None or not sw.step or self.time_scale <= 1.0:
            return
        try:
            ledger = Ledger(sw.job_dir, fresh=False)
        except OSError as exc:  # the job's folder went away: nothing to account it to
            log.warning("switch latency not recorded: %s", exc)
            return
        try:
            ledger.switch(self.excess_mm3(sw.step, latency), latency)
        finally:
            ledger.close()


def _forward(latest: float, now: float) -> float:
    """``now``, never back from ``latest`` (a twin that lags pulls the shared clock back a
    little), unless the clock was reset (``REWIND_S`` behind)."""
    return now if now < latest - REWIND_S else max(latest, now)


def wall_clock() -> float:
    """The real cell's flow clock: the wall clock, s."""
    return time.monotonic()
