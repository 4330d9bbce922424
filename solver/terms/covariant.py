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

    Beyond the paper (DESIGN.md, objective terms table): eq. 9's f2 acts on the spline's q itself, and a
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

    Args:
        quat_slots: (s, 4) qpos indices of the quaternions.
    """

    name = "covariant_normalized"
    units = "1/s^4"
    needs = (0, 1, 2)

    def __init__(self, quat_slots: np.ndarray):
        self.idx = np.asarray(quat_slots, dtype=int).reshape(-1, 4)
        self._single = self.idx.shape[0] == 1 and np.array_equal(self.idx[0], np.arange(4))

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        if self._single and Y.shape[1] == 4:  # the single-body problem: no gather/scatter
            q, q1, q2 = Y[:, None, :], Y1[:, None, :], Y2[:, None, :]
        else:
            q, q1, q2 = Y[:, self.idx], Y1[:, self.idx], Y2[:, self.idx]
        r = 1.0 / np.sqrt(np.einsum("nsi,nsi->ns", q, q))[..., None]  # 1/s
        u, v, a = q * r, q1 * r, q2 * r
        uv = np.einsum("nsi,nsi->ns", u, v)[..., None]
        w = a - 2.0 * uv * v
        uw = np.einsum("nsi,nsi->ns", u, w)[..., None]
        A = w - uw * u
        f = np.einsum("nsi,nsi->n", A, A)
        if not grad:
            return TermEval(f)
        Av = np.einsum("nsi,nsi->ns", A, v)[..., None]
        gv = -4.0 * (Av * u + uv * A)
        gu = -2.0 * uw * w - 4.0 * Av * v
        c = (np.einsum("nsi,nsi->ns", gu, u) + 2.0 * np.einsum("nsi,nsi->ns", A, a)
             + np.einsum("nsi,nsi->ns", gv, v))[..., None]
        dq, dq1, dq2 = (gu - c * u) * r, gv * r, 2.0 * A * r
        if self._single and Y.shape[1] == 4:
            return TermEval(f, dY=dq[:, 0], dY1=dq1[:, 0], dY2=dq2[:, 0])
        dY, dY1, dY2 = np.zeros_like(Y), np.zeros_like(Y), np.zeros_like(Y)
        dY[:, self.idx], dY1[:, self.idx], dY2[:, self.idx] = dq, dq1, dq2
        return TermEval(f, dY=dY, dY1=dY1, dY2=dY2)
