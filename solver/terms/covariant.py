"""Covariant acceleration of quaternion paths (paper eq. 9, f2; Barr et al. 1992)."""
from __future__ import annotations

import numpy as np

from solver.terms.base import Term, TermEval


class CovariantAcceleration(Term):
    """f2 = sum over quaternion slots of |q'' - q (q''.q)/(q.q)|^2 [1/s^4] (paper eq. 9 and eq. 25).

    The acceleration with its radial component removed; = q''.q'' - (q''.q)^2/(q.q). Gradients as in
    appendix B: df/dq'' = 2 (q'' - q a/b), df/dq = 2 (q a^2/b^2 - q'' a/b), a = q''.q, b = q.q.
    Optionally adds the squared linear acceleration of `linear_index` components (e.g. the root
    position, [m^2/s^4]) so one term smooths the whole figure.

    Args:
        quat_slots: (s, 4) qpos indices of the quaternions.
        linear_index: (l,) qpos indices whose plain acceleration |y''|^2 is added (default none).
    """

    name = "covariant"
    units = "1/s^4"
    needs = (0, 2)
    #: [1] d^2/d(y'')^2 of |y''|^2 per linear component, and per tangential quaternion direction
    acceleration_curvature = 2.0
    pointwise = True

    def __init__(self, quat_slots: np.ndarray, linear_index: np.ndarray | None = None):
        self.idx = np.asarray(quat_slots, dtype=int).reshape(-1, 4)
        self.lin = np.asarray([] if linear_index is None else linear_index, dtype=int)

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        q, q2 = Y[:, self.idx], Y2[:, self.idx]
        a = np.einsum("nsi,nsi->ns", q2, q)
        b = np.einsum("nsi,nsi->ns", q, q)
        f = (np.einsum("nsi,nsi->ns", q2, q2) - a * a / b).sum(axis=1)
        y2 = Y2[:, self.lin]
        f = f + (y2 * y2).sum(axis=1)
        if not grad:
            return TermEval(f)
        r = (a / b)[..., None]
        dY, dY2 = np.zeros_like(Y), np.zeros_like(Y)
        dY2[:, self.idx] = 2.0 * (q2 - q * r)
        dY[:, self.idx] = 2.0 * (q * r * r - q2 * r)
        dY2[:, self.lin] = 2.0 * y2
        return TermEval(f, dY=dY, dY2=dY2)

class NormalizedCovariantAcceleration(Term):
    """f2 of the orientation actually shown: |A|^2 with A the covariant acceleration of u = q/|q| [1/s^4].

    Beyond the paper (docs/design.md, the objective table): eq. 9's f2 acts on the spline's q itself, and a
    polynomial spline cannot stay on the unit sphere, so shrinking q lowers that f2. Here f2 is the
    covariant acceleration of the normalized path u = q/|q| (what MuJoCo shows), which is scale-free
    (f(c q) = f(q) for any c != 0); a unit term must then hold the scale of q near 1.

    With s = |q|, u = q/s, v = q'/s, a = q''/s and the tangent projector P = I - u u^T:

        u' = P v,  A = u'' - u (u''.u) = P (a - 2 (u.v) v),   f = |A|^2 = |w|^2 - (u.w)^2,  w = a - 2 (u.v) v.

    (From q = s u: q'' = s'' u + 2 s' u' + s u'', s' = u.q'.) Gradients, with g_w = 2 A:
        df/dq'' = 2 A / s
        df/dq'  = -4 ((A.v) u + (u.v) A) / s
        df/dq   = (g_u - (g_u.u + 2 A.a + g_v.v) u) / s,  g_u = -2 (u.w) w - 4 (A.v) v,  g_v = s df/dq'
    (f is homogeneous of degree 0 in (q, q', q''): q.df/dq + q'.df/dq' + q''.df/dq'' = 0.)

    Computed from the Gram matrix of (q, q', q''), which f depends on alone: with a = q.q, b = q.q',
    c = q.q'', d = q'.q', e = q'.q'', g = q''.q'', p = 1/a, m = u.w = (c - 2 b^2 p) p,

        f = (g - 4 b p e + 4 b^2 p^2 d) p - m^2,

    and the gradient is df/dX_i = sum_j C_ij X_j with X = (q, q', q''), C_ii = 2 df/dG_ii and
    C_ij = df/dG_ij: two small einsums and a few operations on (n,) arrays instead of some thirty
    operations on (n, 4) arrays (the same values and gradients as the vector form above, which the
    tests check against finite differences).

    Args:
        quat_slots: (s, 4) qpos indices of the quaternions.
    """

    name = "covariant_normalized"
    units = "1/s^4"
    needs = (0, 1, 2)
    acceleration_curvature = 2.0  # [1] of |A|^2 on a unit quaternion's tangent directions
    pointwise = True

    def __init__(self, quat_slots: np.ndarray):
        self.idx = np.asarray(quat_slots, dtype=int).reshape(-1, 4)
        self._single = self.idx.shape[0] == 1 and np.array_equal(self.idx[0], np.arange(4))

    @property
    def single_quaternion(self) -> bool:
        """True if the term's one quaternion fills qpos 0-3 (the orientation problem)."""
        return self._single

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        single = self._single and Y.shape[1] == 4  # the single-body problem: no gather/scatter
        if single:
            X = np.stack((Y, Y1, Y2))  # (3, n, 4)
        else:
            X = np.stack((Y[:, self.idx], Y1[:, self.idx], Y2[:, self.idx]))  # (3, n, s, 4)
        G = np.einsum("a...i,b...i->ab...", X, X)
        a, b, c, d, e, g = G[0, 0], G[0, 1], G[0, 2], G[1, 1], G[1, 2], G[2, 2]
        p = 1.0 / a
        bp = b * p
        m = (c - 2.0 * b * bp) * p  # u.w
        f = (g - 4.0 * bp * e + 4.0 * bp * bp * d) * p - m * m
        if not single:
            f = f.sum(axis=1)
        if not grad:
            return TermEval(f)
        pp = p * p
        C = np.empty_like(G)
        C[0, 0] = (-2.0 * pp) * (g - 8.0 * bp * e + 12.0 * bp * bp * d - 2.0 * m * (c - 4.0 * b * bp))
        C[0, 1] = C[1, 0] = (-4.0 * e + 8.0 * bp * d + 8.0 * m * b) * pp
        C[0, 2] = C[2, 0] = -2.0 * m * p
        C[1, 1] = 8.0 * bp * bp * p
        C[1, 2] = C[2, 1] = -4.0 * bp * p
        C[2, 2] = 2.0 * p
        D = np.einsum("ab...,b...i->a...i", C, X)
        if single:
            return TermEval(f, dY=D[0], dY1=D[1], dY2=D[2])
        dY, dY1, dY2 = np.zeros_like(Y), np.zeros_like(Y), np.zeros_like(Y)
        dY[:, self.idx], dY1[:, self.idx], dY2[:, self.idx] = D[0], D[1], D[2]
        return TermEval(f, dY=dY, dY1=dY1, dY2=dY2)

