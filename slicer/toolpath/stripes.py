"""Stripe toolpaths across the contours (paper eqs. 10-12), after Knoppel et al. 2015.

``stripe_lines`` follows "Stripe Patterns on Surfaces": a unit complex value Psi_i = exp(i psi_i)
per vertex minimises sum_ij w_ij |Psi_j - T_ij(Psi_i)|^2 (eq. 11) with T_ij the rotation by the
target phase change omega_ij along edge ij; for a line field (direction defined up to sign) an
edge whose end directions disagree also conjugates (Psi_j = conj(exp(i omega_ij) Psi_i)). In
real form (Psi = a + ib) this is a 2n x 2n symmetric matrix A; the solution is the eigenvector
of the smallest eigenvalue of A x = lambda M x with the lumped mass M (inverse iteration on one
factor by default, ARPACK shift-invert as the alternative). The relaxed eigenvector puts nearly
all its amplitude near the boundary; projected inverse iterations (unit modulus per vertex) then
spread it, which is what places the branch points. Lines are the crests psi = 2 pi N (eq. 12),
extracted face by face from the phases unwrapped with the per-edge jumps. Faces around which
the jumps add up to a whole period hold a branch point: there the stripe running past is joined
straight through (the two stripe ends farthest apart) and the stripe that stops simply ends;
faces where the line field itself is singular emit nothing. Stripe ends that converge on a
longer neighbour are cut back (``stripe_trim``); the Poisson alternative of the paper's
comparison is ``poisson_stripes``. Measurements behind these choices: docs/benchmarks.md
("Moved from docstrings", stripes).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal, NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.linalg import LinearOperator, eigsh

from core.errors import InputError
from core.tolerance import tol
from slicer.toolpath.isolines import (
    Nodes,
    edge_crossings,
    lines_from_segments,
    periodic_face_segments,
)
from slicer.toolpath.lines import SurfaceLines, empty_lines, merge_lines
from slicer.toolpath.stripe_trim import CONVERGE_TRIM, trim_converging
from slicer.toolpath.surface import (
    check_mesh,
    components,
    cotan_weights,
    edge_topology,
    face_normals,
    lumped_mass,
    rotate_in_plane,
    spd_solver,
    tangent_frames,
    vertex_normals,
)

EIGEN_SHIFT = 1e-6  # sigma of the shift-invert, relative to the mean diagonal of A over M
ARPACK_RTOL = 1e-6  # relative accuracy of ARPACK's eigenpair (the ``arpack`` alternative)


class StripeField(NamedTuple):
    """The optimised periodic field behind ``stripe_lines``.

    phase:    (n,) float64 rad, psi at each vertex (in the vertex's direction orientation).
    z:        (n, 3) float64, unit phase-gradient direction per vertex (sign arbitrary).
    singular: (m,) bool, faces with a branch point or a line-field singularity.
    eigenvalue: float, the smallest eigenvalue of A x = lambda M x (1/mm^2).
    """

    phase: NDArray[np.float64]
    z: NDArray[np.float64]
    singular: NDArray[np.bool_]
    eigenvalue: float


def check_stripe_inputs(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                        direction: NDArray[np.float64], spacing: float) -> None:
    """Raise ``InputError`` unless the mesh, the per-face direction and the spacing are usable."""
    check_mesh(vertices, faces)
    d = np.asarray(direction)
    if d.shape != (len(faces), 3) or not np.all(np.isfinite(d)):
        raise InputError(f"stripe direction must be a finite (m, 3) array with m = {len(faces)}, "
                         f"got shape {d.shape}", "pass surface.stripe_direction(...)")
    if not spacing > 0:
        raise InputError(f"stripe spacing must be positive, got {spacing} mm",
                         "use the toolpath width")


def vertex_line_field(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                      field: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n, 3) unit per-vertex line field: area-weighted average of per-face directions.

    Directions are taken up to sign (squared as complex numbers in the vertex tangent frame).
    """
    vn = vertex_normals(vertices, faces)
    e1, e2 = tangent_frames(vn)
    _, area = face_normals(vertices, faces)
    acc = np.zeros(len(vertices), dtype=np.complex128)
    for k in range(3):
        vid = faces[:, k]
        c = np.einsum("ij,ij->i", field, e1[vid]) + 1j * np.einsum("ij,ij->i", field, e2[vid])
        np.add.at(acc, vid, area * c**2 / np.maximum(np.abs(c) ** 2, tol.zero))
    half = np.sqrt(acc)
    out = half.real[:, None] * e1 + half.imag[:, None] * e2
    return out / np.maximum(np.linalg.norm(out, axis=1), tol.zero)[:, None]


def _edge_weights(vertices: NDArray[np.float64], faces: NDArray[np.integer]
                  ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Unique edges (E, 2) and their cotangent weights clamped at zero (slivers stay PSD)."""
    topo = edge_topology(faces)
    i, j, w = cotan_weights(vertices, faces)
    n = len(vertices)
    mat = sp.coo_matrix((w, (np.minimum(i, j), np.maximum(i, j))), shape=(n, n)).tocsr()
    we = np.asarray(mat[topo.edges[:, 0], topo.edges[:, 1]]).ravel()
    return topo.edges, np.maximum(we, 1e-3 * max(float(np.abs(we).mean()), tol.zero))


def stripe_field(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                 direction: NDArray[np.float64], spacing: float, refine: int = 10,
                 eigen: Literal["arpack", "inverse"] = "inverse") -> StripeField:
    """Solve eq. 11: the periodic field whose crests run along ``direction``, ``spacing`` apart."""
    check_stripe_inputs(vertices, faces, direction, spacing)
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = len(v)
    fn, _ = face_normals(v, f)
    # paper's z: the phase gradient, perpendicular to the lines, in the face plane
    zf = rotate_in_plane(np.asarray(direction, dtype=np.float64), fn)
    z = vertex_line_field(v, f, zf)
    nu = 2.0 * np.pi / spacing
    edges, w = _edge_weights(v, f)
    i, j = edges[:, 0], edges[:, 1]
    e = v[j] - v[i]
    s = np.where(np.einsum("ij,ij->i", z[i], z[j]) >= 0.0, 1.0, -1.0)
    omega = 0.5 * nu * (np.einsum("ij,ij->i", e, z[i]) + s * np.einsum("ij,ij->i", e, z[j]))
    c, sn = np.cos(omega), np.sin(omega)
    # Q = R(omega) or C R(omega) (C = diag(1, -1)): energy w |x_j - Q x_i|^2
    q = np.empty((len(i), 2, 2))
    q[:, 0, 0], q[:, 0, 1] = c, -sn
    q[:, 1, 0], q[:, 1, 1] = s * sn, s * c
    rows, cols, vals = [], [], []
    for a in range(2):
        rows += [2 * i + a, 2 * j + a]
        cols += [2 * i + a, 2 * j + a]
        vals += [w, w]
        for b in range(2):
            # -w x_j^T Q x_i - w x_i^T Q^T x_j
            rows += [2 * j + a, 2 * i + b]
            cols += [2 * i + b, 2 * j + a]
            vals += [-w * q[:, a, b], -w * q[:, a, b]]
    amat = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(2 * n, 2 * n))
    mass = np.repeat(np.maximum(lumped_mass(v, f), tol.zero), 2)
    mmat = sp.diags(mass).tocsc()
    # shift-invert just below zero: A is PSD, so A - sigma M is definite and splu-stable
    sigma = -EIGEN_SHIFT * float(amat.diagonal().mean() / mass.mean())
    # one factorisation serves the shift-invert eigen solve and the refinement below
    solve = spd_solver(amat - sigma * mmat)
    opinv = LinearOperator((2 * n, 2 * n), matvec=solve, dtype=np.float64)
    rng = np.random.default_rng(0)
    if eigen == "arpack":
        vals_, vecs = eigsh(amat, k=1, M=mmat, sigma=sigma, which="LM", OPinv=opinv,
                            v0=rng.standard_normal(2 * n), tol=ARPACK_RTOL, ncv=8)
        x = vecs[:, 0].reshape(n, 2)
        lam = float(vals_[0])
    else:
        # plain inverse iteration with the same factor: enough to seed the refinement
        y = rng.standard_normal(2 * n)
        for _ in range(8):
            y = solve(mass * y)
            y /= np.sqrt(float((mass * y * y).sum()))
        lam = float(y @ (amat @ y))
        x = y.reshape(n, 2)
    if refine > 0:
        # the relaxed eigenvector concentrates its amplitude where the field is integrable
        # (the boundary) and leaves the interior to round-off; projected inverse iterations
        # (unit modulus per vertex after each solve) spread it evenly, which is what places
        # the branch points where the line count must change
        for _ in range(refine):
            # amplitudes span many decades (1e-12 inside): normalise any non-zero value
            amp = np.linalg.norm(x, axis=1)
            x = x / np.where(amp > 0.0, amp, 1.0)[:, None]
            x = solve(mass * x.ravel()).reshape(n, 2)
    phase = np.arctan2(x[:, 1], x[:, 0])
    fp = _face_phases(v, f, phase, z, nu)
    singular = fp.branch | fp.flip
    return StripeField(phase=phase, z=z, singular=singular, eigenvalue=lam)


def _wrap(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


class FacePhases(NamedTuple):
    """Phases of the stripe field seen from each face (all (m, 3) float64 rad unless noted).

    corner:   unwrapped corner phases (linear interpolation inside the face).
    branch:   (m,) bool, the unwrapped jumps around the face add up to a non-zero multiple of
              2 pi (a branch point: one stripe ends here).
    flip:     (m,) bool, the line field itself is singular in the face (index 1/2).
    start, end: phase at corners k and k + 1 of side k, unwrapped along that side alone
              (what the neighbour across the side sees too, up to sign and 2 pi).
    """

    corner: NDArray[np.float64]
    branch: NDArray[np.bool_]
    flip: NDArray[np.bool_]
    start: NDArray[np.float64]
    end: NDArray[np.float64]


def _face_phases(v: NDArray[np.float64], f: NDArray[np.int64], phase: NDArray[np.float64],
                 z: NDArray[np.float64], nu: float) -> FacePhases:
    """Per-face unwrapped phases and the singular faces (see ``FacePhases``).

    Corner 0 sets the face's orientation of the line field; corners whose direction disagrees
    are flipped (psi -> -psi, which keeps the crests). Corners 1 and 2 are unwrapped from
    corner 0 along the target jumps; the face is singular when unwrapping along side 1-2
    disagrees by a whole period (a branch point) or the flipped directions of corners 1 and 2
    still disagree (a line-field singularity).
    """
    zc = z[f]  # (m, 3, 3)
    sig = np.where(np.einsum("fi,fki->fk", zc[:, 0], zc) >= 0.0, 1.0, -1.0)
    ph = sig * phase[f]
    zs = sig[:, :, None] * zc
    p = v[f]

    def omega(a: int, b: int) -> NDArray[np.float64]:
        return 0.5 * nu * np.einsum("fi,fi->f", p[:, b] - p[:, a], zs[:, a] + zs[:, b])

    w01, w02, w12 = omega(0, 1), omega(0, 2), omega(1, 2)
    out = np.empty_like(ph)
    out[:, 0] = ph[:, 0]
    out[:, 1] = ph[:, 0] + w01 + _wrap(ph[:, 1] - ph[:, 0] - w01)
    out[:, 2] = ph[:, 0] + w02 + _wrap(ph[:, 2] - ph[:, 0] - w02)
    d12 = w12 + _wrap(ph[:, 2] - ph[:, 1] - w12)
    jump = np.rint((out[:, 2] - out[:, 1] - d12) / (2.0 * np.pi))
    flip = np.einsum("fi,fi->f", zs[:, 1], zs[:, 2]) < 0.0
    # side k runs from corner k to corner k + 1 (side 2 from corner 2 back to corner 0)
    end = np.column_stack([out[:, 1], ph[:, 1] + d12,
                           ph[:, 2] - w02 + _wrap(ph[:, 0] - ph[:, 2] + w02)])
    return FacePhases(corner=out, branch=(jump != 0) & ~flip, flip=flip, start=ph, end=end)


def _branch_segments(nodes: Nodes) -> NDArray[np.int64]:
    """Join stripe ends inside branch faces: (S, 2) node keys.

    A branch face is entered by an odd number of stripe ends (usually 3: one stripe runs
    through, one ends). The two ends farthest apart are the stripe running through and are
    joined; the remaining end stays an end (the stripe that stops at the branch point).
    """
    if len(nodes.key) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    order = np.argsort(nodes.face, kind="stable")
    face = nodes.face[order]
    start = np.flatnonzero(np.concatenate([[True], face[1:] != face[:-1]]))
    count = np.diff(np.concatenate([start, [len(face)]]))
    pairs = []
    two = start[count == 2]
    pairs.append(np.column_stack([order[two], order[two + 1]]))
    three = start[count == 3]
    if len(three):
        idx = order[three[:, None] + np.arange(3)]  # (t, 3)
        p = nodes.point[idx]
        dist = np.stack([np.linalg.norm(p[:, 0] - p[:, 1], axis=1),
                         np.linalg.norm(p[:, 0] - p[:, 2], axis=1),
                         np.linalg.norm(p[:, 1] - p[:, 2], axis=1)], axis=1)
        choice = np.array([[0, 1], [0, 2], [1, 2]])[np.argmax(dist, axis=1)]
        pairs.append(np.take_along_axis(idx, choice, axis=1))
    for s, c in zip(start[count > 3], count[count > 3], strict=True):  # rare: 2+ branch points
        idx = order[s:s + c]
        d = np.linalg.norm(nodes.point[idx][:, None] - nodes.point[idx][None], axis=2)
        a, b = np.unravel_index(np.argmax(d), d.shape)
        pairs.append(np.array([[idx[a], idx[b]]]))
    pair = np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64)
    return nodes.key[pair]


LineFn = Callable[[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64], float],
                  SurfaceLines]


def per_component(fn: LineFn, vertices: NDArray[np.float64], faces: NDArray[np.integer],
                  direction: NDArray[np.float64], spacing: float) -> SurfaceLines:
    """Run a pattern on each edge-connected component (its eigen/Poisson problem is per piece)."""
    comps = components(faces)
    f = np.asarray(faces, dtype=np.int64)
    d = np.asarray(direction, dtype=np.float64)
    if len(comps) == 1:
        return fn(np.asarray(vertices, dtype=np.float64), f, d, spacing)
    parts, maps = [], []
    for comp in comps:  # loop over layer components
        used, local = np.unique(f[comp], return_inverse=True)
        parts.append(fn(np.asarray(vertices, dtype=np.float64)[used], local.reshape(-1, 3),
                        d[comp], spacing))
        maps.append(comp)
    return merge_lines(parts, maps)


def _stripe_lines_one(vertices: NDArray[np.float64], faces: NDArray[np.int64],
                      direction: NDArray[np.float64], spacing: float,
                      join_branches: bool = True, trim: bool = True) -> SurfaceLines:
    field = stripe_field(vertices, faces, direction, spacing)
    fp = _face_phases(vertices, faces, field.phase, field.z, 2.0 * np.pi / spacing)
    period = 2.0 * np.pi
    stride = int(np.ceil(np.abs(fp.end - fp.start).max() / period)) + 2
    singular = fp.branch | fp.flip
    nodes, seg = periodic_face_segments(vertices, faces, fp.corner, period, active=~singular,
                                        stride=stride)
    branch = np.flatnonzero(fp.branch)
    if join_branches and len(branch):
        fid = np.repeat(branch, 3)
        side = np.tile(np.arange(3), len(branch))
        bnodes, _ = edge_crossings(vertices, faces, fid, side, fp.start[branch].ravel(),
                                   fp.end[branch].ravel(), period, stride)
        bseg = _branch_segments(bnodes)
        if len(bseg):
            nodes = Nodes(key=np.concatenate([nodes.key, bnodes.key]),
                          point=np.concatenate([nodes.point, bnodes.point]),
                          face=np.concatenate([nodes.face, bnodes.face]),
                          bary=np.concatenate([nodes.bary, bnodes.bary]))
            seg = np.concatenate([seg, bseg])
    if len(seg) == 0:
        return empty_lines()
    lines = lines_from_segments(nodes, seg)
    if not trim or CONVERGE_TRIM <= 0:
        return lines
    return trim_converging(lines, spacing, CONVERGE_TRIM)


def stripe_lines(vertices: NDArray[np.float64], faces: NDArray[np.integer],
                 direction: NDArray[np.float64], spacing: float) -> SurfaceLines:
    """Stripe toolpath lines (eqs. 10-12) running along ``direction``, ``spacing`` apart.

    vertices (n, 3) mm; faces (m, 3); direction: (m, 3) per-face unit tangent along which the
    lines run (``surface.stripe_direction``: across the contours); spacing: mm between lines
    (tau * W). Lines are cut at the boundary; at a branch point one line ends and its
    neighbour runs through. Several components are solved one by one.
    """
    check_stripe_inputs(vertices, faces, direction, spacing)
    return per_component(_stripe_lines_one, vertices, faces, direction, spacing)
