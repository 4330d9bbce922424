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