def unit_and_normalized(X: np.ndarray, w: np.ndarray, c_unit: float, c_cov: float, grad: bool = True):
    """`UnitQuaternion` and `NormalizedCovariantAcceleration` of one quaternion filling the state (the
    orientation problem), weighted and integrated in one pass over the Gram matrix of (q, q', q'').

    The same values and gradients as the two terms' `evaluate` weighted by the objective, with the
    Gram form of `NormalizedCovariantAcceleration` rewritten in u = b/a and the entries over a (with
    p = 1/a: m = c p - 2 u^2, f2 = g p - 4 u e p + 4 u^2 d p - m^2, C = p K with K free of p), and
    f1 = (1 - a)^2 read off the Gram matrix too (its gradient -4 (1 - a) q adds to C_00). One Gram
    product, one gradient product and ~30 operations on (n,) arrays, component-major (einsum on (n, 4)
    rows was 2x slower here; on the component-major (3, 4, n) the two products are einsums, ~15 us
    faster per call at 144 points than broadcast-and-sum, with the same bits); `Objective.evaluate_path`
    takes this path when its terms are these two (docs/orient.md).

    Args:
        X: (3, 4, n) q, q', q'' at the quadrature points, component-major.
        w: (n,) quadrature weights [s].
        c_unit, c_cov: each term's weight over its scale (lambda_j / s_j).
        grad: compute the gradient.
    Returns:
        (integral of f1 [s], integral of f2 [1/s^3], dE/dX (3, 4, n) of E = c_unit I1 + c_cov I2, or None).
    """
    G = np.einsum("ain,bin->abn", X, X)  # (3, 3, n): a = q.q, b = q.q', c = q.q'', d, e, g
    a = G[0, 0]
    p = 1.0 / a
    Gp = G * p
    u, cp, dp, ep, gp = Gp[0, 1], Gp[0, 2], Gp[1, 1], Gp[1, 2], Gp[2, 2]
    uu = u * u
    m = cp - 2.0 * uu  # u.w of the class docstring
    f2 = gp - 4.0 * u * ep + 4.0 * uu * dp - m * m
    eu = 1.0 - a
    I1, I2 = float(w @ (eu * eu)), float(w @ f2)
    if not grad:
        return I1, I2, None
    C = np.empty_like(G)
    C[0, 0] = -2.0 * (gp - 8.0 * u * ep + 12.0 * uu * dp - 2.0 * m * (cp - 4.0 * uu))
    C[0, 1] = C[1, 0] = 8.0 * (u * dp + m * u) - 4.0 * ep
    C[0, 2] = C[2, 0] = -2.0 * m
    C[1, 1] = 8.0 * uu
    C[1, 2] = C[2, 1] = -4.0 * u
    C[2, 2] = 2.0
    C *= (c_cov * w) * p
    C[0, 0] -= (4.0 * c_unit) * (w * eu)
    return I1, I2, np.einsum("abn,bin->ain", C, X)
