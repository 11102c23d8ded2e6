"""The slicing scalar field of paper section 4.1: vector/scalar iteration with critical regions.

Unknowns: ``g`` is P1 on the tet vertices (its gradient constant per tet, ``TetOperators``);
all vertices of one critical region share one unknown (g constant on it, eq. 7; touching
regions share one), the gauge is fixed by pinning one unknown per connected part and
shifting g to min 0. The vector field ``v`` lives on tets; eq. 6 uses normalised weights
(``vol / mean(vol)``, ``area / mean(area)``) so the balance of w_l and w_h does not depend on
the mesh size or the units. Tets owning a region's boundary face are constrained to its
growth direction; a part without any region gets v = +z on its bottom tets.

Steps (each constant matrix set up once, ``slicer.solvers``):
    1. G0, the harmonic baseline ([42]): Laplace's equation with g fixed on each region to its
       mean height (the planar default completes parts it leaves flat,
       ``_harmonic_anchors``); its layer height is the baseline the result is measured
       against. G0 is uneven where the part extends beyond the regions, so the iteration
       starts from the harmonic *vector* field (eq. 6 without alignment) and its Poisson solve.
    2. v = argmin eq. 6 aligned with grad g / |grad g| (one matrix for the three components),
       renormalised to unit length per tet: a shortened v would mean a thicker layer.
    3. g = argmin sum vol |grad g - v|^2 (Poisson, eq. 8); stop when O_align changes by less
       than ``convergence`` or after ``max_iterations``.

The layer height each field implies, and its statistics: ``slicer.field_heights``. How the
choices above were measured: docs/benchmarks.md (field).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from core.progress import NullProgress, Progress
from core.stages import TetMesh
from core.tolerance import tol
from slicer.config import SlicingConfig
from slicer.critical import CriticalSelection, select_critical_regions
from slicer.field_heights import (
    HeightStats,
    height_std,
    layer_heights,
    stats_of_gradient,
)
from slicer.operators import TetOperators, build_operators
from slicer.solvers import SPDSolver

ALIGN_WEIGHT = 1.0  # w_l; config.smoothness_weight is w_h relative to it
NORMALISE_V = True
INITIAL_FIELD = "scalar"  # G0: "scalar" harmonic (Laplace, regions fixed) or "vector" (eq. 6)
HARMONIC_REGULARISATION = 1e-8  # tiny mass term keeping the pure-smoothness system SPD
# Relative residuals of the iterative solves: the iteration is a fixed point that corrects
# itself and v is renormalised after each solve (docs/benchmarks.md, field).
POISSON_RTOL = 1e-6
VECTOR_RTOL = 1e-5


class FieldTrace(NamedTuple):
    """Per-iteration history of the vector/scalar iteration.

    Attributes:
        o_align: tuple of float, mm^3, O_align = sum vol |grad g - v|^2 after each iteration.
        height_std: tuple of float, mm, layer-height std of G0, then after each iteration
            (one more entry than o_align).
    """

    o_align: tuple[float, ...]
    height_std: tuple[float, ...]


@dataclass(frozen=True, eq=False)
class FieldResult:
    """The slicing field and how it was obtained.

    Attributes:
        g: (V,) float64, final field (min 0), field units (~mm).
        g0: (V,) float64, initial harmonic field G0 (min 0).
        gradient: (T, 3) float64, per-tet gradient of g.
        delta: float, field units, iso-spacing giving the target mean layer height.
        layer_height_mm: float, mm, the target mean layer height the stats are scaled to.
        height: stats of the final field's layer height (mm).
        height_initial: stats of G0's layer height with the same target mean (mm).
        status: "converged" | "max_iterations" | "planar" | "no_iterations" |
            "solver_failed:<what>" (g is then the last good field).
        iterations: int, number of vector/scalar iterations done.
        trace: O_align and the layer-height std per iteration.
        timings: dict stage -> s.
        notes: tuple of str, remarks (dropped patches, solver fallbacks, ...).
        regions: the critical regions used.
        constrained: (T,) bool, tets whose v is fixed by a region (or the bottom default).
        operators: the mesh operators (reuse them for layer extraction).
    """

    g: np.ndarray
    g0: np.ndarray
    gradient: np.ndarray
    delta: float
    layer_height_mm: float
    height: HeightStats
    height_initial: HeightStats
    status: str
    iterations: int
    trace: FieldTrace
    timings: dict[str, float]
    notes: tuple[str, ...]
    regions: CriticalSelection
    constrained: np.ndarray
    operators: TetOperators = field(repr=False)
    height_start: HeightStats | None = None

    def report(self) -> dict[str, object]:
        """The field's part of report.json's "slicing" section (mm, s; JSON-ready)."""
        return {
            "status": self.status,
            "iterations": self.iterations,
            "critical_regions": len(self.regions.regions),
            "height_mm": self.height.as_dict(),
            "height_cv": self.height.cv,
            "height_std_initial_mm": self.height_initial.std,
            "height_initial_mm": self.height_initial.as_dict(),
            "height_std_start_mm": (self.height_start.std if self.height_start is not None
                                    else self.height_initial.std),
            "o_align": list(self.trace.o_align),
            "height_std_per_iteration_mm": list(self.trace.height_std),
            "field_timing_s": dict(self.timings),
            "notes": list(self.notes),
        }


def _unknown_map(n_vertices: int, selection: CriticalSelection) -> tuple[np.ndarray, int]:
    """(V,) int64 unknown index per vertex, regions collapsed; and the number of unknowns."""
    rows = [r.vertices for r in selection.regions]
    cols = [np.full(len(r.vertices), r.vertices[0]) for r in selection.regions]
    if rows:
        i, j = np.concatenate(rows), np.concatenate(cols)
    else:
        i = j = np.zeros(0, dtype=np.int64)
    graph = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n_vertices, n_vertices))
    count, labels = connected_components(graph, directed=False)
    return labels.astype(np.int64), int(count)


def _vertex_components(ops: TetOperators) -> np.ndarray:
    """(V,) int64 connected-part label per vertex (vertices connected through tets)."""
    _, comp = connected_components(ops.laplacian, directed=False)
    return comp.astype(np.int64)


def _mean_edge(ops: TetOperators) -> float:
    return float(np.linalg.norm(ops.vertices[ops.tets[:, 1]] - ops.vertices[ops.tets[:, 0]],
                                axis=1).mean())


def _part_extremes(values: np.ndarray, comp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-part min and max of a vertex quantity: ((P,), (P,))."""
    lo = np.full(int(comp.max()) + 1, np.inf)
    hi = np.full(len(lo), -np.inf)
    np.minimum.at(lo, comp, values)
    np.maximum.at(hi, comp, values)
    return lo, hi


