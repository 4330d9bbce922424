"""The C2 natural cubic spline through frames, as a linear map of the frame values.

Paper eq. 2-6: the spline Y(t) through frame values P at knot times t_m is linear in P. At fixed
sample times (the quadrature points) Y = W P, Y' = W1 P, Y'' = W2 P with W, W1, W2 of shape (n, m),
built once per frame set (eq. 6: the matrix [Phi] is inverted once). End conditions are *natural*
(Y'' = 0 at both ends, docs/design.md "The spline"): with them, inserting a frame at a segment midpoint with
the value the path already has there leaves the path unchanged, so subdivision never makes the
result worse.

The matrices come straight from the spline's moments (second derivatives at the knots), M = S y with
S = A^-1 R from the tridiagonal system A M = R y of a natural cubic spline (LAPACK dgtsv via scipy;
de Boor, A Practical Guide to Splines, ch. IV): on segment [x_k, x_k+1] of length h, with a = x_k+1 - t,
b = t - x_k,

    Y(t) = (a y_k + b y_k+1) / h + ((a^3/h - a h) M_k + (b^3/h - b h) M_k+1) / 6,

so each row of W, W1, W2 is two unit entries plus two rows of S. It is the interpolant
`make_interp_spline(knots, y, k=3, bc_type="natural")` gives (tests/test_spline.py compares them), built
1.3-2x faster than from it (measured 24-760 points, 7-40 frames). `solver.spline_basis.SplineBasis`
holds these maps for one frame set and evaluates them densely or through the tridiagonal system.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgtsv

from solver.errors import InputError


def _check_knots(knots: np.ndarray) -> np.ndarray:
    knots = np.asarray(knots, dtype=float)
    if knots.ndim != 1 or len(knots) < 2:
        raise InputError(f"spline knots must be a 1-D array of at least 2 times, got shape {knots.shape}")
    if not np.all(np.isfinite(knots)) or np.any(np.diff(knots) <= 0):
        raise InputError(f"spline knots must be finite and strictly increasing, got {knots.tolist()}")
    return knots


def moment_matrix(knots: np.ndarray) -> np.ndarray:
    """S with M = S y: the natural cubic spline's second derivatives at the knots from the values there.

    Args:
        knots: (m,) frame times [s], strictly increasing (unchecked), m >= 2.
    Returns:
        S (m, m) [1/s^2]; rows 0 and m-1 are zero (natural ends); all zero for m = 2 (a straight line).
    """
    x = np.asarray(knots, dtype=float)
    m = len(x)
    S = np.zeros((m, m))
    if m < 3:
        return S
    h = np.diff(x)
    inv = 6.0 / h
    R = np.zeros((m - 2, m))  # 6 * divided differences: R[i-1] y = 6 ((y_i+1 - y_i)/h_i - (y_i - y_i-1)/h_i-1)
    i = np.arange(m - 2)
    R[i, i] = inv[:-1]
    R[i, i + 1] = -inv[:-1] - inv[1:]
    R[i, i + 2] = inv[1:]
    # A M = R y, A tridiagonal: h_i-1 M_i-1 + 2 (h_i-1 + h_i) M_i + h_i M_i+1 (interior rows); LAPACK's
    # tridiagonal solver (what solve_banded does for bandwidth 1, without its ~10 us of checks)
    diag = 2.0 * (h[:-1] + h[1:])
    if m == 3:
        S[1] = R[0] / diag[0]
        return S
    off = h[1:-1]
    *_, sol, info = dgtsv(off, diag, off.copy(), R, overwrite_b=True)
    if info != 0:  # A is strictly diagonally dominant for increasing knots; cannot happen
        raise ValueError(f"natural spline system is singular (LAPACK dgtsv info={info})")
    S[1:-1] = sol
    return S


def _moments(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """M = moment_matrix(x) @ y for values y (m, nq), solved for directly (no (m, m) matrix)."""
    m = len(x)
    M = np.zeros_like(y)
    if m < 3:
        return M
    h = np.diff(x)
    d = np.diff(y, axis=0) / h[:, None]
    r = 6.0 * (d[1:] - d[:-1])  # (m-2, nq)
    diag = 2.0 * (h[:-1] + h[1:])
    if m == 3:
        M[1] = r[0] / diag[0]
        return M
    off = h[1:-1]
    *_, sol, info = dgtsv(off, diag, off.copy(), r, overwrite_b=True)
    if info != 0:
        raise ValueError(f"natural spline system is singular (LAPACK dgtsv info={info})")
    M[1:-1] = sol
    return M


def _segments(x: np.ndarray, t: np.ndarray):
    """Segment index k of each time (the end segments extend beyond the knots, like scipy's splines),
    a = x_k+1 - t, b = t - x_k and h = x_k+1 - x_k."""
    k = np.clip(np.searchsorted(x, t, side="right") - 1, 0, len(x) - 2)
    h = x[k + 1] - x[k]
    return k, x[k + 1] - t, t - x[k], h


def spline_matrices(knots: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """W, W1, W2 with Y(t) = W P, Y'(t) = W1 P, Y''(t) = W2 P (paper eq. 6).

    Args:
        knots: (m,) frame times [s].
        t: (n,) sample times [s], inside [knots[0], knots[-1]] (outside: the end cubics continued).
    Returns:
        W (n, m) [1], W1 (n, m) [1/s], W2 (n, m) [1/s^2].
    Raises:
        InputError: knots not strictly increasing or fewer than 2.
    """
    B = _stacked_matrices(_check_knots(knots), np.asarray(t, dtype=float).reshape(-1))
    return B[0], B[1], B[2]


def _stacked_matrices(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(3, n, m): W, W1, W2 of `spline_matrices` in one array (knots x already checked)."""
    S = moment_matrix(x)
    k, a, b, h = _segments(x, t)
    ih = 1.0 / h
    # coefficients of S[k] and S[k+1] in each row of W, W1, W2; then the two unit (linear) entries
    ca = np.stack([(a * a * ih - h) * a / 6.0, (h - 3.0 * a * a * ih) / 6.0, a * ih])[:, :, None]
    cb = np.stack([(b * b * ih - h) * b / 6.0, (3.0 * b * b * ih - h) / 6.0, b * ih])[:, :, None]
    Sk, Sk1 = S[k], S[k + 1]
    if Sk.size < 8192:  # small (orientation): whole-array products
        B = ca * Sk
        B += cb * Sk1
    else:  # large (the figure at 400 Hz): no (3, n, m) temporaries - fresh large blocks cost page faults
        B = np.empty((3,) + Sk.shape)
        scratch = np.empty_like(Sk)
        for j in range(3):
            np.multiply(ca[j], Sk, out=B[j])
            B[j] += np.multiply(cb[j], Sk1, out=scratch)
    r = np.arange(len(t))
    B[0, r, k] += a * ih
    B[0, r, k + 1] += b * ih
    B[1, r, k] -= ih
    B[1, r, k + 1] += ih
    return B


def interpolate(frame_times: np.ndarray, frames: np.ndarray, t: np.ndarray, nu: int | tuple = 0):
    """Evaluate the natural cubic spline through frames (or its nu-th derivative) at times t.

    Args:
        frame_times: (m,) [s]. frames: (m, nq). t: (n,) [s]. nu: derivative order >= 0 (0 beyond 3;
            the third derivative is piecewise constant, taken from the segment to the right of a knot),
            or a tuple of orders (the spline's moments are then solved for once).
    Returns:
        (n, nq) values [units of frames / s^nu]; a tuple of them for a tuple nu.
    Raises:
        InputError: knots not strictly increasing or fewer than 2.
    """
    x = _check_knots(frame_times)
    y = np.asarray(frames, dtype=float)
    t = np.asarray(t, dtype=float)
    shape = t.shape + y.shape[1:]
    y = y.reshape(len(x), -1)
    M = _moments(x, y)  # (m, nq) second derivatives at the knots
    orders = nu if isinstance(nu, tuple) else (nu,)
    tt = t.reshape(-1)
    out = [np.empty((tt.size, y.shape[1])) for _ in orders]
    # blocks of samples: the gathered rows and the temporaries of a block stay in a core's cache (a
    # long path's whole (n, nq) temporaries do not: a limit check samples 17 s at 4000 Hz)
    rows = max(64, BLOCK_DOUBLES // max(1, y.shape[1]))
    for s0 in range(0, tt.size, rows):
        sl = slice(s0, s0 + rows)
        k, a, b, h = _segments(x, tt[sl])
        a, b, h = a[:, None], b[:, None], h[:, None]
        yk, yk1, Mk, Mk1 = y[k], y[k + 1], M[k], M[k + 1]
        for o, order in zip(out, orders):
            o[sl] = _order(order, a, b, h, yk, yk1, Mk, Mk1)
    out = [o.reshape(shape) for o in out]
    return tuple(out) if isinstance(nu, tuple) else out[0]


#: [doubles] Doubles (points x components) per block of points on long paths, here and in the pointwise terms
#: (`Term.pointwise`, more than 4 blocks' worth; shorter paths are evaluated whole): a block's arrays
#: (128 KB each; 321 points of the figure's 51 components) and a term's temporaries stay in a core's L2
#: cache, a long clip's do not. Run-and-step's gait tiled 8x (5440 points): 60-65 -> 54-60 ms per
#: evaluation (6-11%; blocks of 128-1024 points within noise of each other; 2 MB L2; docs/scaling.md).
BLOCK_DOUBLES = 1 << 14


def _order(order, a, b, h, yk, yk1, Mk, Mk1):
    """The spline's `order`-th derivative at samples with a = x_k+1 - t, b = t - x_k, h (n, 1) between
    values yk, yk1 and moments Mk, Mk1 (n, nq) (the cubic's Hermite-moment form: de Boor, *A
    Practical Guide to Splines*, ch. IV)."""
    if order == 0:
        return (a * yk + b * yk1) / h + ((a * a / h - h) * a * Mk + (b * b / h - h) * b * Mk1) / 6.0
    if order == 1:
        return (yk1 - yk) / h + ((h - 3.0 * a * a / h) * Mk + (3.0 * b * b / h - h) * Mk1) / 6.0
    if order == 2:
        return (a * Mk + b * Mk1) / h
    if order == 3:
        return (Mk1 - Mk) / h
    return np.zeros_like(yk)


def interpolate_segments(frame_times: np.ndarray, frames: np.ndarray, nodes: np.ndarray, nu: int | tuple = 0):
    """The natural cubic spline through frames at the same relative positions of every segment.

    The same values as `interpolate` at times t_k + nodes * (t_k+1 - t_k), k = 0..m-2 (segment by
    segment), computed as one small product per order: with tau the node, a segment's value is
    (1 - tau) y_k + tau y_k+1 + h^2 (((1 - tau)^3 - (1 - tau)) M_k + (tau^3 - tau) M_k+1) / 6, so the
    node weights are shared by all segments (no per-sample gathers; ~10x faster than `interpolate` for
    dense sampling).

    Args:
        frame_times: (m,) [s]. frames: (m, nq). nodes: (J,) in [0, 1]. nu: order 0..3 or a tuple.
    Returns:
        ((m-1) * J, nq) [units of frames / s^nu], segment-major; a tuple of them for a tuple nu.
    Raises:
        InputError: knots not strictly increasing or fewer than 2.
    """
    x = _check_knots(frame_times)
    y = np.asarray(frames, dtype=float).reshape(len(x), -1)
    tau = np.asarray(nodes, dtype=float).reshape(-1)
    M = _moments(x, y)
    h = np.diff(x)[:, None]
    s = 1.0 - tau
    out = []
    for order in (nu if isinstance(nu, tuple) else (nu,)):
        if order == 0:
            phi = np.stack([s, tau, (s**3 - s) / 6.0, (tau**3 - tau) / 6.0])
            coef = (y[:-1], y[1:], h * h * M[:-1], h * h * M[1:])
        elif order == 1:
            phi = np.stack([-np.ones_like(tau), np.ones_like(tau), (1.0 - 3.0 * s * s) / 6.0, (3.0 * tau * tau - 1.0) / 6.0])
            coef = (y[:-1] / h, y[1:] / h, h * M[:-1], h * M[1:])
        elif order == 2:
            phi = np.stack([s, tau])
            coef = (M[:-1], M[1:])
        elif order == 3:
            phi = np.stack([-np.ones_like(tau), np.ones_like(tau)])
            coef = (M[:-1] / h, M[1:] / h)
        else:
            phi, coef = np.zeros((1, len(tau))), (np.zeros_like(y[:-1]),)
        C = np.stack(coef)  # (c, m-1, nq)
        r = (phi.T @ C.reshape(len(C), -1)).reshape(len(tau), len(x) - 1, -1)  # (J, m-1, nq)
        out.append(r.transpose(1, 0, 2).reshape(-1, y.shape[1]))
    return tuple(out) if isinstance(nu, tuple) else out[0]
