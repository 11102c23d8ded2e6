"""Where the printing direction turns fast along a path, the nozzle turns less: alpha's band used.

Why: the flange sits 460 mm up the nozzle axis, so every degree the axis turns sweeps the
flange 8 mm; where a layer wraps a tight curve (a lying tube's underside: the direction turns
40 deg over 4 mm) the flange sweeps centimetres per millimetre of path, the base and elbow
turn with it, and their acceleration bounds the nozzle's speed far below the toolpath's. The
process needs alpha (the angle between the nozzle and each depositing step) within
[alpha_min, alpha_max], not the nozzle on the normal: within that band the axis can keep
closer to a steady direction.

How: on every depositing run (samples from where deposition starts to where it stops) that
has a sample turning faster than RELIEF_DEG_PER_MM, the directions are relaxed: each pass
averages every direction with its neighbours on the run (weights 1 / step length), pulls it
back towards its printing direction by ATTRACTION, and projects it into what is allowed:
alpha against the leaving and the arriving depositing step within the band narrowed by
MARGIN_DEG on both sides, at most ``smooth_max_deg`` from the printing direction. A run
keeps its own directions where the result breaks the band anywhere, or where it does not
lower the run's largest turn acceleration (``turn_acceleration``: the band, where it binds,
can put a kink into a smooth turn). None is relaxed where the cell's ``smooth_length_mm``
is 0 (it follows the printing directions as they are). The orientation stage and the
verification check alpha on the result as on any printing direction.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from planner.cell import CellConfig
from planner.nozzle_axis import alpha_within, unit
from planner.samples import Samples
from planner.upright import turn_towards

RELIEF_DEG_PER_MM = 5.0  # runs with a direction turning faster than this are relaxed
ATTRACTION = 0.03  # pull back towards the printing direction per pass (sets the relaxation
# length: about sqrt(1 / ATTRACTION) samples)
PASSES = 150  # relaxation passes
MARGIN_DEG = 3.0  # the band kept inside [alpha_min, alpha_max] (left to the orientation stage)


def depositing_runs(extrude: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M,) int64 run number of each sample on a depositing run (its leaving or arriving
    step deposits), -1 elsewhere; (M - 1,) bool: the step k -> k + 1 deposits."""
    ex = np.asarray(extrude, dtype=bool)
    on = ex.copy()
    on[1:] |= ex[:-1]
    begin = on & ~np.r_[False, on[:-1]]
    run = np.where(on, np.cumsum(begin) - 1, -1)
    return run, ex[:-1]


def _project(a: np.ndarray, n: np.ndarray, leave: np.ndarray, use_leave: np.ndarray,
             arrive: np.ndarray, use_arrive: np.ndarray, d_lo: float, d_hi: float,
             max_rad: float) -> np.ndarray:
    """Directions ``a`` (K, 3) moved into the allowed set (module docstring): a . t within
    [d_lo, d_hi] for each step direction t used, at most ``max_rad`` from ``n``."""
    for t, use in ((leave, use_leave), (arrive, use_arrive)):
        d = np.einsum("ij,ij->i", a, t)
        a = unit(a + np.where(use, np.clip(d, d_lo, d_hi) - d, 0.0)[:, None] * t)
    dev = np.arccos(np.clip(np.einsum("ij,ij->i", a, n), -1.0, 1.0))
    return turn_towards(n, a, np.minimum(dev, max_rad))


def turn_acceleration(a: np.ndarray, tcp: np.ndarray, prv: np.ndarray, nxt: np.ndarray
                      ) -> np.ndarray:
    """|d^2 a / ds^2| (M,) rad/mm^2 of unit directions ``a`` (M, 3) along the samples at
    ``tcp`` (M, 3) mm, by the three-point difference over the neighbours ``prv``, ``nxt``
    (M,) (0 where a sample has not both). What the flange's acceleration grows with."""
    h1 = np.linalg.norm(tcp - tcp[prv], axis=1)
    h2 = np.linalg.norm(tcp[nxt] - tcp, axis=1)
    both = (h1 > 1e-3) & (h2 > 1e-3)
    h1, h2 = np.where(both, h1, 1.0), np.where(both, h2, 1.0)
    d2 = 2.0 * ((a[nxt] - a) / h2[:, None] - (a - a[prv]) / h1[:, None]) / (h1 + h2)[:, None]
    return np.where(both, np.linalg.norm(d2, axis=1), 0.0)


