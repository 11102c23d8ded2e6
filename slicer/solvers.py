"""Set-up-once solver for symmetric positive definite sparse systems.

The slicing iteration solves the same sparse systems many times, so each matrix is set up
once and reused. ``auto`` picks ``cholespy`` (exact) below ``DIRECT_MAX_UNKNOWNS`` unknowns
and ``amg`` above, where the direct factorisations of 3D meshes grow too slow: a pyamg
smoothed-aggregation hierarchy built once, used as CG preconditioner and warm-started from
the previous iterate. ``cg`` is Jacobi-preconditioned CG for matrices with a strong diagonal
(eq. 6 with its alignment term); ``splu`` (SciPy SuperLU) is the fallback. The iterative
backends work on a reverse Cuthill-McKee reordering above ``REORDER_MIN`` unknowns (fTetWild
numbers tets nearly at random). The measurements behind these choices:
docs/benchmarks.md, "Moved from docstrings (issue 24)".

Solvers never raise: ``status`` says what happened.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import reverse_cuthill_mckee

from core.tolerance import tol
from slicer.status import SolverStatus

Method = Literal["auto", "cholespy", "amg", "cg", "splu"]
AMG_SEED = 0  # of the random start vectors pyamg's setup draws
DIRECT_MAX_UNKNOWNS = 20_000
ITERATIVE = ("amg", "cg")
REORDER_MIN = 5_000  # below this the whole system sits in cache anyway
DEFAULT_RTOL = 1e-9


def _fallbacks(method: Method, n: int) -> tuple[str, ...]:
    if method == "auto":
        first = "cholespy" if n <= DIRECT_MAX_UNKNOWNS else "amg"
        return (first, *(m for m in ("amg", "cholespy", "splu", "cg") if m != first))
    return (method, *(m for m in ("amg", "splu", "cg") if m != method))


def _finite_status(x: np.ndarray) -> str:
    """``ok``, or ``failed:non-finite`` when a direct solve returned nan or inf."""
    return SolverStatus.OK if np.all(np.isfinite(x)) else SolverStatus.FAILED.with_detail(
        "non-finite")


class SPDSolver:
    """Set up (factor or build a preconditioner for) an SPD matrix once; solve many times.

    Attributes:
        n: int, size of the system.
        backend: the backend in use ("cholespy", "amg", "cg", "splu"), or "" if none worked.
        status: str, a ``SolverStatus`` text: "ok", "fallback:<why>" (a later backend is in
            use) or "failed:<why>".
        notes: list of str, one per backend that was tried and failed.
        iterations: int, total Krylov iterations of all solves so far (iterative backends).
    """

    def __init__(self, matrix: sp.spmatrix, method: Method = "auto",
                 rtol: float = DEFAULT_RTOL) -> None:
        """Set up ``matrix`` ((n, n) sparse SPD) with the first backend that works.

        Args:
            matrix: (n, n) sparse, symmetric positive definite.
            method: preferred backend; others are tried in turn if it fails.
            rtol: relative residual for the iterative backends.
        """
        a = sp.csr_matrix(matrix, dtype=np.float64)
        a.sort_indices()
        self.n = a.shape[0]
        self._perm: np.ndarray | None = None
        self.rtol = rtol
        self.backend = ""
        self.status: str = SolverStatus.FAILED.with_detail("no backend")
        self.notes: list[str] = []
        self.iterations = 0
        self._matrix = a
        self._impl: object = None
        permuted: tuple[np.ndarray, sp.csr_matrix] | None = None
        for name in _fallbacks(method, self.n):
            try:
                use, perm = a, None
                if name in ITERATIVE and self.n > REORDER_MIN:
                    # Mesh files come in arbitrary element order (fTetWild's is close to
                    # random), so a matrix row touches x all over memory. A reverse
                    # Cuthill-McKee order halves the time of a sparse mat-vec on a 400k-tet
                    # face graph (3.9 -> 2.0 ms) and helps the Gauss-Seidel smoothers alike.
                    if permuted is None:
                        order = reverse_cuthill_mckee(a, symmetric_mode=True)
                        permuted = (order, sp.csr_matrix(a[order][:, order]))
                    perm, use = permuted
                self._impl = self._setup(name, use)
                self._perm, self._matrix = perm, use
            except Exception as exc:  # a failing backend must not crash the pipeline
                self.notes.append(f"{name}: {type(exc).__name__}: {exc}")
                continue
            self.backend = name
            self.status = (SolverStatus.OK if not self.notes
                           else SolverStatus.FALLBACK.with_detail(self.notes[-1]))
            break
        else:
            self.status = SolverStatus.FAILED.with_detail("; ".join(self.notes))

    @property
    def ok(self) -> bool:
        """True when the matrix is set up with some backend."""
        return bool(self.backend)

    @staticmethod
    def _setup(name: str, a: sp.csr_matrix) -> object:
        if a.shape[0] == 0:
            return None
        diag = a.diagonal()
        if np.any(~np.isfinite(a.data)) or np.any(diag <= 0):
            raise ValueError("matrix has a non-positive diagonal or non-finite entries")
        if name == "cholespy":
            from cholespy import CholeskySolverD, MatrixType

            solver = CholeskySolverD(
                a.shape[0],
                np.ascontiguousarray(a.indptr, dtype=np.int32),
                np.ascontiguousarray(a.indices, dtype=np.int32),
                np.ascontiguousarray(a.data, dtype=np.float64),
                MatrixType.CSR,
            )
            # A non-SPD matrix can come back as a garbage factor instead of an exception:
            # check one solve against a known answer.
            probe = np.linspace(1.0, 2.0, a.shape[0])
            out = np.empty_like(probe)
            solver.solve(np.ascontiguousarray(a @ probe), out)
            err = np.abs(out - probe).max()
            if not np.isfinite(err) or err > tol.computed:
                raise ValueError(f"factorization inaccurate (error {err:.1e}; not SPD?)")
            return solver
        if name == "amg":
            import pyamg

            # pyamg's spectral-radius estimates start from np.random.rand: seed the global
            # generator for the setup (and give the caller's state back), so one matrix always
            # gets the same hierarchy and a job sliced twice from one tet mesh is identical
            state = np.random.get_state()  # noqa: NPY002 (pyamg's generator)
            np.random.seed(AMG_SEED)  # noqa: NPY002 (pyamg's generator)
            try:
                return pyamg.smoothed_aggregation_solver(
                    a, symmetry="symmetric").aspreconditioner(cycle="V")
            finally:
                np.random.set_state(state)  # noqa: NPY002 (pyamg's generator)
        if name == "cg":
            inv = 1.0 / diag
            return spla.LinearOperator(a.shape, matvec=lambda x: inv * x.ravel(),
                                       dtype=np.float64)
        if name == "splu":
            return spla.splu(a.tocsc(), permc_spec="MMD_AT_PLUS_A",
                             options={"SymmetricMode": True})
        raise ValueError(f"unknown backend {name}")

    def solve(self, b: np.ndarray, x0: np.ndarray | None = None) -> tuple[np.ndarray, str]:
        """Solve ``A x = b``.

        Args:
            b: (n,) or (n, k) float64.
            x0: optional initial guess with b's shape (used by the iterative backends).

        Returns:
            (x with b's shape, status): a ``SolverStatus`` text, "ok", "not_converged"
            (iterative backend hit its cap; x is the last iterate) or "failed:<why>" (x is NaN).
        """
        rhs = np.ascontiguousarray(b, dtype=np.float64)
        if self._perm is not None:
            guess = None if x0 is None else np.asarray(x0)[self._perm]
            out, status = self._solve(rhs[self._perm], guess)
            back = np.empty_like(out)
            back[self._perm] = out
            return back, status
        return self._solve(rhs, x0)

    def _solve(self, rhs: np.ndarray, x0: np.ndarray | None) -> tuple[np.ndarray, str]:
        if not self.ok:
            return np.full_like(rhs, np.nan), self.status
        if self.n == 0:
            return rhs.copy(), SolverStatus.OK
        if self.backend == "cholespy":
            out = np.empty_like(rhs)
            self._impl.solve(rhs, out)  # type: ignore[attr-defined]
            return out, _finite_status(out)
        if self.backend == "splu":
            out = self._impl.solve(rhs)  # type: ignore[attr-defined]
            return out, _finite_status(out)
        cols = rhs.reshape(self.n, -1)
        guess = None if x0 is None else np.asarray(x0, dtype=np.float64).reshape(self.n, -1)
        out = np.empty_like(cols)
        status: str = SolverStatus.OK
        count = [0]

        def tick(_: np.ndarray) -> None:
            count[0] += 1

        maxiter = 300 if self.backend == "amg" else 2000
        for k in range(cols.shape[1]):  # a few right-hand sides, not a hot loop
            start = None if guess is None else guess[:, k]
            x, info = spla.cg(self._matrix, cols[:, k], x0=start, rtol=self.rtol,
                              maxiter=maxiter, M=self._impl, callback=tick)
            out[:, k] = x
            if info != 0 or not np.all(np.isfinite(x)):
                status = SolverStatus.NOT_CONVERGED
        self.iterations += count[0]
        return out.reshape(rhs.shape), status
