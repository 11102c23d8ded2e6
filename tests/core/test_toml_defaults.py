"""Every default of the job and cell dataclasses is defined once: in its defaults file."""

from __future__ import annotations

import ast
import inspect
from types import ModuleType

import pytest

import planner.cell
import slicer.config
from core.toml_defaults import frozen, table

CONFIG_MODULES = [slicer.config, planner.cell]


def literal_defaults(source: str) -> list[str]:
    """``Class.field = value`` of every field of a config section (a ``*Config`` dataclass)
    whose default is written as a literal (a number, string, bool or a tuple/list of them)
    instead of read from the defaults file."""

    def literal(node: ast.expr) -> bool:
        if isinstance(node, ast.Constant):
            return True
        if isinstance(node, ast.UnaryOp):
            return literal(node.operand)
        if isinstance(node, ast.BinOp):  # (360.0,) * 6
            return literal(node.left) and literal(node.right)
        if isinstance(node, (ast.Tuple, ast.List)):
            return all(literal(e) for e in node.elts)
        return False

    found = []
    for cls in ast.walk(ast.parse(source)):
        if not isinstance(cls, ast.ClassDef) or not cls.name.endswith("Config"):
            continue
        if not any("dataclass" in ast.unparse(d) for d in cls.decorator_list):
            continue
        for stmt in cls.body:
            if (isinstance(stmt, ast.AnnAssign) and stmt.value is not None
                    and isinstance(stmt.target, ast.Name) and literal(stmt.value)):
                found.append(f"{cls.name}.{stmt.target.id} = {ast.unparse(stmt.value)}")
    return found


@pytest.mark.parametrize("module", CONFIG_MODULES, ids=lambda m: m.__name__)
def test_no_config_default_is_written_twice(module: ModuleType) -> None:
    twice = literal_defaults(inspect.getsource(module))
    assert not twice, f"{module.__name__} repeats defaults of its TOML file: {twice}"


def test_a_default_defined_twice_is_caught() -> None:
    source = '''
@dataclass(frozen=True)
class PlanningConfig:
    alpha_min_deg: float = _CELL["planning"]["alpha_min_deg"]
    lean_max_deg: float = 30.0
    joint_min_deg: tuple[float, ...] = (-360.0,) * 6
    parts: tuple = field(default_factory=tuple)
'''
    assert literal_defaults(source) == ["PlanningConfig.lean_max_deg = 30.0",
                                        "PlanningConfig.joint_min_deg = (-360.0,) * 6"]


def test_dataclass_defaults_are_the_files_defaults() -> None:
    assert slicer.config.JobConfig() == slicer.config.load_job()
    assert planner.cell.CellConfig() == planner.cell.load_cell()
    assert planner.cell.PlanningConfig().lean_max_deg == table(
        "planner", "cells/default.toml", "planning")["lean_max_deg"]
    assert frozen({"a": [1, [2, 3]]}) == {"a": (1, (2, 3))}