def relieve_turns(samples: Samples, cell: CellConfig) -> tuple[Samples, np.ndarray]:
    """``samples`` with fast turns of the printing direction relieved (module docstring),
    and how far each direction was turned, (M,) float64 rad."""
    n = samples.normal
    M = len(n)
    turn = np.zeros(M)
    pl = cell.planning
    max_rad = np.radians(pl.smooth_max_deg)
    run, deposits = depositing_runs(samples.extrude)
    if M < 3 or max_rad <= 0 or pl.smooth_length_mm <= 0:  # the cell turns no directions
        return samples, turn
    length = np.maximum(np.linalg.norm(np.diff(samples.tcp, axis=0), axis=1), 1e-3)
    rate = np.arccos(np.clip(np.einsum("ij,ij->i", n[1:], n[:-1]), -1.0, 1.0)) / length
    fast_step = deposits & (rate > np.radians(RELIEF_DEG_PER_MM))
    fast_runs = np.unique(run[:-1][fast_step])
    rows = np.flatnonzero(np.isin(run, fast_runs) & (run >= 0))
    if not len(rows):
        return samples, turn
    # neighbours on the same run (itself at a run's ends), weighted by 1 / step length
    k = np.arange(M)
    prv = np.where((k > 0) & (run == np.r_[-2, run[:-1]]), k - 1, k)
    nxt = np.where((k < M - 1) & (run == np.r_[run[1:], -2]), k + 1, k)
    w_p = np.where(prv < k, 1.0 / length[np.maximum(k - 1, 0)], 0.0)
    w_n = np.where(nxt > k, 1.0 / length[np.minimum(k, M - 2)], 0.0)
    # the axis is -a: alpha within [lo, hi] means a . t within [-cos lo, -cos hi]
    lo, hi = np.radians([pl.alpha_min_deg + MARGIN_DEG, pl.alpha_max_deg - MARGIN_DEG])
    d_lo, d_hi = -np.cos(lo), -np.cos(hi)
    leave, arrive = samples.tangent[rows], samples.arrive[rows]
    use_leave = samples.extrude[rows]
    use_arrive = np.linalg.norm(arrive, axis=1) > 0.5
    nr = n[rows]
    wp, wn = w_p[rows, None], w_n[rows, None]
    a = n.copy()
    for _ in range(PASSES):  # relaxation passes, each over all relaxed samples at once
        mean = (wp * a[prv[rows]] + wn * a[nxt[rows]]) / np.maximum(wp + wn, 1e-12)
        mean = np.where((wp + wn) > 0, mean, a[rows])
        a[rows] = _project(unit((1.0 - ATTRACTION) * mean + ATTRACTION * nr), nr, leave,
                           use_leave, arrive, use_arrive, d_lo, d_hi, max_rad)
    # a run keeps its own directions where the result breaks the band anywhere, or where it
    # does not lower the run's largest turn acceleration (the band, where it binds, can put
    # a kink into a turn that was smooth)
    ok = alpha_within(cell, -a[rows], leave, samples.extrude[rows], arrive)
    first = np.flatnonzero(np.r_[True, run[rows][1:] != run[rows][:-1]])
    broken = np.minimum.reduceat(ok.astype(np.int8), first) == 0
    before = np.maximum.reduceat(turn_acceleration(n, samples.tcp, prv, nxt)[rows], first)
    after = np.maximum.reduceat(turn_acceleration(a, samples.tcp, prv, nxt)[rows], first)
    undo = broken | (after >= before)
    keep = np.repeat(undo, np.diff(np.r_[first, len(rows)]))
    a[rows[keep]] = n[rows[keep]]
    turn = np.arccos(np.clip(np.einsum("ij,ij->i", a, n), -1.0, 1.0))
    return replace(samples, normal=a), turn