def _constraints(ops: TetOperators, selection: CriticalSelection,
                 comp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Constrained tets and their fixed vectors: ((T,) bool, (T, 3) float64 unit).

    A connected part of the mesh without any region (the whole mesh when there is none, or
    a stray fragment of the mesher) gets the planar default: its bottom tets grow along +z.
    """
    n = ops.n_tets
    fixed = np.zeros((n, 3))
    if selection.regions:
        tets = np.concatenate([ops.boundary.tet[r.faces] for r in selection.regions])
        grow = np.concatenate([r.growth * ops.boundary.area[r.faces, None]
                               for r in selection.regions])
        np.add.at(fixed, tets, grow)
    tet_part = comp[ops.tets[:, 0]]
    has_region = np.zeros(int(comp.max()) + 1 if len(comp) else 0, dtype=bool)
    has_region[tet_part[np.linalg.norm(fixed, axis=1) > tol.zero]] = True
    bare = ~has_region[tet_part]
    if bare.any():
        # The layers start at the part's bottom, growing along +z.
        z = ops.vertices[:, 2]
        zmin, _ = _part_extremes(z, comp)
        bottom = bare & (z[ops.tets].min(axis=1) <= zmin[tet_part] + 0.5 * _mean_edge(ops))
        fixed[bottom] = (0.0, 0.0, 1.0)
    norm = np.linalg.norm(fixed, axis=1)
    constrained = norm > tol.zero
    fixed[constrained] /= norm[constrained, None]
    return constrained, fixed


class _Poisson:
    """Eq. 7/8 with collapsed region unknowns: min sum vol |grad g - v|^2, set up once."""

    def __init__(self, ops: TetOperators, labels: np.ndarray, count: int,
                 region_vertices: np.ndarray) -> None:
        self.ops = ops
        n_vertices = ops.n_vertices
        self.labels = labels
        self.collapse = sp.csr_matrix(
            (np.ones(n_vertices), (np.arange(n_vertices), labels)), shape=(n_vertices, count))
        lap = sp.csr_matrix(self.collapse.T @ ops.laplacian @ self.collapse)
        # One pinned unknown per connected component: region unknowns first, then lowest z.
        ncomp, comp = connected_components(lap, directed=False)
        key_region = np.ones(count)
        if len(region_vertices):
            key_region[labels[region_vertices]] = 0.0
        zmin = np.full(count, np.inf)
        np.minimum.at(zmin, labels, ops.vertices[:, 2])
        order = np.lexsort((zmin, key_region, comp))
        _, first = np.unique(comp[order], return_index=True)
        pinned = order[first]
        self.free = np.setdiff1d(np.arange(count), pinned)
        self.count = count
        self.components = int(ncomp)
        self.matrix = lap[self.free][:, self.free]
        self.solver = SPDSolver(self.matrix, method="auto", rtol=POISSON_RTOL)
        self._last: np.ndarray | None = None

    def solve(self, v: np.ndarray) -> tuple[np.ndarray, float, str]:
        """g (V,) with min 0, O_align, status for the target vector field v (T, 3)."""
        rhs = self.collapse.T @ self.ops.divergence(v)
        x, status = self.solver.solve(rhs[self.free], x0=self._last)
        if status.startswith("failed"):
            return np.full(self.ops.n_vertices, np.nan), float("nan"), status
        self._last = x
        u = np.zeros(self.count)
        u[self.free] = x
        g = u[self.labels]
        g = g - g.min()
        diff = self.ops.gradient(g) - v
        o_align = float((self.ops.volume * np.einsum("ij,ij->i", diff, diff)).sum())
        return g, o_align, status


def _harmonic_anchors(ops: TetOperators, selection: CriticalSelection, labels: np.ndarray,
                      comp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dirichlet data of the scalar harmonic G0: (unknown indices, values), both (k,).

    Each critical region's (collapsed) unknown gets the region's area-weighted mean height z.
    In a connected part where that leaves fewer than two distinct values (one region, or none)
    the field would be constant, so the planar default completes it: the part's boundary
    vertices within half an edge of its lowest z (when none of its regions is a start
    surface) and of its highest z (when none is an end surface) get g = z, i.e. layers start
    flat on the build plate / end flat at the top.
    """
    n_parts = int(comp.max()) + 1 if len(comp) else 0
    idx: list[np.ndarray] = []
    val: list[np.ndarray] = []
    part = np.zeros(len(selection.regions), dtype=np.int64)
    for k, r in enumerate(selection.regions):  # loop over regions, not faces
        area = ops.boundary.area[r.faces]
        zc = ops.vertices[ops.boundary.faces[r.faces], 2].mean(axis=1)
        idx.append(labels[r.vertices[:1]])
        val.append(np.array([float((zc * area).sum() / max(float(area.sum()), tol.zero))]))
        part[k] = comp[r.vertices[0]]
    values = np.concatenate(val) if val else np.zeros(0)
    signs = np.array([r.sign for r in selection.regions])
    lo_v, hi_v = np.full(n_parts, np.inf), np.full(n_parts, -np.inf)
    np.minimum.at(lo_v, part, values)
    np.maximum.at(hi_v, part, values)
    scale = max(1.0, float(np.abs(ops.vertices[:, 2]).max()))
    flat = ~(hi_v - lo_v > tol.zero * scale)  # also the parts without any region
    has_start = np.zeros(n_parts, dtype=bool)
    has_end = np.zeros(n_parts, dtype=bool)
    has_start[part[signs < 0]] = True
    has_end[part[signs > 0]] = True
    if flat.any():
        z = ops.vertices[:, 2]
        on_boundary = np.zeros(ops.n_vertices, dtype=bool)
        on_boundary[ops.boundary.faces.ravel()] = True
        zmin, zmax = _part_extremes(z, comp)
        half = 0.5 * _mean_edge(ops)
        base = on_boundary & (flat & ~has_start)[comp] & (z <= zmin[comp] + half)
        top = on_boundary & (flat & ~has_end)[comp] & (z >= zmax[comp] - half)
        extra = np.flatnonzero(base | top)
        idx.append(labels[extra])
        values = np.concatenate([values, z[extra]])
    unknowns = np.concatenate(idx) if idx else np.zeros(0, dtype=np.int64)
    # A vertex may be picked twice (an anchor on a region): keep its first value (the region's).
    unknowns, first = np.unique(unknowns, return_index=True)
    return unknowns, values[first]


class _ScalarHarmonic:
    """G0 of the harmonic constraint: Laplace with g fixed on the anchors, set up once."""

    def __init__(self, poisson: _Poisson, anchors: np.ndarray, values: np.ndarray) -> None:
        self.poisson = poisson
        lap = sp.csr_matrix(poisson.collapse.T @ poisson.ops.laplacian @ poisson.collapse)
        self.fixed = anchors
        self.values = values
        self.free = np.setdiff1d(np.arange(poisson.count), anchors)
        self.coupling = sp.csr_matrix(lap[self.free][:, anchors])
        self.solver = SPDSolver(lap[self.free][:, self.free], method="auto",
                                rtol=POISSON_RTOL)

    def solve(self) -> tuple[np.ndarray, str]:
        """g (V,) with min 0 and the solver status."""
        x, status = self.solver.solve(-(self.coupling @ self.values))
        if status.startswith("failed"):
            return np.full(self.poisson.ops.n_vertices, np.nan), status
        u = np.zeros(self.poisson.count)
        u[self.fixed] = self.values
        u[self.free] = x
        g = u[self.poisson.labels]
        return g - g.min(), status


def _normalised(vec: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Rows of ``vec`` scaled to unit length; ``fallback`` rows where a row is ~zero."""
    norm = np.sqrt(np.einsum("ij,ij->i", vec, vec))
    good = norm > tol.zero
    return np.where(good[:, None], vec / np.where(good, norm, 1.0)[:, None], fallback)



def planar_field(ops: TetOperators) -> np.ndarray:
    """The degenerate planar case (paper 5.1): g = z - min z, (V,) float64 mm."""
    z = ops.vertices[:, 2]
    return z - z.min()


def compute_field(
    mesh: TetMesh,
    config: SlicingConfig,
    progress: Progress | None = None,
    operators: TetOperators | None = None,
) -> FieldResult:
    """The slicing field of paper section 4.1 (or g = z for ``config.planar``).

    Args:
        mesh: the tet mesh.
        config: slicing settings (critical selectors, layer height, iterations, w_h, ...).
        progress: receives stage starts/ends and per-iteration progress.
        operators: prebuilt operators of ``mesh`` (built here if None).

    Returns:
        The field result; never raises for solver trouble (see ``status``).
    """
    # The Krylov solvers do many level-1 BLAS calls on ~1e5-long vectors: a multi-threaded
    # BLAS gains nothing there and, on a loaded 2-core machine, thread hand-offs made each
    # dot product ~30x slower (measured 3.2 ms vs 0.12 ms). One BLAS thread it is.
    with single_blas_thread():
        return _compute_field(mesh, config, progress, operators)


@contextmanager
def single_blas_thread() -> Iterator[None]:
    """Limit BLAS to one thread inside the block (no-op without threadpoolctl)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional: only a speed matter
        yield
        return
    with threadpool_limits(limits=1, user_api="blas"):
        yield


def _compute_field(
    mesh: TetMesh,
    config: SlicingConfig,
    progress: Progress | None,
    operators: TetOperators | None,
) -> FieldResult:
    prog: Progress = progress if progress is not None else NullProgress()
    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    notes: list[str] = []

    t = time.perf_counter()
    ops = operators if operators is not None else build_operators(mesh)
    timings["operators"] = time.perf_counter() - t
    if ops.flipped:
        notes.append(f"{ops.flipped} negatively oriented tets were reoriented")
    if ops.degenerate:
        notes.append(f"{ops.degenerate} degenerate (zero-volume) tets ignored")

    t = time.perf_counter()
    selection = select_critical_regions(ops, config.selectors)
    notes.extend(selection.notes)
    timings["regions"] = time.perf_counter() - t
    comp = _vertex_components(ops)
    constrained, fixed = _constraints(ops, selection, comp)
    target_h = config.layer_height_mm
    vol = ops.volume

    if config.planar:
        g = planar_field(ops)
        grad = ops.gradient(g)
        hs = stats_of_gradient(grad, vol, target_h)
        _, delta = layer_heights(grad, vol, target_h)
        timings["total"] = time.perf_counter() - t_start
        return FieldResult(g=g, g0=g.copy(), gradient=grad, delta=delta,
                           layer_height_mm=target_h, height=hs, height_initial=hs,
                           status="planar", iterations=0, trace=FieldTrace((), (hs.std,)),
                           timings=timings, notes=tuple(notes),
                           regions=selection, constrained=constrained, operators=ops)

    # --- set up the constant systems once ---------------------------------------------------
    prog.start("field setup")
    t = time.perf_counter()
    region_vertices = (np.concatenate([r.vertices for r in selection.regions])
                       if selection.regions else np.zeros(0, dtype=np.int64))
    labels, count = _unknown_map(ops.n_vertices, selection)
    poisson = _Poisson(ops, labels, count, region_vertices)
    if poisson.components > 1:
        notes.append(f"mesh has {poisson.components} connected parts; each gets its own gauge")

    free = np.flatnonzero(~constrained)
    cons = np.flatnonzero(constrained)
    mass = vol / max(float(vol.mean()), tol.zero)
    face_w = ops.face_area / max(float(ops.face_area.mean()), tol.zero)
    lf = ops.face_laplacian(face_w)
    lf_ff = sp.csr_matrix(lf[free][:, free])
    coupling = sp.csr_matrix(lf[free][:, cons]) @ fixed[cons]  # (F, 3)
    w_h, w_l = config.smoothness_weight, ALIGN_WEIGHT
    harmonic = SPDSolver(w_h * lf_ff + sp.diags(HARMONIC_REGULARISATION * mass[free]),
                         method="amg", rtol=1e-6)
    vector = SPDSolver(w_l * sp.diags(mass[free]) + w_h * lf_ff, method="cg", rtol=VECTOR_RTOL)
    for name, s in (("poisson", poisson.solver), ("harmonic", harmonic), ("vector", vector)):
        if s.status != "ok":
            notes.append(f"{name} solver: {s.status}")
    timings["setup"] = time.perf_counter() - t
    prog.end("field setup", timings["setup"])

    # --- step 1: the harmonic initial field G0 ----------------------------------------------
    prog.start("initial field")
    t = time.perf_counter()
    v = fixed.copy()
    vf, st_h = harmonic.solve(-w_h * coupling)
    v[free] = vf
    g_start, _, st_p = poisson.solve(v)
    st_s = "ok"
    if INITIAL_FIELD == "scalar":
        scalar = _ScalarHarmonic(poisson, *_harmonic_anchors(ops, selection, labels, comp))
        g0, st_s = scalar.solve()
        if scalar.solver.status != "ok":
            notes.append(f"scalar harmonic solver: {scalar.solver.status}")
    else:
        g0 = g_start
    timings["initial"] = time.perf_counter() - t
    prog.end("initial field", timings["initial"])
    failed = next((s for s in (st_h, st_p, st_s) if s.startswith("failed")), "")
    if failed or not np.all(np.isfinite(g0)) or not np.all(np.isfinite(g_start)):
        nan = np.full(ops.n_vertices, np.nan)
        hs = HeightStats(*(float("nan"),) * 6)
        timings["total"] = time.perf_counter() - t_start
        return FieldResult(g=nan, g0=nan, gradient=np.full((ops.n_tets, 3), np.nan),
                           delta=float("nan"), layer_height_mm=target_h, height=hs,
                           height_initial=hs,
                           status=f"solver_failed:initial:{failed or 'non-finite'}",
                           iterations=0, trace=FieldTrace((), ()), timings=timings,
                           notes=tuple(notes), regions=selection, constrained=constrained,
                           operators=ops)
    grad0 = ops.gradient(g0)
    hs0 = stats_of_gradient(grad0, vol, target_h)
    grad_start = ops.gradient(g_start)
    hs_start = stats_of_gradient(grad_start, vol, target_h)

    # --- steps 2 and 3, iterated ------------------------------------------------------------
    prog.start("field iterations")
    t = time.perf_counter()
    g, grad = g_start, grad_start
    o_trace: list[float] = []
    std_trace = [hs0.std]
    status = "no_iterations" if config.max_iterations == 0 else "max_iterations"
    iterations = 0
    prev_vf: np.ndarray | None = None
    unconverged = 0
    for it in range(config.max_iterations):
        target = _normalised(grad, v)
        rhs = w_l * mass[free, None] * target[free] - w_h * coupling
        vf, st_v = vector.solve(rhs, x0=prev_vf)
        if st_v.startswith("failed"):
            status = f"solver_failed:vector:{st_v}"
            break
        prev_vf = vf
        v_new = fixed.copy()
        v_new[free] = _normalised(vf, target[free]) if NORMALISE_V else vf
        g_new, o_align, st_p = poisson.solve(v_new)
        if st_p.startswith("failed") or not np.all(np.isfinite(g_new)):
            status = f"solver_failed:poisson:{st_p}"
            break
        unconverged += (st_v != "ok") + (st_p != "ok")
        v, g = v_new, g_new
        grad = ops.gradient(g)
        iterations = it + 1
        o_trace.append(o_align)
        std_trace.append(height_std(grad, vol, target_h))
        prog.update(iterations / config.max_iterations, f"O_align {o_align:.4g}")
        # Relative change below the threshold, or an (almost) exact fit (O_align is at most a
        # few times the volume for unit v, so compare with the volume).
        settled = len(o_trace) > 1 and (
            abs(o_trace[-1] - o_trace[-2]) < config.convergence * o_trace[-2])
        if settled or o_align <= 1e3 * tol.solver * float(vol.sum()):
            status = "converged"
            break
    if unconverged:
        notes.append(f"{unconverged} iterative solve(s) stopped at their iteration cap")
    timings["iterations"] = time.perf_counter() - t
    prog.end("field iterations", timings["iterations"])

    hs = stats_of_gradient(grad, vol, target_h)
    _, delta = layer_heights(grad, vol, target_h)
    timings["total"] = time.perf_counter() - t_start
    return FieldResult(g=g, g0=g0, gradient=grad, delta=delta, layer_height_mm=target_h,
                       height=hs, height_initial=hs0,
                       status=status, iterations=iterations,
                       trace=FieldTrace(tuple(o_trace), tuple(std_trace)), timings=timings,
                       notes=tuple(notes),
                       regions=selection, constrained=constrained, operators=ops,
                       height_start=hs_start)
