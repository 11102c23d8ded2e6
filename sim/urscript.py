"""A planned trajectory as a stand-alone URScript program, and that program read back.

The program replays ``trajectory.npz`` with ``servoj``: one target per trajectory sample, held
for the time to the next one, so the controller follows the same piecewise-linear joint motion
the twin replays. Sample times are rounded to the controller's 2 ms period (samples that fall
on one tick are merged) and intervals longer than ``max_step_s`` are split into linearly
interpolated targets, because servoj is meant for short steps. The extruder is driven by the
controller's standard outputs: a digital output runs it while the trajectory extrudes, an
analog output holds the rate set-point as a fraction of the extruder's full scale (the wiring
the extruder's analog/run inputs need; the Modbus register interface is not used here).

``parse_urscript`` reads back the subset this module writes (``set_tcp``, ``movej``,
``servoj``, ``set_standard_digital_out``), so a program can be checked on the twin.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from core.errors import InputError
from planner.trajectory import Trajectory

CONTROL_PERIOD_S = 0.002  # UR e-series controller period (500 Hz)


@dataclass(frozen=True)
class ExtruderIO:
    """Which controller outputs drive the extruder.

    Attributes:
        rate_mm3_s: the extruder's set-point for the job, mm^3/s (the job's extrusion profile's
            ``setpoint_mm3_s``, the command that delivers its C: the profile is its one owner).
        run_output: standard digital output that runs the extruder (high = extrude).
        rate_output: standard analog output carrying the rate set-point.
        full_scale_mm3_s: the rate the extruder runs at for a full-scale analog signal, mm^3/s.
    """

    rate_mm3_s: float
    run_output: int = 0
    rate_output: int = 0
    full_scale_mm3_s: float = 20.0

    def __post_init__(self) -> None:
        if not 0 <= self.run_output <= 7 or not 0 <= self.rate_output <= 1:
            raise InputError(f"extruder outputs DO{self.run_output}/AO{self.rate_output} "
                             "do not exist on a UR controller",
                             "use a standard digital output 0-7 and analog output 0-1")
        if not 0 < self.rate_mm3_s <= self.full_scale_mm3_s:
            raise InputError(f"rate {self.rate_mm3_s} mm^3/s is outside the extruder's analog "
                             f"full scale {self.full_scale_mm3_s} mm^3/s",
                             "pass --rate-full-scale at least the job's rate")


@dataclass(frozen=True)
class ServoProgram:
    """The motion of a URScript program.

    Attributes:
        t: (K,) float64, s, time each target is reached (0 = the start pose).
        q: (K, 6) float64, rad, joint targets.
        extrude: (K,) bool, the extruder runs on the way to the next target.
        tool_T: (4, 4) float64, mm, the TCP the program sets (flange frame).
    """

    t: NDArray[np.float64]
    q: NDArray[np.float64]
    extrude: NDArray[np.bool_]
    tool_T: NDArray[np.float64]

    def trajectory(self, like: Trajectory) -> Trajectory:
        """The program's motion as a Trajectory (qd by finite differences, frames of ``like``)."""
        from planner import kinematics as kin

        tool = self.tool_T.copy()
        tool[:3, 3] /= 1000.0
        tcp = kin.fk(self.q, tool)[:, :3, 3] * 1000.0
        qd = np.gradient(self.q, self.t, axis=0) if len(self.t) > 1 else np.zeros_like(self.q)
        return Trajectory(
            t=self.t, q=self.q, qd=qd, tcp=tcp, waypoint=np.full(len(self.t), -1, np.int32),
            alpha=np.full(len(self.t), 90.0), extrude=self.extrude, base_T=like.base_T,
            tool_T=self.tool_T, model_T=like.model_T,
        )


def servo_targets(traj: Trajectory, max_step_s: float = 0.1) -> ServoProgram:
    """The servoj targets of ``traj``: 2 ms-grid times, long intervals subdivided."""
    t_src, q_src = np.asarray(traj.t), np.asarray(traj.q)
    ticks = np.unique(np.round(t_src / CONTROL_PERIOD_S).astype(np.int64))
    max_ticks = max(1, round(max_step_s / CONTROL_PERIOD_S))
    pieces = np.maximum(1, np.ceil(np.diff(ticks) / max_ticks).astype(np.int64))
    # each interval split into `pieces` near-equal integer steps
    starts = np.r_[0, np.cumsum(pieces)]
    seg = np.repeat(np.arange(len(pieces)), pieces)
    frac = (np.arange(starts[-1]) - starts[seg]) / pieces[seg]
    new_ticks = np.unique(np.r_[ticks[seg] + np.round(frac * np.diff(ticks)[seg]), ticks[-1]])
    t = new_ticks * CONTROL_PERIOD_S
    # the planned motion sampled at the grid times: on the path at the right time
    q_new = np.stack([np.interp(t, t_src, q_src[:, j]) for j in range(6)], 1)
    src = np.clip(np.searchsorted(t_src, t, side="right") - 1, 0, len(t_src) - 1)
    ext_new = np.asarray(traj.extrude)[src]
    return ServoProgram(t - t[0], q_new, ext_new.astype(bool), np.asarray(traj.tool_T))


