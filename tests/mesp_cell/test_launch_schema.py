"""The launch file's values: endpoints, numbers, lists, each refused by name."""

from __future__ import annotations

import math

import pytest

from core.errors import InputError
from mesp_cell import launch_schema as check


def test_endpoints_need_a_port_in_range() -> None:
    assert check.endpoint("tcp/127.0.0.1:7447", "hub") == "tcp/127.0.0.1:7447"
    assert check.endpoint("tcp/127.0.0.1:auto", "hub", auto=True).endswith("auto")
    assert check.endpoints(["tcp/[::1]:1", "udp/host-a.lan:65535"], "connect")
    for bad in ("tcp/127.0.0.1:99999", "tcp/127.0.0.1:0", "tcp/127.0.0.1:auto", "nonsense", 5):
        with pytest.raises(InputError, match="hub"):
            check.endpoint(bad, "hub")


@pytest.mark.parametrize("value", ["soon", math.nan, math.inf, -1.0, 1e9, True])
def test_numbers_are_finite_and_bounded(value: object) -> None:
    with pytest.raises(InputError, match="heartbeat_timeout"):
        check.number(value, "heartbeat_timeout", check.HEARTBEAT_TIMEOUT_S)
    assert check.number(2, "max_restarts", check.MAX_RESTARTS, whole=True) == 2.0
    with pytest.raises(InputError, match="whole"):
        check.number(2.5, "max_restarts", check.MAX_RESTARTS, whole=True)


def test_lists_tables_and_modules() -> None:
    assert check.arguments(["--port", 5, 1.5], "args") == ("--port", "5", "1.5")
    assert check.module("mesp_cell.nodes.robot_node", "module")
    for call in (lambda: check.arguments(5, "args"), lambda: check.arguments([True], "args"),
                 lambda: check.table("x", "params"), lambda: check.module("a b", "module"),
                 lambda: check.flag("yes", "critical"), lambda: check.string(3, "ready")):
        with pytest.raises(InputError):
            call()
