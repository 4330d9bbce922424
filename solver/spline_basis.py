"""`SplineBasis`: the spline's linear map from frame values to Y, Y', Y'' at the quadrature points of one
frame set (paper eq. 6), evaluated densely for short clips and through the natural spline's tridiagonal
moment system for long ones (docs/scaling.md). The matrices themselves are `solver.spline`'s.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from solver.errors import InputError
from solver.spline import _check_knots, _segments, _stacked_matrices, moment_matrix

try:  # the kernel behind `csr_matrix @ dense` without its ~30 us of Python checks per call
    from scipy.sparse._sparsetools import csr_matvecs as _csr_matvecs
except ImportError:  # a scipy that moved it: the public product (same result, more overhead)
    _csr_matvecs = None


def _csr_accumulate(A, X: np.ndarray, out: np.ndarray) -> None:
    """out += A @ X for a CSR matrix A (r, c), X (c, k), out (r, k) C-contiguous float64."""
    X = np.ascontiguousarray(X, dtype=float)
    if _csr_matvecs is None:
        out += A @ X
        return
    _csr_matvecs(A.shape[0], A.shape[1], X.shape[1], A.indptr, A.indices, A.data, X.ravel(), out.ravel())


#: [entries] At or below this many entries per matrix (quadrature points x frames) `SplineBasis` stores W, W1, W2
#: densely and evaluates with whole-matrix products; above it, it evaluates through the tridiagonal
#: moment system (O(points + frames) work and memory per evaluation). Measured (value + pullback, one
#: thread, `python -m runner.bench.scaling --per-eval`): the two cost the same near 21000 entries for the
#: figure (51 components; 700 points x 30 frames: 0.36 ms each), banded 2.2x faster at 84000 (1400 x 60)
#: and 17x at 5.4e6; for 4 components (orientation) dense is 2x faster up to 21000 and even at 84000.
DENSE_MAX_ENTRIES = 32768


@dataclass
class SplineBasis:
    """Y, Y', Y'' at fixed quadrature times for one frame set (built once per frame set), as a linear
    map of the frame values: Y = W P, Y' = W1 P, Y'' = W2 P (paper eq. 6).

    Two evaluations of the same map, chosen by size (`mode="auto"`):

    - dense (n * m <= DENSE_MAX_ENTRIES): W, W1, W2 built at construction, `evaluate` and `pullback`
      are whole-matrix products (fastest for short clips: a few BLAS calls);
    - banded (larger): nothing (n, m) is formed. Each point depends on its segment's two frame values
      and two moments, and the moments solve the natural spline's tridiagonal system T M_int = R P
      (T symmetric positive definite, factored once with LAPACK dpttrf). `evaluate` is one
      tridiagonal solve (dpttrs, O(m nq)) and one sparse local map per order (4 entries per row,
      O(n nq)); `pullback` is the transpose: the local map's transpose, one solve with T^T = T, R^T.
      Work and memory per evaluation are O((n + m) nq) instead of O(n m nq) (T^-1 is dense, which is
      why W itself is not sparse).

    W, W1, W2 and B stay available in both modes; a banded basis builds them on first use (O(n m);
    `gram` gives W^T diag(w) W and W2^T diag(w) W2 without them).

    Attributes:
        knots: (m,) frame times [s]. t: (n,) quadrature times [s].
        weights: (n,) quadrature weights [s], or None (the caller applies a uniform weight).
        mode: "auto", "dense" or "banded" (tests and benchmarks force one).
        banded: True if this basis evaluates through the tridiagonal system.
        B: (3n, m) the three matrices stacked (Y, Y', Y'' at all points in one product, as
            `solve` uses it for whole free frames).
        W, W1, W2: (n, m) matrices (see `spline_matrices`), views of B.
    """

    knots: np.ndarray
    t: np.ndarray
    weights: np.ndarray | None = None
    mode: str = "auto"
    banded: bool = field(init=False)
    _B3: np.ndarray | None = field(init=False, repr=False, default=None)

    def __post_init__(self):
        x = self.knots = _check_knots(self.knots)
        self.t = np.asarray(self.t, dtype=float).reshape(-1)
        if self.mode not in ("auto", "dense", "banded"):
            raise InputError(f"SplineBasis mode must be 'auto', 'dense' or 'banded', got {self.mode!r}")
        n, m = len(self.t), len(x)
        self.banded = self.mode == "banded" or (self.mode == "auto" and n * m > DENSE_MAX_ENTRIES)
        if not self.banded:
            self._B3 = _stacked_matrices(x, self.t)
            return
        from scipy.linalg.lapack import dpttrf
        from scipy.sparse import csr_matrix

        h = np.diff(x)
        self._h = h
        self._T = None
        if m >= 4:  # T M_int = R P: T = tridiag(h_i-1, 2 (h_i-1 + h_i), h_i), SPD for increasing knots
            d, e, info = dpttrf(2.0 * (h[:-1] + h[1:]), h[1:-1].copy())
            if info != 0:  # cannot happen for strictly increasing knots
                raise ValueError(f"natural spline system is not positive definite (LAPACK dpttrf info={info})")
            self._T = (d, e)
        k, a, b, hk = _segments(x, self.t)
        ih = 1.0 / hk
        # local map of each order on [P; M] (2m columns): the same coefficients as `_stacked_matrices`
        lin = ((a * ih, b * ih), (-ih, ih), None)
        ca = ((a * a * ih - hk) * a / 6.0, (hk - 3.0 * a * a * ih) / 6.0, a * ih)
        cb = ((b * b * ih - hk) * b / 6.0, (3.0 * b * b * ih - hk) / 6.0, b * ih)
        self._local, self._local_T = [], []
        for j in range(3):
            cols = [k + m, k + m + 1] if lin[j] is None else [k, k + 1, k + m, k + m + 1]
            vals = [ca[j], cb[j]] if lin[j] is None else [*lin[j], ca[j], cb[j]]
            width = len(cols)
            L = csr_matrix((np.stack(vals, axis=1).ravel(), np.stack(cols, axis=1).ravel(),
                            np.arange(0, width * n + 1, width)), shape=(n, 2 * m))
            self._local.append(L)
            self._local_T.append(L.T.tocsr())

    # -- the dense matrices (built on first use for a banded basis) --

    @property
    def B3(self) -> np.ndarray:
        """(3, n, m): W, W1, W2."""
        if self._B3 is None:
            self._B3 = _stacked_matrices(self.knots, self.t)
        return self._B3

    @property
    def B(self) -> np.ndarray:
        return self.B3.reshape(3 * len(self.t), len(self.knots))

    @property
    def W(self) -> np.ndarray:
        return self._matrix(0)

    @property
    def W1(self) -> np.ndarray:
        return self._matrix(1)

    @property
    def W2(self) -> np.ndarray:
        return self._matrix(2)

    def _matrix(self, j: int) -> np.ndarray:
        """W, W1 or W2; a banded basis builds (and keeps) only the one asked for: (n, m), O(n m)."""
        if self._B3 is not None:
            return self._B3[j]
        cache = self.__dict__.setdefault("_dense", {})
        if j not in cache:
            m = len(self.knots)
            L = self._local[j]
            # rows of [I; S] (2m, m) gathered by the local map: W_j = L_j [I; S]
            IS = np.vstack([np.eye(m), moment_matrix(self.knots)])
            cache[j] = L @ IS
        return cache[j]

    # -- the banded evaluation --

    def _moments(self, P: np.ndarray) -> np.ndarray:
        """[P; M] (2m, nq): the frame values and the spline's moments (M = S P, `moment_matrix`)."""
        m = len(self.knots)
        PM = np.zeros((2 * m, P.shape[1]))
        PM[:m] = P
        if m >= 3:
            d = np.diff(P, axis=0) / self._h[:, None]
            PM[m + 1:2 * m - 1] = self._solve(6.0 * (d[1:] - d[:-1]))  # T^-1 R P
        return PM

    def _moments_transpose(self, G: np.ndarray) -> np.ndarray:
        """G[:m] + S^T G[m:] (m, nq): a gradient with respect to [P; M] as one with respect to P."""
        m = len(self.knots)
        out = G[:m].copy()
        if m >= 3:
            out += self._R_transpose(self._solve(G[m + 1:2 * m - 1].copy()))  # T^-T = T^-1
        return out

    def _solve(self, b: np.ndarray) -> np.ndarray:
        """T^-1 b for b (m-2, c) (overwritten), with the factors from construction (LAPACK dpttrs)."""
        if self._T is None:  # m = 3: T is 1 x 1
            b /= 2.0 * (self._h[0] + self._h[1])
            return b
        from scipy.linalg.lapack import dpttrs

        x, info = dpttrs(*self._T, b, overwrite_b=True)
        if info != 0:
            raise ValueError(f"tridiagonal solve failed (LAPACK dpttrs info={info})")
        return x

    def _R_transpose(self, z: np.ndarray) -> np.ndarray:
        """R^T z (m, c) for z (m-2, c): R = 6 D2 D1 (D1 y = diff(y) / h, D2 = diff), R^T = 6 D1^T D2^T."""
        m = len(self.knots)
        u = np.zeros((m - 1, z.shape[1]))
        u[:-1] -= z
        u[1:] += z
        u *= (6.0 / self._h)[:, None]
        out = np.zeros((m, z.shape[1]))
        out[:-1] -= u
        out[1:] += u
        return out

    def evaluate(self, P: np.ndarray, needs=(0, 1, 2)):
        """Y, Y', Y'' at the quadrature points (None for orders not in `needs`).

        Args:
            P: (m, nq) frame values.
        Returns:
            tuple of three (n, nq) arrays or None.
        """
        if not self.banded:
            B3 = self._B3
            return tuple(B3[k] @ P if k in needs else None for k in range(3))
        P = np.asarray(P, dtype=float)
        PM = self._moments(P.reshape(len(self.knots), -1))
        n = len(self.t)
        out = []
        for k in range(3):
            if k in needs:
                Y = np.zeros((n, PM.shape[1]))
                _csr_accumulate(self._local[k], PM, Y)
                out.append(Y.reshape((n,) + P.shape[1:]))
            else:
                out.append(None)
        return tuple(out)

    def pullback(self, dY, dY1, dY2) -> np.ndarray:
        """Chain rule through the spline: dE/dP = W^T dE/dY + W1^T dE/dY' + W2^T dE/dY'' (docs/design.md).

        Args:
            dY, dY1, dY2: (n, nq) or None.
        Returns:
            (m, nq).
        """
        nq = next(g for g in (dY, dY1, dY2) if g is not None).shape[1]
        if not self.banded:
            out = np.zeros((len(self.knots), nq))
            for M, g in zip(self._B3, (dY, dY1, dY2)):
                if g is not None:
                    out += M.T @ g
            return out
        G = np.zeros((2 * len(self.knots), nq))
        for LT, g in zip(self._local_T, (dY, dY1, dY2)):
            if g is not None:
                _csr_accumulate(LT, g, G)
        return self._moments_transpose(G)

    def bending_hessian(self, w) -> np.ndarray:
        """`gram(2, w)` = W2^T diag(w) W2; w = 2 h: the Hessian of integral |Y''|^2 dt per component."""
        return self.gram(2, w)

    def gram(self, order: int, w) -> np.ndarray:
        """W_k^T diag(w) W_k (m, m) for k = `order` (0: values, 2: second derivatives) without forming
        W_k on a banded basis: O(n + m^2) work and memory.

        W_k = L_k [I; S] with L_k the local map (n, 2m; 2 or 4 entries per row) and S = [0; T^-1 R; 0]
        the moments. A = L_k^T diag(w) L_k is banded (O(n) to build); with its blocks A_PP, A_PM, A_MM
        (values / moments): W_k^T diag(w) W_k = A_PP + A_PM S + S^T A_PM^T + S^T A_MM S, where S X and
        S^T X are tridiagonal solves (O(m) per column). Y'' reads only the moments (A_PP = A_PM = 0):
        R^T T^-1 A_MM T^-1 R.

        Args:
            order: 0 or 2. w: quadrature weight of each point [s], (n,) or a scalar.
        Returns:
            (m, m) symmetric positive semidefinite [s (order 0); 1/s^3 (order 2), times the unit of w / s].
        Raises:
            ValueError: order not 0 or 2.
        """
        if order not in (0, 2):
            raise ValueError(f"gram order must be 0 or 2, got {order}")
        w = np.broadcast_to(np.asarray(w, dtype=float), self.t.shape)
        m = len(self.knots)
        if not self.banded:
            Wk = self._B3[order]
            return (Wk.T * w) @ Wk
        L = self._local[order]
        A = (L.T.multiply(w[None, :]) @ L).tocsr()  # (2m, 2m) banded
        G = A[:m, :m].toarray()
        if m >= 3:
            X = self._solve(self._R_dense())  # T^-1 R (m-2, m): S's interior rows
            A_MM = A[m + 1:2 * m - 1, m + 1:2 * m - 1]
            SMS = self._R_transpose(self._solve(np.ascontiguousarray(A_MM @ X)))  # S^T A_MM S
            if order == 0:
                PMS = np.asarray(A[:m, m + 1:2 * m - 1] @ X)  # A_PM S
                G += PMS + PMS.T
            G += SMS
        return 0.5 * (G + G.T)

    def _R_dense(self) -> np.ndarray:
        """R (m-2, m) with R y = 6 (second divided differences), as in `moment_matrix`."""
        m, inv = len(self.knots), 6.0 / self._h
        R = np.zeros((m - 2, m))
        i = np.arange(m - 2)
        R[i, i] = inv[:-1]
        R[i, i + 1] = -inv[:-1] - inv[1:]
        R[i, i + 2] = inv[1:]
        return R
