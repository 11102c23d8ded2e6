"""Clearance of the arm and the tool to the cell and to itself: analytic, vectorised.

The robot side is a set of capsules (segment + radius) fixed to DH bodies; the cell side is a
set of oriented boxes (table, tank floor, four walls, gel volume). Capsule-box distance uses the
convexity of the signed distance to a box along a segment (golden-section search, vectorised
over samples and pairs); capsule-capsule distance is the exact segment-segment distance.
Only the nozzle shaft may enter the gel. The same capsules build the MuJoCo twin
(``sim.cell_mjcf``), so planner and twin see one geometry. Units: m inside, like kinematics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner import kinematics as kin
from planner.cell import CellConfig

GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class Capsule:
    """A capsule fixed to a robot body.

    Attributes:
        name: label for reports ("upper_arm", "extruder", "nozzle", ...).
        body: int, 1..6 = DH body of joint i (frame i-1 rotated by q_i); 7 = flange (frame 6).
        p0, p1: (3,) float64, m, segment end points in the body frame.
        radius: float, m.
        tool: the capsule belongs to the tool (holder, extruder, nozzle).
    """

    name: str
    body: int
    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius: float
    tool: bool = False


@dataclass(frozen=True)
class Box:
    """An oriented box of the cell, in the robot base frame.

    Attributes:
        name: label for reports ("table", "tank_wall_+x", "gel", ...).
        center: (3,) float64, m.
        rotation: (3, 3) float64, columns are the box axes.
        half: (3,) float64, m, half extents.
    """

    name: str
    center: np.ndarray
    rotation: np.ndarray
    half: np.ndarray


LINK_NAMES = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
NOZZLE = "nozzle"


def robot_capsules(cell: CellConfig) -> list[Capsule]:
    """The arm links (along the DH geometry) and the tool parts as capsules.

    A box tool part becomes the capsule along its longest axis that encloses it; a cylinder
    the capsule on its axis with its radius; both err on the safe side.
    """
    r = np.asarray(cell.robot.link_radius_mm) / 1000.0
    d, a = kin.D, kin.A
    caps = [
        Capsule(LINK_NAMES[0], 1, (0.0, 0.0, 0.0), (0.0, 0.0, d[0]), r[0]),
        Capsule(LINK_NAMES[1], 2, (0.0, 0.0, 0.0), (a[1], 0.0, 0.0), r[1]),
        Capsule(LINK_NAMES[2], 3, (0.0, 0.0, 0.0), (a[2], 0.0, 0.0), r[2]),
        Capsule(LINK_NAMES[3], 4, (0.0, 0.0, 0.0), (0.0, 0.0, d[3]), r[3]),
        Capsule(LINK_NAMES[4], 5, (0.0, 0.0, 0.0), (0.0, 0.0, d[4]), r[4]),
        Capsule(LINK_NAMES[5], 6, (0.0, 0.0, 0.0), (0.0, 0.0, d[5]), r[5]),
    ]
    for part in cell.tool.parts:
        c = np.asarray(part.center_mm) / 1000.0
        s = np.asarray(part.size_mm) / 1000.0
        if part.shape == "cylinder":
            axis, radius = 2, s[0] / 2.0
        else:
            axis = int(np.argmax(s))
            others = [i for i in range(3) if i != axis]
            radius = 0.5 * float(np.hypot(s[others[0]], s[others[1]]))
        e = np.zeros(3)
        e[axis] = s[axis] / 2.0
        caps.append(Capsule(part.name, 7, tuple(c - e), tuple(c + e), float(radius), tool=True))
    tool_T = cell.tool.tool_T
    tip = tool_T[:3, 3] / 1000.0
    top = (tool_T @ np.array([0.0, 0.0, -cell.tool.nozzle_length_mm, 1.0]))[:3] / 1000.0
    caps.append(
        Capsule(NOZZLE, 7, tuple(tip), tuple(top), cell.tool.nozzle_diameter_mm / 2000.0, True)
    )
    return caps


PEDESTAL_MM = 180.0  # footprint of the pedestal under a raised robot base (UR5e base: 149 mm)


def cell_boxes(cell: CellConfig) -> list[Box]:
    """Table, robot pedestal (if the base stands above the table), tank floor, the four tank
    walls and the gel volume, in the robot base frame (m)."""
    base_inv = np.linalg.inv(cell.robot.base_T)
    out: list[Box] = []

    def add(name: str, T_cell: np.ndarray, center_local: np.ndarray, size: np.ndarray) -> None:
        T = base_inv @ T_cell
        center = (T @ np.append(center_local, 1.0))[:3] / 1000.0
        out.append(Box(name, center, T[:3, :3].copy(), np.asarray(size) / 2000.0))

    t = cell.table
    add("table", np.eye(4), np.asarray(t.center_mm), np.asarray(t.size_mm))
    table_top = t.center_mm[2] + t.size_mm[2] / 2
    base = np.asarray(cell.robot.base_xyz_mm, dtype=float)
    if base[2] > table_top + 1.0:
        # the robot stands on a pedestal from the table top up to its base
        h = base[2] - table_top
        add("pedestal", np.eye(4), np.array([base[0], base[1], table_top + h / 2]),
            np.array([PEDESTAL_MM, PEDESTAL_MM, h]))
    k = cell.tank
    F = k.floor_T
    ix, iy, ih = k.inner_size_mm
    w = k.wall_mm
    add("tank_floor", F, np.array([0.0, 0.0, -w / 2]), np.array([ix + 2 * w, iy + 2 * w, w]))
    add("tank_wall_+x", F, np.array([ix / 2 + w / 2, 0.0, ih / 2]), np.array([w, iy + 2 * w, ih]))
    add("tank_wall_-x", F, np.array([-ix / 2 - w / 2, 0.0, ih / 2]), np.array([w, iy + 2 * w, ih]))
    add("tank_wall_+y", F, np.array([0.0, iy / 2 + w / 2, ih / 2]), np.array([ix, w, ih]))
    add("tank_wall_-y", F, np.array([0.0, -iy / 2 - w / 2, ih / 2]), np.array([ix, w, ih]))
    g = k.gel_fill_mm
    add("gel", F, np.array([0.0, 0.0, g / 2]), np.array([ix, iy, g]))
    return out


def body_frames(q: np.ndarray) -> np.ndarray:
    """Body frames 1..7 in the base frame: (..., 6) rad -> (..., 7, 4, 4), m.

    Body i (1..6) is DH frame i-1 rotated by q_i (so link geometry is fixed in it); body 7 is
    the flange (frame 6).
    """
    F, bodies = kin.chain(q)
    out = np.empty((*np.shape(q)[:-1], 7, 4, 4))
    out[..., :6, :, :] = bodies
    out[..., 6, :, :] = F[..., 6, :, :]
    return out


def _box_sdf(points: np.ndarray, box: Box) -> np.ndarray:
    """Signed distance (m) of ``points`` (..., 3) to ``box`` (negative inside)."""
    local = np.abs((points - box.center) @ box.rotation) - box.half
    # explicit columns: numpy reductions over a length-3 last axis are slow
    dx, dy, dz = local[..., 0], local[..., 1], local[..., 2]
    ox, oy, oz = np.maximum(dx, 0.0), np.maximum(dy, 0.0), np.maximum(dz, 0.0)
    outside = np.sqrt(ox * ox + oy * oy + oz * oz)
    inside = np.minimum(np.maximum(np.maximum(dx, dy), dz), 0.0)
    return outside + inside


def segment_box_distance(p0: np.ndarray, p1: np.ndarray, box: Box, iters: int = 14) -> np.ndarray:
    """Min signed distance (m) from segments ``p0``-``p1`` (..., 3) to ``box``.

    The signed distance to a convex set is convex along a line, so a golden-section search
    brackets the minimum; ``iters`` sets the bracket to 0.618**iters of the segment length.
    """
    lo = np.zeros(p0.shape[:-1])
    hi = np.ones(p0.shape[:-1])
    d = p1 - p0
    x1 = hi - GOLDEN * (hi - lo)
    x2 = lo + GOLDEN * (hi - lo)
    f1 = _box_sdf(p0 + x1[..., None] * d, box)
    f2 = _box_sdf(p0 + x2[..., None] * d, box)
    for _ in range(iters):
        left = f1 < f2
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        new_x = np.where(left, hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo))
        f_new = _box_sdf(p0 + new_x[..., None] * d, box)
        x2, f2, x1, f1 = (
            np.where(left, x1, new_x),
            np.where(left, f1, f_new),
            np.where(left, new_x, x2),
            np.where(left, f_new, f2),
        )
    ends = np.minimum(_box_sdf(p0, box), _box_sdf(p1, box))
    return np.minimum(np.minimum(f1, f2), ends)


def segment_segment_distance(
    p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray
) -> np.ndarray:
    """Exact distance (m) between segments p0-p1 and q0-q1, all (..., 3)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = np.einsum("...i,...i->...", d1, d1)
    e = np.einsum("...i,...i->...", d2, d2)
    f = np.einsum("...i,...i->...", d2, r)
    c = np.einsum("...i,...i->...", d1, r)
    b = np.einsum("...i,...i->...", d1, d2)
    denom = a * e - b * b
    eps = 1e-18
    s = np.where(denom > eps, np.clip((b * f - c * e) / np.maximum(denom, eps), 0.0, 1.0), 0.0)
    t = (b * s + f) / np.maximum(e, eps)
    s = np.where(t < 0.0, np.clip(-c / np.maximum(a, eps), 0.0, 1.0), s)
    s = np.where(t > 1.0, np.clip((b - c) / np.maximum(a, eps), 0.0, 1.0), s)
    t = np.clip(t, 0.0, 1.0)
    diff = p0 + s[..., None] * d1 - (q0 + t[..., None] * d2)
    return np.linalg.norm(diff, axis=-1)


