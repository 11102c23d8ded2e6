"""Who may send which command to which node: the bus obeys only the supervisor.

Each node kind has a table ``verb -> senders``. A sender is ``OPERATOR`` (a session signing as
the operator: ``mesp`` commands, the console), ``MEMBER`` (any session holding the cell's
secret), or the name of a node parameter naming a node (``"supervisor"`` -> the node's
``params["supervisor"]``, default ``"supervisor"``). A verb not in the table takes any member
(the node then refuses what it does not know). Resetting an e-stop is the operator's alone.
Arguments are checked after the sender (``command_checks``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from mesp_cell.bus.signing import Role, Signer
from mesp_cell.messages import Command

OPERATOR = "@operator"
MEMBER = "@member"

_MOTION = ("supervisor", OPERATOR)

#: Node class name -> verb -> who may send it.
POLICIES: dict[str, dict[str, tuple[str, ...]]] = {
    "RobotNode": {
        "load": _MOTION, "move": _MOTION, "stream": _MOTION, "stop": _MOTION,
        "reset": (OPERATOR,), "status": (MEMBER,),
    },
    "ExtruderNode": {
        "start": ("robot", *_MOTION), "set_rate": ("robot", *_MOTION),
        "stop": ("robot", *_MOTION), "clear": _MOTION, "reset": (OPERATOR,),
        "estop": (MEMBER,),
    },
    "SupervisorNode": {
        "pause": (OPERATOR,), "resume": (OPERATOR,), "abort": (OPERATOR,), "ready": (OPERATOR,),
    },
    "SlicerNode": {"slice": _MOTION},
    "PlannerNode": {"plan": _MOTION},
}


def allowed(node_class: str, verb: str) -> tuple[str, ...]:
    """Who may send ``verb`` to a node of class ``node_class``."""
    return POLICIES.get(node_class, {}).get(verb, (MEMBER,))


def sender_refusal(node_class: str, cmd: Command, signer: Signer | None,
                   params: Mapping[str, Any]) -> str:
    """'' if ``signer`` may send ``cmd`` to a node of ``node_class`` (with ``params``), else
    the one-line reason it may not."""
    if signer is None:
        return "the sender does not hold the cell's secret (an unauthenticated session)"
    who = allowed(node_class, cmd.verb)
    for tag in who:
        if tag == MEMBER:
            return ""
        if tag == OPERATOR and signer.role == Role.OPERATOR:
            return ""
        if tag not in (MEMBER, OPERATOR) and signer.role == Role.NODE \
                and signer.name == str(params.get(tag, tag)):
            return ""
    names = " or ".join("the operator" if t == OPERATOR else str(params.get(t, t))
                        for t in who)
    return f"{cmd.verb} is accepted only from {names}, not from {signer.role} {signer.name}"
