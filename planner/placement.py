"""Where the model sits in the tank: position and rotation about z with the best clearance.

The model frame is placed by its bounding-box bottom centre at ``offset`` (x, y, lift) from
the tank's inner floor centre, rotated by ``yaw`` about z. A coarse search (yaw first, then
a position grid) scores placements on a subsample of waypoints by (unreachable waypoints,
smallest best-spin clearance); a refinement halves the steps around the winner; the best few
and the tank centre are re-scored on a larger sample, the centre winning ties in reach. A placement
that leaves part of the job unreachable is refused with an ``InputError``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from core.errors import InputError
from core.stages import Toolpath
from core.tolerance import tol
from planner.cell import CellConfig, pose
from planner.nozzle_axis import alpha_of, alpha_within, nozzle_axis, tool_rotation
from planner.orientation import orientation_levels
from planner.reach import ALPHA, COLLISION, OK, Reach
from planner.refusal import Bends, Steps, bends, cause_of, downward, waypoint_steps
from planner.samples import waypoint_tangents
from planner.status import CAUSES, FIXES, Cause, Refused


@dataclass(frozen=True)
class Placement:
    """A model placement and its score.

    Attributes:
        model_T: (4, 4) float64, mm, model frame -> robot base frame.
        offset_mm: (3,) bounding-box bottom centre from the inner floor centre (x, y, lift).
        yaw_deg: rotation about z, deg.
        unreachable: sampled waypoints no spin reaches at any allowed alpha.
        clearance_mm: clearance score (see ``score``), mm.
        evaluated: how many placements were scored.
        worst_reason: reason code of the first unreachable sampled waypoint (0 if none;
            100 + pair index for a collision).
        worst_waypoint: its toolpath index (-1 if none).
        alternatives: other placements the search found reaching every sampled waypoint, the
            yaws far apart first (see ``_alternatives``): (x, y, yaw_deg, clearance_mm).
            The planner tries them where the entry or exit is blocked at this one.
        checked: waypoints each placement was scored on (the last, larger sample).
        need_tilt: waypoints whose printing direction does not keep alpha on both steps
            (all of them up to ``TILT_SAMPLES`` are among the checked).
    """

    model_T: np.ndarray
    offset_mm: tuple[float, float, float]
    yaw_deg: float
    unreachable: int
    clearance_mm: float
    evaluated: int
    worst_reason: int
    worst_waypoint: int
    alternatives: tuple[tuple[float, float, float, float], ...] = ()
    checked: int = 0
    need_tilt: int = 0


def bbox(toolpath: Toolpath) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box (lo, hi), each (3,) mm, of the waypoints in the model frame."""
    return toolpath.position.min(axis=0), toolpath.position.max(axis=0)


def model_transform(cell: CellConfig, box: tuple[np.ndarray, np.ndarray], offset: np.ndarray,
                    yaw_deg: float) -> np.ndarray:
    """Model frame -> robot base frame (4, 4) mm for a placement (see module docstring).

    ``box`` is the toolpath's bounding box from ``bbox``.
    """
    lo, hi = box
    centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    recentre = np.eye(4)
    recentre[:3, 3] = -centre
    return cell.tank_in_base @ pose(tuple(offset), (0.0, 0.0, yaw_deg)) @ recentre


