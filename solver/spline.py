"""The C2 natural cubic spline through frames, as a linear map of the frame values.

Paper eq. 2-6: the spline Y(t) through frame values P at knot times t_m is linear in P. At fixed
sample times (the quadrature points) Y = W P, Y' = W1 P, Y'' = W2 P with W, W1, W2 of shape (n, m),
built once per frame set (eq. 6: the matrix [Phi] is inverted once). End conditions are *natural*
(Y'' = 0 at both ends, DESIGN.md "The spline"): with them, inserting a frame at a segment midpoint with
the value the path already has there leaves the path unchanged, so subdivision never makes the
result worse.

scipy builds the interpolant: `make_interp_spline(knots, I, k=3, bc_type="natural")` applied to the
identity columns gives the cardinal splines, i.e. the columns of W; `.derivative()` gives W1 and W2.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import BSpline, make_interp_spline

from solver.errors import InputError


def _check_knots(knots: np.ndarray) -> np.ndarray:
    knots = np.asarray(knots, dtype=float)
    if knots.ndim != 1 or len(knots) < 2:
        raise InputError(f"spline knots must be a 1-D array of at least 2 times, got shape {knots.shape}")
    if not np.all(np.isfinite(knots)) or np.any(np.diff(knots) <= 0):
        raise InputError(f"spline knots must be finite and strictly increasing, got {knots.tolist()}")
    return knots


def cardinal_spline(knots: np.ndarray) -> BSpline:
    """The natural cubic splines phi_j with phi_j(t_i) = delta_ij, as one vector-valued BSpline.

    Args:
        knots: (m,) frame times [s], strictly increasing, m >= 2.
    Returns:
        BSpline whose value at t is the (m,) row of W at t.
    Raises:
        InputError: knots not strictly increasing or fewer than 2.
    """
    knots = _check_knots(knots)
    if len(knots) == 2:  # a natural cubic through two points is the straight line
        return make_interp_spline(knots, np.eye(2), k=1)
    return make_interp_spline(knots, np.eye(len(knots)), k=3, bc_type="natural")


def spline_matrices(knots: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """W, W1, W2 with Y(t) = W P, Y'(t) = W1 P, Y''(t) = W2 P (paper eq. 6).

    Args:
        knots: (m,) frame times [s].
        t: (n,) sample times [s], inside [knots[0], knots[-1]].
    Returns:
        W (n, m) [1], W1 (n, m) [1/s], W2 (n, m) [1/s^2].
    """
    phi = cardinal_spline(knots)
    t = np.asarray(t, dtype=float)
    W = phi(t)
    W1 = phi.derivative(1)(t)
    W2 = phi.derivative(2)(t) if phi.k >= 2 else np.zeros_like(W)
    return W, W1, W2


def interpolate(frame_times: np.ndarray, frames: np.ndarray, t: np.ndarray, nu: int = 0) -> np.ndarray:
    """Evaluate the natural cubic spline through frames (or its nu-th derivative) at times t.

    Args:
        frame_times: (m,) [s]. frames: (m, nq). t: (n,) [s]. nu: derivative order 0..3.
    Returns:
        (n, nq) values [units of frames / s^nu].
    """
    knots = _check_knots(frame_times)
    frames = np.asarray(frames, dtype=float)
    if len(knots) == 2:
        spl = make_interp_spline(knots, frames, k=1)
    else:
        spl = make_interp_spline(knots, frames, k=3, bc_type="natural")
    if nu > spl.k:
        return np.zeros((len(np.atleast_1d(t)), frames.shape[1]))
    return spl.derivative(nu)(t) if nu else spl(t)


def quadrature_times(t0: float, t1: float, rate: float) -> tuple[np.ndarray, float]:
    """Uniform midpoint quadrature on [t0, t1] (paper, after eq. 7: "summing the values of the
    integrand at uniformly distributed points and multiplying by the time interval each represents").

    Args:
        t0, t1: interval [s]. rate: points per second [1/s].
    Returns:
        t: (n,) points [s], n = ceil((t1 - t0) * rate); h: weight of each point [s].
    """
    n = max(2, int(np.ceil((t1 - t0) * rate)))
    h = (t1 - t0) / n
    return t0 + h * (np.arange(n) + 0.5), h


@dataclass
class SplineBasis:
    """W, W1, W2 at fixed quadrature times for one frame set (built once per frame set).

    Attributes:
        knots: (m,) frame times [s]. t: (n,) quadrature times [s].
        W, W1, W2: (n, m) matrices (see `spline_matrices`).
    """

    knots: np.ndarray
    t: np.ndarray
    W: np.ndarray = field(init=False)
    W1: np.ndarray = field(init=False)
    W2: np.ndarray = field(init=False)

    def __post_init__(self):
        self.W, self.W1, self.W2 = spline_matrices(self.knots, self.t)

    def evaluate(self, P: np.ndarray, needs=(0, 1, 2)):
        """Y, Y', Y'' at the quadrature points (None for orders not in `needs`).

        Args:
            P: (m, nq) frame values.
        Returns:
            tuple of three (n, nq) arrays or None.
        """
        mats = (self.W, self.W1, self.W2)
        return tuple(mats[k] @ P if k in needs else None for k in range(3))

    def pullback(self, dY, dY1, dY2) -> np.ndarray:
        """Chain rule through the spline: dE/dP = W^T dE/dY + W1^T dE/dY' + W2^T dE/dY'' (DESIGN.md).

        Args:
            dY, dY1, dY2: (n, nq) or None.
        Returns:
            (m, nq).
        """
        out = np.zeros((self.W.shape[1], next(g for g in (dY, dY1, dY2) if g is not None).shape[1]))
        for M, g in ((self.W, dY), (self.W1, dY1), (self.W2, dY2)):
            if g is not None:
                out += M.T @ g
        return out
