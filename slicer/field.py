"""The slicing scalar field of paper section 4.1: vector/scalar iteration with critical regions.

Unknowns: ``g`` is P1 on the tet vertices (its gradient constant per tet, ``TetOperators``);
all vertices of one critical region share one unknown (g constant on it, eq. 7; touching
regions share one), the gauge is fixed by pinning one unknown per connected part and
shifting g to min 0. The vector field ``v`` lives on tets; eq. 6 uses normalised weights
(``vol / mean(vol)``, ``area / mean(area)``) so the balance of w_l and w_h does not depend on
the mesh size or the units. Tets owning a region's boundary face are constrained to its
growth direction; a part without any region gets v = +z on its bottom tets.

Steps (each constant matrix set up once, ``slicer.field_systems``, ``slicer.solvers``):
    1. G0, the harmonic baseline ([42]): Laplace's equation with g fixed on each region to its
       mean height (the planar default completes parts it leaves flat,
       ``harmonic_anchors``); its layer height is the baseline the result is measured
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

from core.progress import NullProgress, Progress
from core.stages import TetMesh
from core.tolerance import tol
from slicer.config import SlicingConfig
from slicer.critical import CriticalSelection, select_critical_regions
from slicer.field_constraints import constraints, harmonic_anchors, unknown_map, vertex_components
from slicer.field_heights import (
    HeightStats,
    height_std,
    layer_heights,
    stats_of_gradient,
)
from slicer.field_systems import Poisson, ScalarHarmonic
from slicer.operators import TetOperators, build_operators
from slicer.solvers import SPDSolver
from slicer.status import FieldStatus, SolverStatus

ALIGN_WEIGHT = 1.0  # w_l; config.smoothness_weight is w_h relative to it
NORMALISE_V = True
INITIAL_FIELD = "scalar"  # G0: "scalar" harmonic (Laplace, regions fixed) or "vector" (eq. 6)
HARMONIC_REGULARISATION = 1e-8  # tiny mass term keeping the pure-smoothness system SPD
# Relative residual of the vector solve: the iteration is a fixed point that corrects itself
# and v is renormalised after each solve (docs/benchmarks.md, field).
VECTOR_RTOL = 1e-5
HARMONIC_RTOL = 1e-6  # the harmonic vector field only starts the iteration


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
        status: how the iteration ended (``FieldStatus``; SOLVER_FAILED: g is then the last
            good field).
        failure: which solve failed and why ("initial:<why>", "vector:<why>",
            "poisson:<why>"); '' unless SOLVER_FAILED.
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
    status: FieldStatus
    iterations: int
    trace: FieldTrace
    timings: dict[str, float]
    notes: tuple[str, ...]
    regions: CriticalSelection
    constrained: np.ndarray
    operators: TetOperators = field(repr=False)
    height_start: HeightStats | None = None
    failure: str = ""

    @property
    def status_text(self) -> str:
        """The status as report.json writes it: ``"solver_failed:<what>"`` on a failure."""
        return self.status.with_detail(self.failure)

    def report(self) -> dict[str, object]:
        """The field's part of report.json's "slicing" section (mm, s; JSON-ready)."""
        return {
            "status": self.status_text,
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
    comp = vertex_components(ops)
    constrained, fixed = constraints(ops, selection, comp)
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
                           status=FieldStatus.PLANAR, iterations=0, trace=FieldTrace((), (hs.std,)),
                           timings=timings, notes=tuple(notes),
                           regions=selection, constrained=constrained, operators=ops)

    # --- set up the constant systems once ---------------------------------------------------
    prog.start("field setup")
    t = time.perf_counter()
    region_vertices = (np.concatenate([r.vertices for r in selection.regions])
                       if selection.regions else np.zeros(0, dtype=np.int64))
    labels, count = unknown_map(ops.n_vertices, selection)
    poisson = Poisson(ops, labels, count, region_vertices)
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
                         method="amg", rtol=HARMONIC_RTOL)
    vector = SPDSolver(w_l * sp.diags(mass[free]) + w_h * lf_ff, method="cg", rtol=VECTOR_RTOL)
    for name, s in (("poisson", poisson.solver), ("harmonic", harmonic), ("vector", vector)):
        if s.status != SolverStatus.OK:
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
    st_s: str = SolverStatus.OK
    if INITIAL_FIELD == "scalar":
        scalar = ScalarHarmonic(poisson, *harmonic_anchors(ops, selection, labels, comp))
        g0, st_s = scalar.solve()
        if scalar.solver.status != SolverStatus.OK:
            notes.append(f"scalar harmonic solver: {scalar.solver.status}")
    else:
        g0 = g_start
    timings["initial"] = time.perf_counter() - t
    prog.end("initial field", timings["initial"])
    failed = next((s for s in (st_h, st_p, st_s)
                   if SolverStatus.kind_of(s) is SolverStatus.FAILED), "")
    if failed or not np.all(np.isfinite(g0)) or not np.all(np.isfinite(g_start)):
        nan = np.full(ops.n_vertices, np.nan)
        hs = HeightStats(*(float("nan"),) * 6)
        timings["total"] = time.perf_counter() - t_start
        return FieldResult(g=nan, g0=nan, gradient=np.full((ops.n_tets, 3), np.nan),
                           delta=float("nan"), layer_height_mm=target_h, height=hs,
                           height_initial=hs,
                           status=FieldStatus.SOLVER_FAILED,
                           failure=f"initial:{failed or 'non-finite'}",
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
    status = (FieldStatus.NO_ITERATIONS if config.max_iterations == 0
              else FieldStatus.MAX_ITERATIONS)
    failure = ""
    iterations = 0
    prev_vf: np.ndarray | None = None
    unconverged = 0
    for it in range(config.max_iterations):
        target = _normalised(grad, v)
        rhs = w_l * mass[free, None] * target[free] - w_h * coupling
        vf, st_v = vector.solve(rhs, x0=prev_vf)
        if SolverStatus.kind_of(st_v) is SolverStatus.FAILED:
            status, failure = FieldStatus.SOLVER_FAILED, f"vector:{st_v}"
            break
        prev_vf = vf
        v_new = fixed.copy()
        v_new[free] = _normalised(vf, target[free]) if NORMALISE_V else vf
        g_new, o_align, st_p = poisson.solve(v_new)
        if SolverStatus.kind_of(st_p) is SolverStatus.FAILED or not np.all(np.isfinite(g_new)):
            status, failure = FieldStatus.SOLVER_FAILED, f"poisson:{st_p}"
            break
        unconverged += (st_v != SolverStatus.OK) + (st_p != SolverStatus.OK)
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
            status = FieldStatus.CONVERGED
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
                       status=status, failure=failure, iterations=iterations,
                       trace=FieldTrace(tuple(o_trace), tuple(std_trace)), timings=timings,
                       notes=tuple(notes),
                       regions=selection, constrained=constrained, operators=ops,
                       height_start=hs_start)
