"""The two constant linear systems of the field iteration, each set up and factored once.

``Poisson`` is eq. 8 with the region unknowns collapsed (min sum vol |grad g - v|^2, one pinned
unknown per connected part for the gauge); ``ScalarHarmonic`` is Laplace's equation with g
fixed on G0's anchors. Both return g (V,) float64 shifted to min 0 and the solver's status.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from slicer.operators import TetOperators
from slicer.solvers import SPDSolver
from slicer.status import SolverStatus

# Relative residual of the Poisson solves: the iteration is a fixed point that corrects
# itself and v is renormalised after each solve (docs/benchmarks.md, field).
POISSON_RTOL = 1e-6


class Poisson:
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
        if SolverStatus.kind_of(status) is SolverStatus.FAILED:
            return np.full(self.ops.n_vertices, np.nan), float("nan"), status
        self._last = x
        u = np.zeros(self.count)
        u[self.free] = x
        g = u[self.labels]
        g = g - g.min()
        diff = self.ops.gradient(g) - v
        o_align = float((self.ops.volume * np.einsum("ij,ij->i", diff, diff)).sum())
        return g, o_align, status


class ScalarHarmonic:
    """G0 of the harmonic constraint: Laplace with g fixed on the anchors, set up once."""

    def __init__(self, poisson: Poisson, anchors: np.ndarray, values: np.ndarray) -> None:
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
        if SolverStatus.kind_of(status) is SolverStatus.FAILED:
            return np.full(self.poisson.ops.n_vertices, np.nan), status
        u = np.zeros(self.poisson.count)
        u[self.fixed] = self.values
        u[self.free] = x
        g = u[self.poisson.labels]
        return g - g.min(), status
