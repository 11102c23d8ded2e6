"""The node base class: a crashed thread fails the node, and a failed node still makes its
devices safe on the way out."""

from __future__ import annotations

from mesp_cell.bus.session import BusConfig
from mesp_cell.nodes.lifecycle import LifecycleNode
from mesp_cell.states import NodeState


class Device(LifecycleNode):
    """A node whose device records being made safe."""

    def __init__(self) -> None:
        super().__init__("device", BusConfig(), {})
        self.made_safe = 0

    def on_deactivate(self) -> None:
        self.made_safe += 1


def test_a_crashed_thread_fails_the_node() -> None:
    node = Device()
    node.state = NodeState.ACTIVE

    def poll() -> None:
        raise ZeroDivisionError("division by zero")

    node.spawn(poll, "poll").join(5.0)
    assert node.state == NodeState.FAILED
    assert node.failed == "thread poll crashed: ZeroDivisionError: division by zero"


def test_the_first_failure_is_kept() -> None:
    node = Device()
    node.state = NodeState.ACTIVE
    node.spawn(lambda: 1 / 0, "a").join(5.0)
    node.spawn(lambda: [][1], "b").join(5.0)
    assert node.failed.startswith("thread a crashed")


def test_a_thread_that_ends_normally_is_no_failure() -> None:
    node = Device()
    node.state = NodeState.ACTIVE
    node.spawn(lambda: None, "once").join(5.0)
    assert node.state == NodeState.ACTIVE and not node.failed


def test_a_failed_node_makes_its_devices_safe() -> None:
    node = Device()
    node.state = NodeState.FAILED
    node.deactivate()
    assert node.made_safe == 1 and node.state == NodeState.INACTIVE
    node.deactivate()  # once only
    assert node.made_safe == 1
