"""The preview data: depositing waypoints thinned evenly, paths kept apart by nulls."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from mesp_cell.planned_ink import planned_ink
from mesp_cell.web.preview import toolpath_preview
from tests.mesp_cell import synthetic


def test_preview_keeps_path_ends_and_separates_paths(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no toolpath yet"):
        toolpath_preview(tmp_path)
    tp = synthetic.toolpath()
    n = tp.position.shape[0]
    ext = np.ones(n, bool)
    ext[5] = False  # a travel waypoint is not drawn
    tp = dataclasses.replace(tp, path=(np.arange(n) // 6).astype(np.int32), extrude=ext)
    tp.save(tmp_path)
    full = toolpath_preview(tmp_path)
    assert full["layers"] == 3
    assert len(full["x"]) == (n - 1) + (n // 6 - 1)  # every depositing point, a null per path
    assert full["x"].count(None) == n // 6 - 1 == full["layer"].count(None)
    thin = toolpath_preview(tmp_path, max_points=12)
    pts = [v for v in thin["x"] if v is not None]
    assert 12 <= len(pts) < n - 1 and thin["x"][0] == full["x"][0]
    assert thin["x"][-1] == full["x"][-1]


def test_planned_ink_is_width_times_height_times_length(tmp_path: Path) -> None:
    pos = np.array([[0.0, 0, 0], [10, 0, 0], [10, 5, 0], [20, 5, 0]])
    tp = dataclasses.replace(
        synthetic.toolpath(), position=pos, normal=np.tile([0.0, 0, 1], (4, 1)),
        layer=np.zeros(4, np.int32), path=np.array([0, 0, 0, 1], np.int32),
        height=np.full(4, 0.5), width=np.full(4, 2.0), speed=np.full(4, 9.0),
        extrude=np.ones(4, bool), pattern=np.zeros(4, np.int8))
    tp.save(tmp_path)
    assert planned_ink(tmp_path) == pytest.approx((10 + 5) * 2.0 * 0.5)  # not the jump to path 1