def _fmt(values: NDArray[np.float64]) -> str:
    return "[" + ", ".join(f"{v:.6f}" for v in values) + "]"


def urscript(traj: Trajectory, io: ExtruderIO, max_step_s: float = 0.1,
             lookahead_s: float = 0.1, gain: int = 300, name: str = "mesp_print") -> str:
    """The URScript program text that prints ``traj`` without this software."""
    prog = servo_targets(traj, max_step_s)
    tool = prog.tool_T
    rv = Rotation.from_matrix(tool[:3, :3]).as_rotvec()
    tcp = np.r_[tool[:3, 3] / 1000.0, rv]
    out = [
        f"def {name}():",
        f"  # MESP Cell print: {len(prog.t)} servoj targets, {prog.t[-1]:.1f} s",
        f"  # extruder: run = standard DO{io.run_output}, rate {io.rate_mm3_s:.3f} mm^3/s on "
        f"standard AO{io.rate_output} (full scale {io.full_scale_mm3_s:.3f} mm^3/s)",
        f"  set_tcp(p{_fmt(tcp)})",
        f"  set_standard_digital_out({io.run_output}, False)",
        f"  set_standard_analog_out({io.rate_output}, "
        f"{io.rate_mm3_s / io.full_scale_mm3_s:.6f})",
        f"  movej({_fmt(prog.q[0])}, a=0.5, v=0.25)",
    ]
    on = False
    dt = np.diff(prog.t)
    for k in range(1, len(prog.t)):
        want = bool(prog.extrude[k - 1])
        if want != on:
            out.append(f"  set_standard_digital_out({io.run_output}, {want})")
            on = want
        out.append(f"  servoj({_fmt(prog.q[k])}, 0, 0, {dt[k - 1]:.3f}, {lookahead_s}, {gain})")
    out += ["  stopj(2.0)", f"  set_standard_digital_out({io.run_output}, False)", "end",
            f"{name}()", ""]
    return "\n".join(out)


_NUM = r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"
_LIST = rf"\[\s*({_NUM}(?:\s*,\s*{_NUM}){{5}})\s*\]"
_SERVOJ = re.compile(rf"^\s*servoj\(\s*{_LIST}\s*,\s*{_NUM}\s*,\s*{_NUM}\s*,\s*({_NUM})")
_MOVEJ = re.compile(rf"^\s*movej\(\s*{_LIST}")
_TCP = re.compile(rf"^\s*set_tcp\(\s*p{_LIST}")
_DOUT = re.compile(r"^\s*set_standard_digital_out\(\s*(\d+)\s*,\s*(True|False)\s*\)")


def _floats(text: str) -> NDArray[np.float64]:
    return np.array([float(v) for v in text.split(",")])


def parse_urscript(text: str, run_output: int = 0) -> ServoProgram:
    """Read the motion of a program written by ``urscript`` back.

    Raises:
        InputError: the program has no start pose or no servoj targets.
    """
    tool = np.eye(4)
    q: list[NDArray[np.float64]] = []
    t: list[float] = []
    ext: list[bool] = []
    on = False
    for line in text.splitlines():
        if m := _TCP.match(line):
            v = _floats(m.group(1))
            tool[:3, :3] = Rotation.from_rotvec(v[3:]).as_matrix()
            tool[:3, 3] = v[:3] * 1000.0
        elif m := _DOUT.match(line):
            if int(m.group(1)) == run_output:
                on = m.group(2) == "True"
        elif (m := _MOVEJ.match(line)) and not q:
            q.append(_floats(m.group(1)))
            t.append(0.0)
            ext.append(False)
        elif m := _SERVOJ.match(line):
            if not q:
                raise InputError("servoj before the start pose", "start with movej")
            ext[-1] = on  # the state on the way to this target
            q.append(_floats(m.group(1)))
            t.append(t[-1] + float(m.group(2)))
            ext.append(on)
    if len(q) < 2:
        raise InputError("the program has no servoj motion", "write it with mesp export")
    return ServoProgram(np.array(t), np.array(q), np.array(ext, bool), tool)
