"""Strong-form Euler-Lagrange residual of the quaternion objective (paper sec. 3, eq. 10-11; appendix B).

For E = integral lambda (1 - q.q)^2 + |q'' - q (q''.q)/(q.q)|^2 dt (eq. 25), with a = q.q'', b = q.q,
T = a/b, the Euler-Lagrange equation (eq. 24 applied per component, halved) is

    X + d^2/dt^2 Y + Z = 0,   X = q T^2 - q'' T,   Y = q'' - q T,   Z = 2 lambda (b - 1) q      (eq. 10)
    d^2/dt^2 Y = q'''' - (q'' T + 2 q' T' + q T'')                                              (eq. 11)

The left-hand side EL(t) is what this module computes. As the paper does, T' and T'' are obtained by
numerical differentiation of T (five-point stencils kept inside one spline segment, where T is smooth);
q, q', q'' and q'''' come from the path. On a cubic spline q'''' = 0 inside each segment; the jumps of
q''' at the knots are delta functions in d^2Y/dt^2 that this strong form, evaluated pointwise, does not
see (the weak form of `solver.subdivide` does).

With ``normalized=True`` the residual is evaluated on the orientation shown, u = q/|q| (unit, so b = 1
and Z = 0), and only its tangential part is returned: the radial part of eq. 10 on a unit path is the
Lagrange multiplier of |u| = 1, and the tangential part vanishes exactly on the natural Riemannian cubic
spline, the optimum of the normalized objective (`solver.paper.orient`).

Units: [1/s^4].
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from solver.errors import InputError

#: default numerical-differentiation step, relative to the segment length
STEP = 1e-2


def el_lhs(q, q1, q2, q4, T1, T2, unit_weight: float = 0.0) -> np.ndarray:
    """Left-hand side of eq. 10 from the path's derivatives and T', T''.

    Args:
        q, q1, q2, q4: (n, 4) q, q', q'', q'''' [1, 1/s, 1/s^2, 1/s^4].
        T1, T2: (n,) T' and T'' with T = (q.q'')/(q.q) [1/s^3, 1/s^4].
        unit_weight: lambda of the unit term f1 relative to f2 (plain weights) [1/s^4].
    Returns:
        (n, 4) X + Y'' + Z [1/s^4].
    """
    b = np.einsum("ni,ni->n", q, q)
    T = np.einsum("ni,ni->n", q, q2) / b
    X = q * (T * T)[:, None] - q2 * T[:, None]
    Ydd = q4 - (q2 * T[:, None] + 2.0 * q1 * T1[:, None] + q * T2[:, None])
    Z = (2.0 * unit_weight * (b - 1.0))[:, None] * q
    return X + Ydd + Z


def normalized_derivatives(q, q1, q2, q3, q4) -> tuple[np.ndarray, ...]:
    """u = q/|q| and its first four derivatives from those of q (Leibniz rule with g = (q.q)^-1/2).

    Args:
        q, q1, q2, q3, q4: (n, 4) q and its derivatives.
    Returns:
        u, u', u'', u''', u'''' each (n, 4).
    """
    d = lambda a, c: np.einsum("ni,ni->n", a, c)  # noqa: E731
    n0 = d(q, q)
    n1 = 2 * d(q, q1)
    n2 = 2 * (d(q1, q1) + d(q, q2))
    n3 = 2 * (3 * d(q1, q2) + d(q, q3))
    n4 = 2 * (3 * d(q2, q2) + 4 * d(q1, q3) + d(q, q4))
    f1, f2, f3, f4 = (-0.5 * n0**-1.5, 0.75 * n0**-2.5, -1.875 * n0**-3.5, 6.5625 * n0**-4.5)
    g = [n0**-0.5, f1 * n1, f2 * n1**2 + f1 * n2, f3 * n1**3 + 3 * f2 * n1 * n2 + f1 * n3,
         f4 * n1**4 + 6 * f3 * n1**2 * n2 + f2 * (3 * n2**2 + 4 * n1 * n3) + f1 * n4]
    qs = [q, q1, q2, q3, q4]
    binom = [[1], [1, 1], [1, 2, 1], [1, 3, 3, 1], [1, 4, 6, 4, 1]]
    return tuple(sum(binom[k][j] * g[j][:, None] * qs[k - j] for j in range(k + 1)) for k in range(5))


def _stencil_weights(offsets: np.ndarray) -> np.ndarray:
    """Weights (n, 2, 5) of the 1st and 2nd derivative at 0 from values at 5 offsets (n, 5) [units of
    offsets]: solves the Vandermonde (Taylor) system per point."""
    k = np.arange(5)
    fact = np.array([1.0, 1.0, 2.0, 6.0, 24.0])
    V = offsets[:, None, :] ** k[None, :, None] / fact[None, :, None]  # (n, 5 powers, 5 nodes)
    rhs = np.zeros((len(offsets), 5, 2))
    rhs[:, 1, 0] = 1.0
    rhs[:, 2, 1] = 1.0
    return np.swapaxes(np.linalg.solve(V, rhs), 1, 2)


def residual(
    path: Callable[[np.ndarray, int], np.ndarray],
    t: np.ndarray,
    breaks: np.ndarray,
    *,
    unit_weight: float = 0.0,
    normalized: bool = False,
    step: float = STEP,
) -> np.ndarray:
    """EL(t), the left-hand side of eq. 10, on a path with T' and T'' by numerical differentiation.

    Args:
        path: path(t, nu) -> (n, 4), the nu-th derivative of q at times t, for nu = 0..4 (a cubic
            spline returns zeros for nu = 4; `FrameSet.path` does).
        t: (n,) times [s] inside [breaks[0], breaks[-1]].
        breaks: (m,) times where the path may be non-smooth (spline knots); stencils stay between them.
        unit_weight: lambda of f1 relative to f2 (plain weights) [1/s^4]; ignored if normalized.
        normalized: evaluate on u = q/|q| and return the tangential part (see the module docstring).
        step: differentiation step relative to the segment length.
    Returns:
        (n, 4) residual [1/s^4].
    Raises:
        InputError: times outside the breaks, or breaks not increasing.
    """
    t = np.asarray(t, float).reshape(-1)
    br = np.asarray(breaks, float)
    if br.ndim != 1 or len(br) < 2 or np.any(np.diff(br) <= 0):
        raise InputError("breaks must be at least 2 strictly increasing times")
    if t.size and (t.min() < br[0] or t.max() > br[-1]):
        raise InputError(f"residual times must lie in [{br[0]}, {br[-1]}] s")
    j = np.clip(np.searchsorted(br, t, side="right") - 1, 0, len(br) - 2)
    a, hseg = br[j], np.diff(br)[j]
    delta = step * hseg
    base = np.clip(t - 2 * delta, a, a + hseg - 4 * delta)
    nodes = base[:, None] + delta[:, None] * np.arange(5)[None, :]  # (n, 5), inside the segment

    def derivs(tt):
        q = [path(tt, nu) for nu in range(5)]
        return normalized_derivatives(*q) if normalized else tuple(q)

    # T at the stencil nodes, each node evaluated as a member of its own point's segment
    flat = nodes.ravel()
    dn = derivs(flat)
    Tn = (np.einsum("ni,ni->n", dn[0], dn[2]) / np.einsum("ni,ni->n", dn[0], dn[0])).reshape(nodes.shape)
    w = _stencil_weights((nodes - t[:, None]) / delta[:, None])
    T1 = np.einsum("nk,nk->n", w[:, 0], Tn) / delta
    T2 = np.einsum("nk,nk->n", w[:, 1], Tn) / delta**2
    d = derivs(t)
    if normalized:
        el = el_lhs(d[0], d[1], d[2], d[4], T1, T2, 0.0)
        u = d[0]
        return el - u * np.einsum("ni,ni->n", u, el)[:, None]
    return el_lhs(d[0], d[1], d[2], d[4], T1, T2, unit_weight)


def spline_residual(frame_times, frames, t, **kwargs) -> np.ndarray:
    """`residual` of the natural cubic spline through frames (a `FrameSet`'s path): (n,) -> (n, 4).

    Args:
        frame_times: (m,) [s]. frames: (m, 4). t: (n,) [s]. kwargs: see `residual`.
    """
    from solver.spline import interpolate

    ft = np.asarray(frame_times, float)
    P = np.asarray(frames, float)
    if P.ndim != 2 or P.shape[1] != 4 or len(P) != len(ft):
        raise InputError(f"frames must have shape (m={len(ft)}, 4), got {P.shape}")
    return residual(lambda tt, nu: interpolate(ft, P, tt, nu), t, ft, **kwargs)


def deviation_by_region(frame_times, frames, n_regions: int = 10, samples: int = 200, **kwargs) -> np.ndarray:
    """integral |EL(t)| dt over n_regions equal parts of the path (figure 10: "the integrated deviation
    over equal tenths of the path").

    Midpoint rule with `samples` points per region (the integrand is piecewise smooth).

    Args:
        frame_times: (m,) [s]. frames: (m, 4). n_regions: parts. kwargs: see `residual`.
    Returns:
        (n_regions,) [1/s^3].
    """
    ft = np.asarray(frame_times, float)
    edges = np.linspace(ft[0], ft[-1], n_regions + 1)
    h = (edges[1] - edges[0]) / samples
    t = (edges[:-1, None] + h * (np.arange(samples)[None, :] + 0.5)).ravel()
    el = np.linalg.norm(spline_residual(ft, frames, t, **kwargs), axis=1)
    return h * el.reshape(n_regions, samples).sum(axis=1)
