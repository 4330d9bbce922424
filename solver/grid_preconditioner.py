"""D's preconditioner on a grid of frames, in time linear in the frames: the Kronecker factor of
`solver.lagrangian.Preconditioner` taken through the frames' B-spline coefficients, where it is banded.

`Preconditioner` whitens D/D0's time-averaged Gauss-Newton Hessian H = K2 (x) Mbar + K0 (x) Pbar by the
generalized eigenvectors of (K2, K0), m x m matrices over the m frame values: O(m^3) to build and O(m^2) an
application, which a clean's grid (a frame at every capture frame, thousands of them) cannot afford: on a
3069-frame capture the build took 6.1 s and each application 39 ms, beside 54 ms for an evaluation.

Here the same H is factored in the coefficients C of the natural spline (`solver.spline_coefficients`): the
generalized eigenvectors U of (Mbar, Pbar) (U^T Pbar U = I, U^T Mbar U = diag(sigma)) split H into one
problem per mode k, sigma_k G2 + G0, with G2 and G0 the Gram matrices of the second derivatives and of the
values at the points (`SplineCoefficients.gram_band`), banded with three off-diagonals (Van Loan, "The
ubiquitous Kronecker product", J. Comput. Appl. Math. 123, 2000). The natural end conditions and the fixed
frames (a clean's pins) are constraints on a few neighbouring coefficients each; solved for one coefficient
each (`null_space`: C = N c), they leave c, one coefficient for each free frame, and the band N^T G N
(`_reduced_band`). With each mode's band factored as L_k L_k^T (`solver.gauss_newton._factor`: LAPACK's banded
Cholesky of the equilibrated band; all modes in one band), x = S z with S = Sel A N (L^-T (x) U^T) (A the basis
at the frames, Sel the free frames) is square and S S^T = H^-1 exactly: x = Sel A N c is one-to-one (a natural
spline is fixed by its values at the frames). So S S^T is `Preconditioner`'s R^-1 R^-T, and L-BFGS, invariant
under an orthogonal change of its variables, takes the same steps with either, to round-off.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dtbtrs
from scipy.sparse import csr_matrix, diags, tril

from solver.gauss_newton import _factor
from solver.lagrangian import _pair_basis, _variable_dofs
from solver.manifold import FrameVariables
from solver.spline_basis import SplineBasis
from solver.spline_coefficients import SplineCoefficients

__all__ = ["BandedPreconditioner", "grid_maps", "null_space"]

#: [1] entries of N below this fraction of its largest (at least its identity's 1) are the solve's round-off (about 50
#: machine epsilons) where the exact N has zeros: dropped, so that N^T G N keeps the band its constraints' few
#: neighbours give it
ROUND_OFF = 1e-14


class BandedPreconditioner:
    """x = S z with S S^T the inverse of D/D0's time-averaged Gauss-Newton Hessian over the free frame values
    (module docstring), with `solver.lagrangian.Preconditioner`'s interface (`size`, `apply`, `apply_transpose`).

    Args:
        variables: FrameVariables (x: n values). basis: the frames' SplineBasis at the quadrature points.
        change: MeasureOfChange (its weights, mbar, pbar, omega). tmap: TangentMap. d0: D0 [kg m^2/s^3].
    Attributes:
        size: n, z's length.
    Raises:
        ValueError: the degrees of freedom are not all free at the same frames (a partial keyframe):
            `Preconditioner` serves such frames.
    """

    def __init__(self, variables: FrameVariables, basis: SplineBasis, change, tmap, d0: float):
        frames, dofs = _variable_dofs(variables, tmap)
        F, D = np.unique(frames), np.unique(dofs)
        order = np.lexsort((dofs, frames))  # by frame, then degree of freedom
        if len(order) != F.size * D.size or not (np.array_equal(frames[order], np.repeat(F, D.size))
                                                  and np.array_equal(dofs[order], np.tile(D, F.size))):
            raise ValueError("the degrees of freedom are not all free at the same frames; use Preconditioner")
        self.index, self.free = order.reshape(F.size, D.size), F  # index[f, j]: x's entry of frame F[f], dof D[j]
        co = SplineCoefficients(basis.knots, change.ref.t)
        fixed = np.setdiff1d(np.arange(len(basis.knots)), F)
        N = null_space(np.vstack([co.ends, co.at_frames[fixed].toarray()]))  # C = N c: natural ends, fixed frames 0
        self.AN = (co.at_frames @ N).tocsr()  # (m, f): the frame values of c
        w = change.ref.weights * (2.0 / d0)
        sigma, self.U = _pair_basis(change.mbar[np.ix_(D, D)], change.pbar[np.ix_(D, D)])
        G2, G0 = (_reduced_band(co.gram_band(r, w), N) for r in (2, 0))
        band = sigma[:, None, None] * G2 + change.omega ** 4 * G0  # (k, b + 1, f): each mode's band
        self._scale, self.L = _factor(band.transpose(1, 0, 2).reshape(len(G2), -1))  # the modes one after another
        self.size = band.shape[0] * band.shape[2]

    def apply(self, z: np.ndarray) -> np.ndarray:
        """x = S z: (n,) from (n,)."""
        c, _ = dtbtrs(self.L, z, uplo="L", trans="T")
        Y = self.AN @ (c * self._scale).reshape(len(self.U), -1).T  # (m, k): each mode at the frames
        out = np.empty(self.index.size)
        out[self.index] = (Y @ self.U.T)[self.free]
        return out

    def apply_transpose(self, g: np.ndarray) -> np.ndarray:
        """S^T g: (n,) from a gradient (n,) in x."""
        G = np.zeros((self.AN.shape[0], len(self.U)))
        G[self.free] = g[self.index]
        y = (self.AN.T @ (G @ self.U)).T.ravel()
        out, _ = dtbtrs(self.L, y * self._scale, uplo="L", trans="N")
        return out


def null_space(B: np.ndarray):
    """(c, c - r) sparse N with B N = 0 whose columns are the coefficients left free: each of B's r rows
    (constraints on the c coefficients, each on a few neighbours: the natural ends, the fixed frames) solved for
    one coefficient, its largest not yet taken, in terms of the others; the rest an identity.

    Raises:
        ValueError: the rows are not independent.
    """
    B = np.asarray(B, float)
    r, c = B.shape
    piv: list[int] = []
    for row in B:
        mag = np.abs(row)
        mag[piv] = 0.0
        piv.append(int(np.argmax(mag)))
    rest = np.setdiff1d(np.arange(c), piv)
    P = B[:, piv]
    if np.linalg.matrix_rank(P) < r:
        raise ValueError("the spline's constraints are not independent")
    M = -np.linalg.solve(P, B[:, rest])  # (r, c - r): the pivots in terms of the rest
    pr, pc = np.nonzero(np.abs(M) >= ROUND_OFF * max(1.0, np.abs(M).max()))
    rows = np.r_[rest, np.asarray(piv)[pr]]
    cols = np.r_[np.arange(c - r), pc]
    return csr_matrix((np.r_[np.ones(c - r), M[pr, pc]], (rows, cols)), shape=(c, c - r))


def _reduced_band(band: np.ndarray, N) -> np.ndarray:
    """The lower band (b + 1, f) of N^T G N, G symmetric with lower band `band` (4, c) and N (c, f) sparse
    (`null_space`); b its half-bandwidth (3 where the constraints tie only neighbouring coefficients)."""
    c = band.shape[1]
    G = diags([band[d, : c - d] for d in range(4)], [0, -1, -2, -3], shape=(c, c), format="csr")
    G = G + tril(G, -1, format="csr").T
    R = (N.T @ G @ N).tocoo()
    low = R.row >= R.col
    b = int((R.row - R.col)[low].max(initial=0))
    out = np.zeros((b + 1, R.shape[0]))
    out[(R.row - R.col)[low], R.col[low]] = R.data[low]
    return out


def grid_maps(al, frames, quat_slots) -> tuple:
    """(SplineBasis, BandedPreconditioner) of a grid's frame set at `al`'s points: `solver.lagrangian.frame_maps`
    in time linear in the frames, for frames whose degrees of freedom are all free at the same frames.

    Args:
        al: AugmentedLagrangian (its points, measure of change, D0). frames: FrameSet (m, nq).
        quat_slots: (s, 4) the layout's quaternion slots.
    Raises:
        ValueError: a partial keyframe (`BandedPreconditioner`).
    """
    basis = SplineBasis(frames.times, al.t)
    return basis, BandedPreconditioner(FrameVariables(frames, quat_slots), basis, al.change, al.tmap, al.d0)
