"""Unit quaternion soft constraint (paper eq. 9, f1)."""
from __future__ import annotations

import numpy as np

from solver.terms.base import Term, TermEval


class UnitQuaternion(Term):
    """f1 = sum over quaternion slots of (1 - q.q)^2 [1] (paper eq. 9).

    Args:
        quat_slots: (s, 4) qpos indices of the quaternions (`StateLayout.quat_slots`).
    """

    name = "unit"
    units = "1"
    needs = (0,)
    #: [1] d^2/dr^2 (1 - r^2)^2 = 12 r^2 - 4 = 8 at r = |q| = 1 (also its Gauss-Newton value 2 (2r)^2)
    radial_curvature = 8.0
    pointwise = True

    def __init__(self, quat_slots: np.ndarray):
        self.idx = np.asarray(quat_slots, dtype=int).reshape(-1, 4)
        self.radial_slots = self.idx
        self._single = self.idx.shape[0] == 1 and np.array_equal(self.idx[0], np.arange(4))

    @property
    def single_quaternion(self) -> bool:
        """True if the term's one quaternion fills qpos 0-3 (the orientation problem)."""
        return self._single

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        if self._single and Y.shape[1] == 4:  # the single-body problem: no gather/scatter
            e = 1.0 - np.einsum("ni,ni->n", Y, Y)
            return TermEval(e * e) if not grad else TermEval(e * e, dY=(-4.0 * e)[:, None] * Y)
        q = Y[:, self.idx]  # (n, s, 4)
        e = 1.0 - np.einsum("nsi,nsi->ns", q, q)
        f = (e * e).sum(axis=1)
        if not grad:
            return TermEval(f)
        dY = np.zeros_like(Y)
        dY[:, self.idx] = (-4.0 * e)[..., None] * q
        return TermEval(f, dY=dY)

