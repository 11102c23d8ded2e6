"""What a plan's status means: one enum for the outcome, one table of what to do about it.

``PlanStatus`` is the plan's verdict (``PlanResult.status``, report.json ``plan.status``); only
``OK`` may be executed. ``Cause`` names why a waypoint is refused, in the user's terms (a bend
of the path, a printing direction pointing down, reach, a wall). ``MESSAGES`` and ``CAUSES``
hold the one-line explanation of each; the specific message of a plan (which waypoint, which
layer, which fix was checked) is built where it is found (``planner.refusal``,
``planner.verify``).
"""

from __future__ import annotations

from enum import StrEnum

from core.errors import InputError
from core.status import Status


class PlanStatus(StrEnum):
    """The outcome of ``planner.plan.plan``: ``OK`` or the first limit it could not keep."""

    OK = "ok"
    UNREACHABLE = "unreachable waypoints"
    UNREACHABLE_BETWEEN = "unreachable between waypoints"
    ENTRY_BLOCKED = "unreachable entry"
    EXIT_BLOCKED = "unreachable exit"
    SWING = "off the path between samples"
    TIME_LAW = "time law not met"
    ALPHA = "alpha out of range"
    CLEARANCE = "clearance below the requirement"
    JOINT_SPEED = "joint speed above the limit"
    JOINT_RANGE = "joint outside its range"
    TCP_SPEED = "nozzle faster than the toolpath"


MESSAGES: dict[PlanStatus, str] = {
    PlanStatus.OK: "every limit holds on every sample of the trajectory",
    PlanStatus.UNREACHABLE: "some toolpath waypoints have no nozzle pose within the limits",
    PlanStatus.UNREACHABLE_BETWEEN: "samples between waypoints have no pose within the limits",
    PlanStatus.ENTRY_BLOCKED: "the move from home into the gel collides or has no solution",
    PlanStatus.EXIT_BLOCKED: "the move out of the gel back home collides or has no solution",
    PlanStatus.SWING: "the tip would leave the path between two samples (near a singularity)",
    PlanStatus.TIME_LAW: "the time law could not keep the joint accelerations within limits",
    PlanStatus.ALPHA: "the executed nozzle axis leaves [alpha_min, alpha_max] on a depositing "
                      "step",
    PlanStatus.CLEARANCE: "the executed motion comes closer than [planning] clearance_mm to the "
                          "cell",
    PlanStatus.JOINT_SPEED: "the executed motion turns a joint faster than its velocity limit",
    PlanStatus.JOINT_RANGE: "the executed motion takes a joint outside its position limits",
    PlanStatus.TCP_SPEED: "the executed motion moves the nozzle faster than the toolpath asks "
                          "(too little ink per mm)",
}


class Cause(StrEnum):
    """Why a waypoint has no pose, in terms of what the user can change."""

    BEND = "bend"
    DOWNWARD = "downward"
    REACH = "reach"
    WALL = "wall"
    GEL = "gel"
    OBSTACLE = "obstacle"


CAUSES: dict[Cause, str] = {
    Cause.BEND: "the path bends against its layer so sharply that no nozzle axis the cell "
                "can take there keeps alpha in range on both the arriving and the leaving step",
    Cause.DOWNWARD: "the printing direction points downward: the nozzle would have to come "
                    "from below the part",
    Cause.REACH: "the arm cannot take the pose (out of reach, a joint limit or a singularity)",
    Cause.WALL: "the tool or the arm hits a tank wall",
    Cause.GEL: "the tool body would enter the gel or hit the tank floor",
    Cause.OBSTACLE: "the arm or tool hits the cell (table, its own links)",
}

# what the user can change, per cause (the refusal adds what it checked)
FIXES: dict[Cause, str] = {
    Cause.BEND: "re-slice so the paths follow their layers there (another --layer-height or "
                "--edge-length, fewer --critical regions)",
    Cause.DOWNWARD: "re-slice with critical regions whose layers face up (e.g. without "
                    "--critical top) or turn the model over (its bottom facing down)",
    Cause.REACH: "move the tank closer to the robot or the robot base ([tank] "
                 "floor_center_mm, [robot] base_xyz_mm), or use a smaller model",
    Cause.WALL: "use a wider tank ([tank] inner_size_mm), a longer nozzle ([tool] "
                "nozzle_length_mm, tip_xyz_mm) or a smaller model",
    Cause.GEL: "lower the gel ([tank] gel_fill_mm), lift the model less ([placement] "
               "offset_mm) or use a longer nozzle ([tool] nozzle_length_mm, tip_xyz_mm)",
    Cause.OBSTACLE: "move the tank or the robot base ([tank] floor_center_mm, [robot] "
                    "base_xyz_mm)",
}


class Refused(InputError):
    """A job refused before motion: an ``InputError`` that also says why and where.

    Attributes:
        cause: the cause in the user's terms.
        waypoint: the first toolpath waypoint concerned (-1 if none in particular).
    """

    def __init__(self, problem: str, fix: str, cause: Cause, waypoint: int = -1) -> None:
        super().__init__(problem, fix)
        self.cause = cause
        self.waypoint = waypoint


class TimingStatus(Status):
    """The time law's outcome (``planner.timing.Timing.status``, report.json ``time_law``).

    A failure's text adds how many passes were made (``"<value> after N passes"``).
    """

    OK = "ok", "every joint's acceleration keeps within its limit"
    ACCELERATION = ("acceleration limit not met",
                    "slowing down did not bring the joint accelerations within their limits")