@dataclass(frozen=True)
class Clearance:
    """Clearances of many configurations.

    Attributes:
        distance: (S,) float64, mm, smallest distance over all checked pairs (negative =
            penetration).
        pair: (S,) int32, index into ``names`` of the closest pair.
        names: the checked pairs as "robot part vs obstacle".
    """

    distance: np.ndarray
    pair: np.ndarray
    names: tuple[str, ...]


class CollisionModel:
    """Capsules of the robot, boxes of the cell and the pairs to check between them."""

    def __init__(self, cell: CellConfig) -> None:
        self.capsules = robot_capsules(cell)
        self.boxes = cell_boxes(cell)
        self.env_pairs: list[tuple[int, int]] = []
        for ci, cap in enumerate(self.capsules):
            for bi, box in enumerate(self.boxes):
                if cap.name == LINK_NAMES[0] and box.name in ("table", "pedestal"):
                    continue  # the base stands on the table or the pedestal
                if cap.name == NOZZLE and box.name in ("gel", "table"):
                    continue  # only the nozzle shaft may enter the gel
                self.env_pairs.append((ci, bi))
        index = {c.name: i for i, c in enumerate(self.capsules)}
        tool = [i for i, c in enumerate(self.capsules) if c.tool]
        self.self_pairs: list[tuple[int, int]] = []
        for link, others in (
            ("shoulder", ["wrist_1", "wrist_2", "wrist_3"]),
            ("upper_arm", ["wrist_2", "wrist_3"]),
        ):
            for o in others:
                self.self_pairs.append((index[link], index[o]))
        for link in ("shoulder", "upper_arm", "forearm"):
            for ti in tool:
                self.self_pairs.append((index[link], ti))
        self.names = tuple(
            [f"{self.capsules[c].name} vs {self.boxes[b].name}" for c, b in self.env_pairs]
            + [f"{self.capsules[a].name} vs {self.capsules[b].name}" for a, b in self.self_pairs]
        )
        self._p0 = np.array([c.p0 for c in self.capsules])
        self._p1 = np.array([c.p1 for c in self.capsules])
        self._body = np.array([c.body for c in self.capsules]) - 1
        self._radius = np.array([c.radius for c in self.capsules])

    def segments(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Capsule end points in the base frame: (S, 6) rad -> two (S, C, 3) arrays, m."""
        B = body_frames(q)[:, self._body]  # (S, C, 4, 4)
        R, t = B[..., :3, :3], B[..., :3, 3]
        a = np.einsum("scij,cj->sci", R, self._p0) + t
        b = np.einsum("scij,cj->sci", R, self._p1) + t
        return a, b

    def clearance(self, q: np.ndarray, iters: int = 14, chunk: int = 20000) -> Clearance:
        """Smallest clearance (mm) of each configuration ``q`` (S, 6) rad over all pairs."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        S = len(q)
        dist = np.empty(S)
        pair = np.empty(S, dtype=np.int32)
        for start in range(0, S, chunk):
            qs = q[start : start + chunk]
            a, b = self.segments(qs)
            # a 1-Lipschitz bound from each capsule's midpoint prunes the far pairs: only
            # pairs whose lower bound beats the best upper bound get the golden search
            mid = 0.5 * (a + b)
            half_len = 0.5 * np.sqrt(np.einsum("sci,sci->sc", b - a, b - a))
            ub = np.empty((len(qs), len(self.env_pairs)))
            lb = np.empty_like(ub)
            for k, (ci, bi) in enumerate(self.env_pairs):
                centre = _box_sdf(mid[:, ci], self.boxes[bi]) - self._radius[ci]
                ub[:, k] = centre
                lb[:, k] = centre - half_len[:, ci]
            best = ub.min(axis=1)
            cols = []
            for k, (ci, bi) in enumerate(self.env_pairs):
                col = np.full(len(qs), np.inf)
                need = np.flatnonzero(lb[:, k] < best)
                if len(need):
                    d = segment_box_distance(a[need, ci], b[need, ci], self.boxes[bi], iters)
                    col[need] = d - self._radius[ci]
                cols.append(col)
            if self.self_pairs:
                i = np.array([p[0] for p in self.self_pairs])
                j = np.array([p[1] for p in self.self_pairs])
                dd = segment_segment_distance(a[:, i], b[:, i], a[:, j], b[:, j])
                dd = dd - self._radius[i] - self._radius[j]
                cols.extend(dd.T)
            D = np.stack(cols, axis=1)
            k = np.argmin(D, axis=1)
            dist[start : start + chunk] = D[np.arange(len(qs)), k] * 1000.0
            pair[start : start + chunk] = k
        return Clearance(dist, pair, self.names)
