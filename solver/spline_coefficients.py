"""The natural cubic spline through frames as a clamped cubic B-spline: m frame values and two end conditions
fix its m + 2 coefficients, and each point depends on the four coefficients of its knot interval (de Boor, A
Practical Guide to Splines, 2001, ch. IX). The preconditioners of a grid of frames work in these coefficients,
where the curvature of anything measured at the points is banded (`solver.gauss_newton`,
`solver.grid_preconditioner`).
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import BSpline

__all__ = ["SplineCoefficients", "derivative_design"]


class SplineCoefficients:
    """The natural cubic spline through frames at `knots` as a clamped cubic B-spline (module docstring).

    Args:
        knots: (m,) increasing frame times [s], m >= 2. t: (n,) quadrature times [s] within them.
    Attributes:
        span: (n,) the first of each point's four coefficients. b: (3, n, 4) the basis functions' value,
        first and second derivative [1, 1/s, 1/s^2] at the points. at_frames: (m, m + 2) CSR, the basis at
        the frames (the frame values are at_frames @ C). ends: (2, m + 2) the second derivative at the ends.
    """

    def __init__(self, knots: np.ndarray, t: np.ndarray):
        x = np.asarray(knots, float)
        t = np.clip(np.asarray(t, float), x[0], x[-1])
        m = len(x)
        self.size = m + 2
        full = np.r_[[x[0]] * 3, x, [x[-1]] * 3]
        self.span = np.clip(np.searchsorted(x, t, side="right") - 1, 0, max(m - 2, 0))
        self.b = np.zeros((3, len(t), 4))
        for r in range(3):
            M = derivative_design(full, t, r).tocoo()  # (n, m + 2), four entries a row at most
            self.b[r, M.row, M.col - self.span[M.row]] = M.data
        self.at_frames = derivative_design(full, x, 0).tocsr()
        self.at_frames.eliminate_zeros()
        self.ends = derivative_design(full, x[[0, -1]], 2).toarray()

    def gram_band(self, r: int, w: np.ndarray) -> np.ndarray:
        """(4, m + 2) the lower band (LAPACK's storage, G[c + d, c] at [d, c]) of the Gram matrix of the r-th
        derivatives at the points, G = sum_i w_i b_i b_i^T over each point's four coefficients: a quadrature
        of the integral of the spline's r-th derivative squared, C^T G C [its unit squared times w's].

        Args:
            r: 0, 1 or 2. w: (n,) the points' weights.
        """
        b, w = self.b[r], np.asarray(w, float)
        out = np.zeros((4, self.size))
        for a in range(4):
            for c in range(a + 1):
                out[a - c] += np.bincount(self.span + c, weights=w * b[:, a] * b[:, c], minlength=self.size)
        return out


def derivative_design(full: np.ndarray, x: np.ndarray, r: int):
    """(len(x), n) sparse: the r-th derivative of each of the n cubic B-splines on the knots `full` at x, as
    the degree 3 - r design matrix (scipy's `BSpline.design_matrix`) times the difference map of the
    coefficients, d_i = k (c_i+1 - c_i) / (t_i+k+1 - t_i+1) per derivative (de Boor, ch. X)."""
    from scipy.sparse import diags

    k, T = 3, full
    D = None
    for _ in range(r):
        n = len(T) - k - 1
        h = k / (T[k + 1: n + k] - T[1:n])
        step = diags([-h, h], [0, 1], shape=(n - 1, n), format="csr")
        D = step if D is None else step @ D
        T, k = T[1:-1], k - 1
    X = BSpline.design_matrix(x, T, k)
    return X if D is None else X @ D
