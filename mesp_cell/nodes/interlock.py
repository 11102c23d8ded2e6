"""The robot node's interlocks: asked before every servo sample of a stream.

A stream goes on only while there is no e-stop, the extruder and supervisor processes are on
the bus, the extruder reports no fault (travel included), and, wherever the trajectory
deposits, the extruder reports fresh (``fresh_s``), with
no fault, running, and delivering what it is commanded (``FlowCheck``). ``MustRun`` says at
which samples the extruder must already be running: the robot node switches it ``lead_n``
samples ahead of each change of deposition, and a switch-on needs ``margin_n`` samples to show.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from mesp_cell.messages import ExtruderState, fault_text
from mesp_cell.nodes.flow_check import FlowCheck


def must_run_mask(extrude: np.ndarray, lead_n: int, margin_n: int, start: int) -> np.ndarray:
    """Samples at which the extruder must already be running.

    The robot node switches the extruder ``lead_n`` samples ahead of each change of
    ``extrude`` (``cmd_on``); a deposition sample needs the motor on unless its switch-off lead
    has begun or the last switch-on was less than ``margin_n`` samples ago (command latency).
    A stream that starts with the extruder on (the supervisor started it) counts as switched on
    before ``start``. The whole window since the last switch-on counts, so travel moves shorter
    than the margin cannot make a fresh switch-on look settled.

    Args:
        extrude: (K,) bool. Returns (K,) bool.
    """
    K = extrude.shape[0]
    return _must_run(extrude, np.arange(K), K, lead_n, margin_n, start, -1)[0]


def _must_run(extrude: Any, idx: np.ndarray, K: int, lead_n: int, margin_n: int, start: int,
              last_off_before: int) -> tuple[np.ndarray, int]:
    """``must_run_mask`` at the consecutive samples ``idx`` of K, given the last "off" sample
    before them (-1: none); returns the mask and the last "off" sample up to ``idx[-1]``.
    ``extrude`` is indexable with an int array (a (K,) bool array or ``ServoExtrude``)."""
    ext = np.asarray(extrude[idx], dtype=bool)
    cmd_on = np.asarray(extrude[np.minimum(idx + lead_n, K - 1)], dtype=bool)
    off = ~cmd_on & (idx >= start)
    # last "off" sample at or before k
    last_off = np.maximum(np.maximum.accumulate(np.where(off, idx, -1)), last_off_before)
    settled = (last_off < start) | (idx - last_off - 1 >= margin_n)
    return ext & cmd_on & settled, int(last_off[-1]) if len(idx) else last_off_before


def fault_reason(ext: ExtruderState) -> str:
    """Why a faulted extruder stops the stream, in words ("extruder fault: e-stop latched ...")."""
    return f"extruder fault: {ext.detail or fault_text(ext.fault)}"


class MustRun:
    """``must_run_mask`` of a stream from ``start``, computed a chunk of samples at a time as
    the stream asks for them (a whole long job's mask would hold tens of millions of
    samples). Call it with non-decreasing sample indices >= ``start``."""

    CHUNK = 1 << 16

    def __init__(self, extrude: Any, lead_n: int, margin_n: int, start: int) -> None:
        self.extrude, self.K = extrude, len(extrude)
        self.lead_n, self.margin_n, self.start = lead_n, margin_n, start
        self.c0 = start
        self.mask = np.zeros(0, dtype=bool)
        self.last_off = -1

    def __call__(self, k: int) -> bool:
        if k < self.c0:
            raise ValueError(f"sample {k} before the stream's window at {self.c0}")
        while k >= self.c0 + len(self.mask):
            c0 = self.c0 + len(self.mask)
            idx = np.arange(c0, min(c0 + self.CHUNK, self.K), dtype=np.int64)
            if not len(idx):
                raise IndexError(f"sample {k} beyond the {self.K} samples")
            self.mask, self.last_off = _must_run(self.extrude, idx, self.K, self.lead_n,
                                                 self.margin_n, self.start, self.last_off)
            self.c0 = c0
        return bool(self.mask[k - self.c0])


class Interlock:
    """What the robot node knows of the cell's safety, and the guard built from it.

    Args:
        extruder, supervisor: node names whose processes must be on the bus.
        fresh_s: s of wall time, oldest extruder state accepted where the trajectory deposits.
        flow: the measured-flow check fed by every extruder state.
    """

    def __init__(self, extruder: str, supervisor: str, fresh_s: float, flow: FlowCheck) -> None:
        self.extruder, self.supervisor = extruder, supervisor
        self.fresh_s = fresh_s
        self.flow = flow
        self.alive: set[str] = set()
        self.estopped = ""  # the latched e-stop's reason ("" = none)
        self.estop_t = 0.0  # s since the epoch it latched
        self.ext: ExtruderState | None = None
        self.ext_t = 0.0  # monotonic s the last extruder state arrived
        self.max_age = 0.0  # s, oldest extruder state a guard saw since ``reset_age``

    def on_extruder(self, msg: ExtruderState) -> None:
        """An extruder state arrived (bus thread)."""
        now = time.monotonic()
        self.ext, self.ext_t = msg, now
        self.flow.update(now, msg)

    def latch_estop(self, reason: str) -> None:
        self.estopped, self.estop_t = reason, time.time()

    def presence_reason(self) -> str:
        """Why the stream cannot go on for a missing process ("" if both are there)."""
        for node in (self.extruder, self.supervisor):
            if node not in self.alive:
                return f"{node} process lost"
        return ""

    def extruder_reason(self) -> str:
        """Why the extruder does not deliver what a depositing sample needs ("" if it does)."""
        ext, age = self.ext, time.monotonic() - self.ext_t
        if age > self.max_age:
            self.max_age = age
        if ext is None or age > self.fresh_s:
            return f"no extruder state for {age * 1000:.0f} ms"
        if ext.fault:
            return fault_reason(ext)
        if not ext.running:
            return "extruder not running where the trajectory deposits"
        return self.flow.mismatch()

    def guard(self, must: MustRun) -> Callable[[int], str]:
        """The stream's guard: "" to send sample k, else why it stops before it."""
        self.max_age = 0.0

        def check(k: int) -> str:
            if self.estopped:
                return self.estopped
            why = self.presence_reason()
            if why:
                return why
            if must(k):
                return self.extruder_reason()
            ext = self.ext  # a faulted extruder stops travel moves too, at once
            if ext is not None and ext.fault and time.monotonic() - self.ext_t <= self.fresh_s:
                return fault_reason(ext)
            return ""

        return check
