"""Shared fixtures: the default cell, small synthetic toolpaths and their plans."""

from __future__ import annotations

import pytest

from core.stages import Toolpath
from planner.cell import CellConfig, load_cell
from planner.plan import PlanResult, plan
from tests.planner import synthetic


@pytest.fixture(scope="session")
def cell() -> CellConfig:
    return load_cell()


@pytest.fixture(scope="session")
def lines_tp() -> Toolpath:
    return synthetic.lines(n_lines=3, length=30.0)


@pytest.fixture(scope="session")
def spiral_tp() -> Toolpath:
    return synthetic.spiral(turns=2.0, radius=20.0, height=4.0)


@pytest.fixture(scope="session")
def dome_tp() -> Toolpath:
    return synthetic.dome(radius=30.0, cap=6.0, rings=3, step=1.0)


@pytest.fixture(scope="session")
def dome_plan(dome_tp: Toolpath, cell: CellConfig) -> PlanResult:
    return plan(dome_tp, cell)


@pytest.fixture(scope="session")
def lines_plan(lines_tp: Toolpath, cell: CellConfig) -> PlanResult:
    return plan(lines_tp, cell)
