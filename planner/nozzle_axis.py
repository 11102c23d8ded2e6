"""The nozzle axis of a sample and its printing angle alpha: geometry shared by every planner stage.

The axis (tool z, out of the tip) is ``-normal`` turned by a *tilt* (in the plane of normal and
motion, changes alpha) and a *lean* (about the motion, keeps alpha); alpha is the angle between
the axis and the direction of motion and must stay within [alpha_min, alpha_max] on every
depositing step. Vectors are unit rows in the base frame, angles rad.
"""

from __future__ import annotations

import numpy as np

from core.tolerance import tol
from planner.cell import CellConfig

ALPHA_MIN_STEP_MM = 0.1  # a depositing step shorter than this lays a dot, not a filament:
# its direction (noise of the map-back at that length) does not constrain alpha


def unit(v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` (..., 3) normalised (zero rows stay zero)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > tol.zero, n, 1.0)


def any_perpendicular(n: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each unit row of ``n`` (..., 3)."""
    ref = np.where(np.abs(n[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    return unit(np.cross(n, ref))


def nozzle_axis(normal: np.ndarray, tangent: np.ndarray, tilt: np.ndarray,
                lean: np.ndarray | None = None) -> np.ndarray:
    """Nozzle axis (N, 3) unit: ``-normal`` tilted by ``tilt`` and leaned by ``lean`` (N,) rad.

    With t the unit part of the tangent perpendicular to n and b = n x t:
    axis = -cos(tilt) cos(lean) n + sin(tilt) t + cos(tilt) sin(lean) b.
    The tilt turns the axis in the plane of the normal and the motion: alpha = alpha0 - tilt,
    alpha0 = angle(-n, t) (90 deg when the motion lies in the layer). The lean turns it about
    the motion direction and leaves alpha unchanged for motion in the layer. The deviation
    from ``-normal`` is arccos(cos(tilt) cos(lean)).
    """
    t = tangent - np.einsum("ni,ni->n", tangent, normal)[:, None] * normal
    bad = np.linalg.norm(t, axis=1) < tol.floor
    t = np.where(bad[:, None], any_perpendicular(normal), unit(t))
    ct = np.cos(tilt)[:, None]
    axis = -ct * normal + np.sin(tilt)[:, None] * t
    if lean is not None:
        b = np.cross(normal, t)
        axis = -ct * np.cos(lean)[:, None] * normal + np.sin(tilt)[:, None] * t \
            + ct * np.sin(lean)[:, None] * b
    return unit(axis)


def alpha_of(axis: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """Printing angle (N,) rad between nozzle axes and motion directions (N, 3)."""
    c = np.einsum("ni,ni->n", unit(axis), unit(tangent))
    return np.arccos(np.clip(c, -1.0, 1.0))


def tool_rotation(axis: np.ndarray, psi: np.ndarray) -> np.ndarray:
    """Tool orientations (N, 3, 3): z = ``axis``, x from the base x axis turned by ``psi`` rad."""
    ref = np.where(np.abs(axis[:, :1]) < 0.95, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    x0 = unit(ref - np.einsum("ni,ni->n", ref, axis)[:, None] * axis)
    y0 = np.cross(axis, x0)
    c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
    x = c * x0 + s * y0
    y = -s * x0 + c * y0
    return np.stack([x, y, axis], axis=2)


def alpha_allowed(cell: CellConfig, alpha: np.ndarray, extrude: np.ndarray) -> np.ndarray:
    """(N,) bool: alpha (rad) is within the allowed range, or the sample does not extrude."""
    lo, hi = np.radians([cell.planning.alpha_min_deg, cell.planning.alpha_max_deg])
    return ~extrude | ((alpha >= lo - tol.slack) & (alpha <= hi + tol.slack))


def alpha_within(cell: CellConfig, axis: np.ndarray, leave: np.ndarray, extrude: np.ndarray,
                 arrive: np.ndarray | None) -> np.ndarray:
    """(N,) bool: nozzle ``axis`` (N, 3) keeps alpha within range against the step leaving
    each sample (``leave``, where ``extrude``) and the depositing step arriving at it
    (``arrive``: (N, 3), zero rows where none deposits; None: not checked)."""
    ok = alpha_allowed(cell, alpha_of(axis, leave), extrude)
    if arrive is not None:
        has = np.linalg.norm(arrive, axis=1) > 0.5
        ok &= alpha_allowed(cell, alpha_of(axis, arrive), has)
    return ok