def _fits(cell: CellConfig, box: tuple[np.ndarray, np.ndarray], offset: np.ndarray,
          yaw_deg: float) -> bool:
    """The rotated bounding box stays ``wall_margin_mm`` inside the tank walls."""
    lo, hi = box
    hx, hy = (hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2
    c, s = abs(np.cos(np.radians(yaw_deg))), abs(np.sin(np.radians(yaw_deg)))
    ex, ey = c * hx + s * hy, s * hx + c * hy
    m = cell.placement.wall_margin_mm
    ix, iy, _ = cell.tank.inner_size_mm
    return bool(abs(offset[0]) + ex <= ix / 2 - m + tol.slack and abs(offset[1]) + ey <= iy / 2 - m
                + tol.slack)


def fit_gel(cell: CellConfig, toolpath: Toolpath) -> CellConfig:
    """The cell with the gel filled to ``gel_cover_mm`` above the part's top (``fit_gel``),
    never above ``gel_fill_mm``; the cell unchanged without ``fit_gel``."""
    tank = cell.tank
    if not tank.fit_gel or not len(toolpath):
        return cell
    lo, hi = bbox(toolpath)
    top = cell.placement.offset_mm[2] + float(hi[2] - lo[2])
    level = min(tank.gel_fill_mm, top + tank.gel_cover_mm)
    if level >= tank.gel_fill_mm or level <= 0:
        return cell
    return replace(cell, tank=replace(tank, gel_fill_mm=level))


def _tangents(toolpath: Toolpath, idx: np.ndarray) -> np.ndarray:
    """Waypoint tangents at ``idx`` only (neighbours within the same path)."""
    lo = np.maximum(idx - 1, 0)
    hi = np.minimum(idx + 1, len(toolpath) - 1)
    window = np.unique(np.concatenate([lo, idx, hi]))
    t = waypoint_tangents(toolpath.position[window], toolpath.path[window])
    return t[np.searchsorted(window, idx)]


SCORE_BATCH = 4096  # poses per check when scoring the levels beyond -normal


class LevelReach(NamedTuple):
    """How sampled waypoints are reached (``reach_levels``).

    Attributes:
        level: (S,) int64, index of the first orientation level (0: along -normal) at which
            some spin reaches the waypoint; -1 if none does.
        best: (S,) float64, mm, best-spin clearance at that level (-inf if unreachable;
            -1e9 where reached without a clearance value).
        first_status: (S,) int64, most frequent failure reason over the spins at level 0 of
            an unreachable waypoint (0 elsewhere).
        first_pair: (S,) int64, a collision pair index seen at level 0 there (-1 if none).
    """

    level: np.ndarray
    best: np.ndarray
    first_status: np.ndarray
    first_pair: np.ndarray


def reach_levels(reach: Reach, p: np.ndarray, n: np.ndarray, t: np.ndarray,
                 extrude: np.ndarray, spins: int = 8, tilt_step_deg: float = 10.0,
                 lean_step_deg: float = 20.0, arrive: np.ndarray | None = None) -> LevelReach:
    """The first orientation level (and its best-spin clearance) reaching each waypoint.

    Args:
        p: (S, 3) float64, mm, nozzle tips in the base frame. n, t: (S, 3) float64, unit
            normals and motion directions (the leaving step) in the base frame.
            extrude: (S,) bool.
        spins: rotations about the nozzle axis tried per level.
        arrive: (S, 3) float64, unit direction of the depositing step arriving at each
            waypoint (zero rows where none): alpha is checked against both steps, as the
            orientation stage does. None: only ``t``.
    """
    S = len(p)
    grid = np.linspace(-np.pi, np.pi, spins, endpoint=False)
    best = np.full(S, -np.inf)
    level = np.full(S, -1, dtype=np.int64)
    first_status = np.zeros(S, dtype=np.int64)
    first_pair = np.full(S, -1, dtype=np.int64)
    levels = orientation_levels(reach.cell, alpha_of(-n, t), tilt_step_deg, lean_step_deg)
    li, grow = 0, 1
    while li < len(levels):  # a loop over blocks of orientation levels
        rows = np.flatnonzero(level < 0)
        if not len(rows):
            break
        # level 0 (along -normal) for every waypoint; then the few that fail try the other
        # levels in blocks that double in size (one check per level would cost mostly call
        # overhead, one big block much work on waypoints an early level reaches)
        nb = int(min(grow, max(SCORE_BATCH // (len(rows) * spins), 1), len(levels) - li))
        grow = 2 * nb if li else 1
        block = levels[li:li + nb]
        rr = np.repeat(rows, nb)  # (len(rows) * nb,): waypoint of each (waypoint, level)
        ax = nozzle_axis(n[rr], t[rr], np.tile(block[:, 0], len(rows)),
                         np.tile(block[:, 1], len(rows)))
        R = tool_rotation(np.repeat(ax, spins, axis=0), np.tile(grid, len(rr)))
        q = reach.solve(np.repeat(p[rr], spins, axis=0), R, reach.home)
        ev = reach.check(q, iters=8)
        st = ev.status.reshape(len(rr), spins)
        ok_alpha = alpha_within(reach.cell, ax, t[rr], extrude[rr],
                                None if arrive is None else arrive[rr])
        st = np.where(ok_alpha[:, None], st, np.int8(ALPHA))
        ok = st == OK
        clear = np.where(ok, np.nan_to_num(ev.clearance, nan=-1e9).reshape(len(rr), spins),
                         -np.inf)
        ok_level = ok.any(axis=1).reshape(len(rows), nb)
        good = ok_level.any(axis=1)
        first = np.argmax(ok_level, axis=1)  # the first level of the block that reaches
        best[rows] = clear.max(axis=1).reshape(len(rows), nb)[np.arange(len(rows)), first]
        level[rows[good]] = li + first[good]
        if li == 0:
            fail = st[~good]
            first_status[rows[~good]] = [np.bincount(f[f != OK]).argmax() for f in fail]
            pairs = ev.pair.reshape(len(rows), spins)[~good]
            first_pair[rows[~good]] = pairs.max(axis=1)
        li += nb
    return LevelReach(level, best, first_status, first_pair)


def score(reach: Reach, toolpath: Toolpath, model_T: np.ndarray, idx: np.ndarray,
          spins: int = 8, tilt_step_deg: float = 10.0,
          lean_step_deg: float = 20.0, steps: Steps | None = None
          ) -> tuple[int, float, int, int]:
    """(unreachable count, clearance score mm, first reason, first waypoint) of a placement.

    The clearance score is the smallest best-spin clearance over the sampled waypoints plus a
    tenth of the mean of their lowest quarter (each capped at 100 mm), so ties of the minimum
    (e.g. nozzle to floor, the same everywhere) are broken by the tight spots of the rest of
    the job; each waypoint that needs a tilt or a lean costs 2 mm. ``steps``: the depositing
    steps of every waypoint (``refusal.waypoint_steps``), alpha checked against both; None:
    the path's tangent only.
    """
    R_m = model_T[:3, :3]
    p = toolpath.position[idx] @ R_m.T + model_T[:3, 3]
    n = toolpath.normal[idx] @ R_m.T
    if steps is None:
        t, arrive, extrude = _tangents(toolpath, idx) @ R_m.T, None, toolpath.extrude[idx]
    else:
        t, arrive = steps.leave[idx] @ R_m.T, steps.arrive[idx] @ R_m.T
        extrude = steps.extrude[idx]
    lv = reach_levels(reach, p, n, t, extrude, spins, tilt_step_deg, lean_step_deg, arrive)
    best, first_status, first_pair = lv.best, lv.first_status, lv.first_pair
    reach_ok = lv.level >= 0
    tilted = int((lv.level > 0).sum())
    unreachable = int((~reach_ok).sum())
    first_reason, first_wp = 0, -1
    if unreachable:
        i = int(np.flatnonzero(~reach_ok)[0])
        first_reason = int(first_status[i])
        first_wp = int(idx[i])
        if first_reason == COLLISION and first_pair[i] >= 0:
            first_reason = 100 + int(first_pair[i])
    # tilted or leaned waypoints count as a lost 2 mm of clearance each: prefer placements
    # where the nozzle follows -normal
    if reach_ok.any():
        b = np.sort(np.minimum(best[reach_ok], 100.0))
        value = float(b[0] + 0.1 * b[: max(1, len(b) // 4)].mean()) - 2.0 * tilted
    else:
        value = -np.inf
    return unreachable, value, first_reason, first_wp


TILT_SAMPLES = 256  # at most this many waypoints that need a tilt join the search's sample


def _where(toolpath: Toolpath, i: int) -> str:
    """'waypoint I (layer L, at x, y, z mm)' for messages."""
    x, y, z = (float(c) for c in toolpath.position[i])
    return f"waypoint {i} (layer {int(toolpath.layer[i])}, at {x:.1f}, {y:.1f}, {z:.1f} mm)"


def bend_refusal(toolpath: Toolpath, cell: CellConfig, found: Bends, also: str = "",
                 also_fix: str = "") -> Refused:
    """The refusal of a job with waypoints no nozzle axis serves (``refusal.bends``): the
    first, its layer, the turn of its path, and the alpha range that would serve them all
    (checked by the same test); no placement or cell with this alpha range can help.
    ``also``: what else the placement search found (appended to the problem), ``also_fix``
    its fix (appended to the fix)."""
    i = int(found.waypoint[0])
    half = float(np.ceil(found.needed_deg.max()))
    pl = cell.planning
    cause = Cause.DOWNWARD if downward(toolpath.normal[i:i + 1], np.array([0.0, 0.0, 1.0]))[0] \
        else Cause.BEND
    turn = (f"; its path turns {found.turn_deg[0]:.0f} deg there" if found.turn_deg[0] > 0
            else "")
    wider = ""
    if half < 90.0:
        wider = (f", or a cell whose [planning] alpha range is at least [{90 - half:.0f}, "
                 f"{90 + half:.0f}] deg (checked: it serves all {len(found.waypoint)})")
    return Refused(
        f"{len(found.waypoint)} waypoints cannot be printed in any placement, the first "
        f"{_where(toolpath, i)}: {CAUSES[cause]} (with any tilt and lean the planner allows; "
        f"alpha range [{pl.alpha_min_deg:g}, {pl.alpha_max_deg:g}] deg{turn}){also}",
        FIXES[cause] + wider + (f"; for the rest, {also_fix}"
                                if also_fix and also_fix != FIXES[cause] else ""), cause, i)


def choose_placement(reach: Reach, toolpath: Toolpath, samples: int = 32) -> Placement:
    """Search (or just check) the model placement; refuse one that leaves waypoints unreachable.

    Raises:
        InputError: the model does not fit in the tank or the gel, or no placement reaches
            the sampled waypoints.
    """
    cell = reach.cell
    pc = cell.placement
    box = bbox(toolpath)
    lo, hi = box
    height = hi[2] - lo[2]
    if pc.offset_mm[2] + height > cell.tank.gel_fill_mm:
        raise InputError(
            f"the model ({height:.1f} mm tall, lifted {pc.offset_mm[2]:.1f} mm) rises above the "
            f"gel surface ({cell.tank.gel_fill_mm:.1f} mm)",
            "raise [tank] gel_fill_mm or lower [placement] offset_mm[2] in the cell TOML",
        )
    steps = waypoint_steps(toolpath, cell)
    # waypoints no axis serves are refused whatever the placement; the search goes on without
    # them, so the refusal also says what else stands in the way
    found = bends(toolpath, cell, steps)
    if len(found.waypoint):
        served = steps.extrude.copy()
        served[found.waypoint] = False
        arrive = steps.arrive.copy()
        arrive[found.waypoint] = 0.0  # neither step of a bent waypoint is asked for alpha
        steps = steps._replace(extrude=served, arrive=arrive)
    N = len(toolpath)
    idx = np.unique(np.linspace(0, N - 1, min(N, samples)).round().astype(int))
    # every waypoint the printing direction alone does not serve (a bend against the layer):
    # it needs a tilt, which the walls or the reach may forbid at one placement only
    tilted = np.flatnonzero(~alpha_within(cell, -toolpath.normal, steps.leave, steps.extrude,
                                          steps.arrive))
    need_tilt = len(tilted)
    if len(tilted) > TILT_SAMPLES:
        tilted = tilted[np.linspace(0, len(tilted) - 1, TILT_SAMPLES).round().astype(int)]
    # where reach and walls bite first: the extreme waypoints in eight horizontal directions
    # (and up and down), and the waypoints whose normals lean furthest, weighted by how far
    # out they lie in the direction they lean
    ang = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
    dirs = np.stack([np.cos(ang), np.sin(ang), np.zeros(8)], axis=1)
    centre = 0.5 * (lo + hi)
    rel = toolpath.position - centre
    extremes = np.concatenate([
        np.argmax(rel @ dirs.T, axis=0),
        [int(np.argmin(rel[:, 2])), int(np.argmax(rel[:, 2]))],
        np.argmax((rel[:, :2] @ dirs[:, :2].T) * np.maximum(toolpath.normal[:, :2]
                                                            @ dirs[:, :2].T, 0.0), axis=0),
    ])
    lean = np.linalg.norm(toolpath.normal[:, :2], axis=1)
    steep = np.argsort(-lean)[: max(1, samples // 2)]
    idx = np.unique(np.concatenate([idx, extremes, steep, tilted]))
    lift = pc.offset_mm[2]
    evaluated = 0
    cache: dict[tuple[float, float, float], tuple[int, float, int, int]] = {}

    def key(x: float, y: float, yaw: float) -> tuple[int, float]:
        nonlocal evaluated
        k = (round(x, 6), round(y, 6), round(yaw % 360.0, 6))
        if k not in cache:
            evaluated += 1
            cache[k] = score(reach, toolpath, model_transform(cell, box,
                             np.array([x, y, lift]), yaw), idx, steps=steps)
        u, c, _, _ = cache[k]
        return (u, -c)

    x0, y0, yaw0 = pc.offset_mm[0], pc.offset_mm[1], pc.yaw_deg
    if not _fits(cell, box, np.array([x0, y0]), yaw0) and not pc.search:
        raise InputError(
            f"the model ({hi[0] - lo[0]:.0f} x {hi[1] - lo[1]:.0f} mm) at offset "
            f"({x0:.0f}, {y0:.0f}) mm does not fit inside the tank walls",
            "move [placement] offset_mm, enlarge [tank] inner_size_mm or enable search",
        )
    best = (x0, y0, yaw0)
    if pc.search:
        yaws = np.arange(0.0, 360.0, pc.search_yaw_step_deg) + yaw0
        cands = [(x0, y0, float(y)) for y in yaws if _fits(cell, box, np.array([x0, y0]), y)]
        if not cands:
            cands = [(0.0, 0.0, float(y)) for y in yaws
                     if _fits(cell, box, np.zeros(2), y)]
        if not cands:
            raise InputError(
                f"the model ({hi[0] - lo[0]:.0f} x {hi[1] - lo[1]:.0f} mm) does not fit inside "
                f"the tank ({cell.tank.inner_size_mm[0]:.0f} x {cell.tank.inner_size_mm[1]:.0f}"
                f" mm, margin {pc.wall_margin_mm:.0f} mm) at any rotation",
                "use a larger tank ([tank] inner_size_mm) or a smaller model",
            )
        best = min(cands, key=lambda c: key(*c))
        ix, iy, _ = cell.tank.inner_size_mm
        # at most 7 x 7 grid points over the tank floor
        step = max(pc.search_step_mm, ix / 6, iy / 6)
        xs = np.arange(-ix / 2, ix / 2 + tol.slack, step)
        ys = np.arange(-iy / 2, iy / 2 + tol.slack, step)
        grid = [(float(x), float(y), best[2]) for x in xs for y in ys
                if _fits(cell, box, np.array([x, y]), best[2])]
        if grid:
            best = min([*grid, best], key=lambda c: key(*c))
        # refine: half steps around the winner
        for scale in (0.5, 0.25):
            s, a = step * scale, pc.search_yaw_step_deg * scale
            near = [(best[0] + dx, best[1] + dy, best[2] + da)
                    for dx in (-s, 0.0, s) for dy in (-s, 0.0, s) for da in (-a, 0.0, a)]
            near = [c for c in near if _fits(cell, box, np.array(c[:2]), c[2])]
            best = min([*near, best], key=lambda c: key(*c))
    else:
        key(*best)
    u, c, reason, wp = cache[(round(best[0], 6), round(best[1], 6), round(best[2] % 360.0, 6))]
    if pc.search:
        # confirm on a larger sample (four times the steepest normals): the search samples
        # are few, so re-score its best few placements and the tank centre and keep the best
        ranked = sorted(cache.items(), key=lambda kv: (kv[1][0], -kv[1][1]))[:4]
        finalists = {k for k, _ in ranked}
        if _fits(cell, box, np.zeros(2), best[2]):
            finalists.add((0.0, 0.0, round(best[2] % 360.0, 6)))
        idx = np.unique(np.concatenate([
            np.linspace(0, N - 1, min(N, 4 * samples)).round().astype(int), extremes,
            np.argsort(-lean)[: 4 * samples], tilted]))
        confirmed = {k: score(reach, toolpath, model_transform(cell, box, np.array(
            [k[0], k[1], lift]), k[2]), idx, 12, 5.0, 10.0, steps) for k in sorted(finalists)}
        evaluated += len(confirmed)
        k_best = min(confirmed, key=lambda k: (confirmed[k][0], -confirmed[k][1]))
        centre = (0.0, 0.0, round(best[2] % 360.0, 6))
        if centre in confirmed and confirmed[centre][0] == confirmed[k_best][0]:
            # the score checks waypoints one by one; along the path, spin and tilt must also
            # change smoothly, which the centre (most room for the tool on every side)
            # allows best: it wins unless another placement reaches more sampled waypoints
            k_best = centre
        best = k_best
        u, c, reason, wp = confirmed[k_best]
    offset = (best[0], best[1], lift)
    if u:
        pair = reach.collision.names[reason - 100] if reason >= 100 else ""
        cause = cause_of(COLLISION if reason >= 100 else reason, pair, toolpath.normal[wp])
        yaw_list = sorted({k[2] for k in cache})
        tried = (f"tried {evaluated} placements (yaw {min(yaw_list):.0f} to "
                 f"{max(yaw_list):.0f} deg, x and y over the tank floor)" if pc.search
                 else "placement search is off")
        unreached = (f"at the best one (offset {best[0]:.0f}, {best[1]:.0f} mm, yaw "
                     f"{best[2]:.0f} deg) {u} of {len(idx)} checked waypoints are unreachable, "
                     f"the first {_where(toolpath, wp)}: {CAUSES[cause]}"
                     + (f" ({pair})" if pair else ""))
        if len(found.waypoint):
            raise bend_refusal(toolpath, cell, found, f"; besides, no placement reaches the "
                                                      f"rest ({tried}): {unreached}",
                               FIXES[cause])
        raise Refused(f"no reachable placement ({tried}): {unreached}", FIXES[cause], cause,
                      wp)
    if len(found.waypoint):
        raise bend_refusal(toolpath, cell, found, f" (the rest is reachable: {evaluated} "
                                                  "placements tried)")
    model_T = model_transform(cell, box, np.array(offset), best[2])
    return Placement(model_T, offset, float(best[2] % 360.0), u, c, evaluated, reason, wp,
                     _alternatives(cache, best), len(idx), need_tilt)


YAW_APART_DEG = 60.0  # alternatives whose yaws differ this much from each other come first


def _alternatives(cache: dict[tuple[float, float, float], tuple[int, float, int, int]],
                  best: tuple[float, float, float]
                  ) -> tuple[tuple[float, float, float, float], ...]:
    """Scored placements that reach every sampled waypoint, other than ``best``, as
    (x, y, yaw_deg, clearance_mm), by clearance (largest first); those whose yaw lies at
    least ``YAW_APART_DEG`` from ``best``'s and from every one taken before them come first
    (a blocked entry or exit depends on where the job starts and ends: turn it away)."""
    chosen = (round(best[0], 6), round(best[1], 6), round(best[2] % 360.0, 6))
    ok = sorted(((k, v[1]) for k, v in cache.items() if v[0] == 0 and k != chosen),
                key=lambda kv: -kv[1])
    yaws = [chosen[2]]
    first: list[tuple[float, float, float, float]] = []
    rest: list[tuple[float, float, float, float]] = []
    for k, c in ok:
        apart = all(abs((k[2] - y + 180.0) % 360.0 - 180.0) >= YAW_APART_DEG for y in yaws)
        (first if apart else rest).append((*k, c))
        if apart:
            yaws.append(k[2])
    return tuple(first + rest)
