"""Toolpath -> timed UR5e joint trajectory: the ``mesp plan`` pipeline as a library call.

Stages: normals (the slicer's repair of single-waypoint spikes, ``slicer.normals``, then the
bounded smoothing along each path, ``planner.path_smoothing``), placement (search the model's
place in the tank),
resample (insert samples on long segments, ``planner.samples``; relax fast turns of the
printing direction within alpha's band, ``planner.turn_relief``; ease the direction on moves
between paths, ``planner.move_axis``), upright (turn printing
directions towards vertical where the wrist would near the base axis), orientation (spin and
alpha per sample), continuity (insert samples where a step in joint space would swing the tip
off the path), entry (into and out of the gel along the nozzle axis), velocity (DLS joint
rates; one-sided where deposition stops and starts, ``path_derivatives``), timing (time law
within joint limits), report (``planner.plan_report``), verify (the
executed trajectory against every limit: ``planner.verify``; the status is ok only if all
hold). Where the plan is not ok at the searched placement (a blocked entry or exit, a waypoint
the search's sample missed, a broken limit), the stages after it run again at the search's
next placements (another yaw first: where the job starts and ends decides). ``plan`` returns
the ``Trajectory`` stage, the report section and the status with its one-line message
(``planner.status``).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from core.errors import InputError
from core.progress import Progress, StageTimer
from core.stages import Toolpath
from core.tolerance import tol
from planner import kinematics as kin
from planner.cell import CellConfig
from planner.continuity import SWING_TOL_MM, subdivide
from planner.entry import safe_heights, safe_move
from planner.move_axis import ease_moves
from planner.nozzle_axis import alpha_of
from planner.orientation import Orientation, choose
from planner.path_derivatives import junctions
from planner.placement import Placement, bbox, choose_placement, fit_gel, model_transform
from planner.plan_report import (
    between_status,
    move_report,
    plan_report,
    stats,
    unreachable,
    unreachable_message,
    upright_report,
)
from planner.printability import directions
from planner.reach import OK, Reach
from planner.samples import (
    Samples,
    expand_timing,
    insert_between,
    moving_samples,
    resample,
    with_moves,
)
from planner.status import MESSAGES, Cause, PlanStatus, TimingStatus
from planner.timing import (
    Timing,
    angular_rates,
    path_parameter,
    task_rates,
    time_law,
)
from planner.trajectory import Trajectory
from planner.turn_relief import relieve_turns
from planner.upright import upright
from planner.verify import verify


@dataclass(frozen=True)
class PlanResult:
    """Everything ``plan`` produced.

    Attributes:
        trajectory: the stage written to trajectory.npz.
        report: the "plan" section of report.json.
        samples, orientation, timing, placement: intermediate values (for plots and tests).
        clearance: (M,) float64, mm, clearance along the trajectory (nan where not sampled).
        status: ``PlanStatus.OK`` or the first limit not kept (only OK may be executed).
        message: one line: what holds, or which waypoint/sample breaks what and why.
        cause: why the first refused waypoint is refused, in the user's terms (None if none).
    """

    trajectory: Trajectory
    report: dict[str, Any]
    samples: Samples
    orientation: Orientation
    timing: Timing
    placement: Placement
    clearance: np.ndarray
    status: PlanStatus
    message: str
    cause: Cause | None = None


REPLANS = 4  # placements tried after the best one where its entry or exit is blocked


def plan(
    toolpath: Toolpath, cell: CellConfig, progress: Progress | None = None,
    placement: Placement | None = None,
) -> PlanResult:
    """Plan the whole job (see module docstring).

    Raises:
        InputError: an empty toolpath, or no placement reaches the job.
    """
    if len(toolpath) == 0:
        raise InputError("the toolpath has no waypoints", "re-run `mesp slice`")
    if not np.all(np.isfinite(toolpath.position)) or not np.all(np.isfinite(toolpath.normal)):
        raise InputError("the toolpath holds non-finite positions or normals",
                         "re-run `mesp slice`")
    timer = StageTimer(progress)
    cell = fit_gel(cell, toolpath)
    reach = Reach(cell)
    with timer.stage("normals"):
        toolpath, repaired, smoothed = directions(toolpath, cell)
    with timer.stage("placement"):
        searched = placement is None
        if placement is None:
            placement = choose_placement(reach, toolpath)
    result = _plan_placed(toolpath, reach, placement, timer, repaired, smoothed)
    if searched and _refused(result):
        # the entry or exit depends on where the job starts and ends, and the placement score
        # checks only a sample of the waypoints (a lone one at a steep edge can be out of
        # reach, a sample between them near a wall): re-plan at the search's other reaching
        # placements
        box = bbox(toolpath)
        tries = 0
        for x, y, yaw, clear in placement.alternatives[:REPLANS]:
            tries += 1
            offset = (x, y, cell.placement.offset_mm[2])
            alt = replace(placement, model_T=model_transform(cell, box, np.array(offset), yaw),
                          offset_mm=offset, yaw_deg=yaw, clearance_mm=clear)
            again = _plan_placed(toolpath, reach, alt, timer, repaired, smoothed,
                                 f" (yaw {yaw:g})")
            again.report["placement"]["replanned"] = tries
            if not _refused(again):
                return again
        result.report["placement"]["replanned"] = tries
    return result


def _refused(result: PlanResult) -> bool:
    """The plan is not executable at its placement (any status but ok: an unreachable
    waypoint, a blocked entry or exit, a limit the verification found broken)."""
    return result.status != PlanStatus.OK


def _plan_placed(toolpath: Toolpath, reach: Reach, placement: Placement, timer: StageTimer,
                 repaired: np.ndarray, smoothed: np.ndarray, tag: str = "") -> PlanResult:
    """The stages after the placement (module docstring), for one placement; ``tag`` follows
    the stage names (a re-plan's stages are told apart from the first plan's)."""
    cell = reach.cell
    with timer.stage("resample" + tag):
        samples, relieved = relieve_turns(resample(toolpath, placement.model_T, cell), cell)
        samples = ease_moves(samples)
    with timer.stage("upright" + tag):
        up = upright(reach, samples.tcp, samples.normal, samples.tangent, samples.extrude,
                     samples.arrive)
    with timer.stage("orientation" + tag):
        orient = choose(reach, samples.tcp, up.normal, samples.tangent, samples.extrude,
                        arrive=samples.arrive)
    with timer.stage("continuity" + tag):
        samples, orient, split = _continuous(reach, samples, orient)
    with timer.stage("entry" + tag):
        # home -> above the first sample -> plunge along its nozzle axis; the mirror at the end
        heights = safe_heights(reach)
        entry = safe_move(reach, reach.home, orient.q[0], heights)
        leave = safe_move(reach, orient.q[-1], reach.home, heights)
        samples, orient, part, corner = with_moves(reach, samples, orient, entry, leave)
    with timer.stage("velocity" + tag):
        q = orient.q
        T_tcp = kin.fk(q, reach.tool_m)
        tcp = T_tcp[:, :3, 3] * 1000.0
        axis = T_tcp[:, :3, 2]
        # samples that repeat the previous pose (repeated waypoints) carry no motion: time
        # and joint rates come from the others, the repeats follow 1 us later
        keep = moving_samples(q)
        s = path_parameter(tcp[keep], T_tcp[keep, :3, :3])
        # entry and exit: joint rates of the sampled joint path; the toolpath: DLS rates
        dq = np.gradient(q[keep], s, axis=0)
        main = part[keep] == 1
        # where deposition stops and starts, rates from the depositing side (``junctions``)
        side = np.zeros(int(keep.sum()), dtype=np.int8)
        side[main] = junctions(samples.extrude[keep][main])
        omega = angular_rates(T_tcp[keep][main, :3, :3], s[main], side[main])
        dq[main] = task_rates(q[keep][main], tcp[keep][main], axis[keep][main], omega, s[main],
                              reach.tool_m, cell.planning.damping, side=side[main])
        # at rest where the toolpath begins and ends and at the corners of entry and exit
        stop = np.zeros(len(q), dtype=bool)
        stop[np.flatnonzero(part == 1)[[0, -1]]] = True
        stop |= corner
    with timer.stage("timing" + tag):
        vmax = np.radians(cell.robot.max_velocity_deg_s)
        amax = np.radians(cell.robot.max_acceleration_deg_s2)
        timing = expand_timing(
            time_law(q[keep], dq, tcp[keep], s, samples.speed[keep], vmax, amax,
                     stop=stop[keep], side=side), keep)
    with timer.stage("report" + tag):
        alpha = np.degrees(alpha_of(axis, samples.tangent))
        traj = Trajectory(
            t=timing.t, q=q, qd=timing.qd, tcp=tcp, waypoint=samples.waypoint, alpha=alpha,
            extrude=samples.extrude, base_T=cell.robot.base_T, tool_T=cell.tool.tool_T,
            model_T=placement.model_T,
        )
        unreached = unreachable(reach, samples, orient, part)
        report = plan_report(toolpath, cell, reach, samples, orient, timing, placement, traj,
                             unreached, timer.seconds)
        report["normals_repaired"] = int(repaired.sum())
        report["normals_smoothed_deg"] = stats(np.degrees(smoothed))
        report["turn_relief_deg"] = {**stats(np.degrees(relieved)),
                                     "samples": int(np.sum(relieved > tol.still))}
        report["gel_fill_mm"] = cell.tank.gel_fill_mm
        report["continuity"] = split
        report["upright"] = upright_report(up, orient, part == 1)
        report["entry"] = move_report(entry, traj, part == 0)
        report["exit"] = move_report(leave, traj, part == 2)
    status, message = PlanStatus.OK, MESSAGES[PlanStatus.OK]
    cause: Cause | None = None
    if unreached.count:
        status = PlanStatus.UNREACHABLE
        message, cause = unreachable_message(toolpath, reach, samples, orient, part)
    elif unreached.between_waypoints:
        status = PlanStatus.UNREACHABLE_BETWEEN
        between = np.flatnonzero((orient.status != OK) & (samples.waypoint < 0) & (part == 1))
        message = between_status(reach, samples, orient, between)
    for move, blocked in ((entry, PlanStatus.ENTRY_BLOCKED), (leave, PlanStatus.EXIT_BLOCKED)):
        if not move.ok and status == PlanStatus.OK:
            status = blocked
            message = (f"{blocked}: {move.reason}; move the part away from the walls "
                       "(placement) or change the home pose")
    if split["worst_swing_mm"] > SWING_TOL_MM and status == PlanStatus.OK:
        status = PlanStatus.SWING
        message = (f"the nozzle would leave the path by {split['worst_swing_mm']:.2f} mm between "
                   "two samples (a pose next to a singularity); move the part (placement) or "
                   "the robot base")
    if timing.status != TimingStatus.OK and status == PlanStatus.OK:
        status, message = PlanStatus.TIME_LAW, timing.status
    with timer.stage("verify" + tag):
        # whatever the stages decided: the executed trajectory against every limit
        checked = verify(traj, samples.speed, reach)
    report["verified"] = checked.as_report()
    if checked.breaches and status == PlanStatus.OK:
        b = checked.breaches[0]
        status = b.status
        layer = (f" (layer {int(toolpath.layer[b.waypoint])})" if b.waypoint >= 0 else "")
        message = (f"{MESSAGES[b.status]}: {b.count} samples, the first after waypoint "
                   f"{b.waypoint}{layer}, worst {b.detail}")
    report["status"] = str(status)
    report["message"] = message
    report["cause"] = None if cause is None else str(cause)
    return PlanResult(traj, report, samples, orient, timing, placement, orient.clearance,
                      status, message, cause)



def _continuous(reach: Reach, samples: Samples, orient: Orientation
                ) -> tuple[Samples, Orientation, dict[str, Any]]:
    """Samples inserted where the joint-space step between two samples would swing the tip
    off the path (``continuity.subdivide``), checked like the others; and the report."""
    sub = subdivide(orient.q, reach.solve, reach.tool_m)
    report: dict[str, Any] = {"tolerance_mm": SWING_TOL_MM,
                              "steps_split": int(np.unique(sub.step).size),
                              "samples_inserted": len(sub.step),
                              "worst_swing_mm": round(sub.worst_mm, 4)}
    samples, orient = insert_between(reach, samples, orient, sub)
    return samples, orient, report
