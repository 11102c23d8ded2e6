"""The suite's own scheduling rule (tests/conftest.py): files holding a slow test first."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import pytest

from tests.conftest import slow_files_first


@dataclass
class FakeItem:
    """What the rule reads of a collected test: its file and its markers."""

    path: Path
    name: str
    slow: bool = False

    def get_closest_marker(self, name: str) -> Any:
        return pytest.mark.slow.mark if name == "slow" and self.slow else None


def test_files_with_a_slow_test_come_first_whole_and_in_order() -> None:
    a, b, c = Path("a.py"), Path("b.py"), Path("c.py")
    items = [FakeItem(a, "a1"), FakeItem(b, "b1"), FakeItem(b, "b2", slow=True),
             FakeItem(b, "b3"), FakeItem(c, "c1"), FakeItem(c, "c2", slow=True)]
    slow_files_first(cast(list[pytest.Item], items))
    assert [i.name for i in items] == ["b1", "b2", "b3", "c1", "c2", "a1"]


def test_without_a_slow_test_the_order_stands() -> None:
    items = [FakeItem(Path(f"{n}.py"), n) for n in "zyx"]
    slow_files_first(cast(list[pytest.Item], items))
    assert [i.name for i in items] == ["z", "y", "x"]
