"""No jolts: the pelvis and every ball joint accelerate no harder than the reference motion does at its hardest.

    |x''_pelvis(t)| <= A_pelvis   [m/s^2],     |alpha_j(t)| <= A_j   [rad/s^2]   at every point,

alpha_j the joint's angular acceleration (MuJoCo's `qacc` of a ball joint, in the child's frame) and A
the larger of the reference's own peak (the plain spline through the keyframes) and, when the keyframes
come from a capture, the capture's peak after the low-pass filter biomechanics applies before
differentiating captured kinematics (6 Hz, Winter 2009; `solver.peak_bounds.filter_capture`). The
eye sees a jolt as an acceleration the motion it was given never has; the measure of change
(`solver.change`) then picks the least change among the paths that have none.

Written smooth as c = (|a|^2 - A^2) / (2 A) (zero at |a| = A with slope 1 in |a| there, no kink at a = 0).
"""
from __future__ import annotations

import numpy as np

from solver.constraints.base import RELATIVE, Constraint
from solver.curvature import Curvature

__all__ = ["AccelerationBound"]


class AccelerationBound(Constraint):
    """|a_j(t)| <= A_j for acceleration columns j (pelvis linear, ball joints' angular) at every point.

    Args:
        n_points: quadrature points. dofs: (j, 3) qvel indices of each column. limits: (j,) A_j > 0 [m/s^2 or
            rad/s^2]. tolerance: (j,) [same units]. labels: (j,) column names. linear: (j,) bool, the columns
            of a linear acceleration [m/s^2] (the others angular [rad/s^2]); None: none.
    """

    name, unit, scale = "acceleration", "m/s^2 | rad/s^2", 1.0
    priority = RELATIVE

    def __init__(self, n_points: int, dofs: np.ndarray, limits: np.ndarray, tolerance: np.ndarray, labels,
                 linear=None):
        self.dofs = np.asarray(dofs, int).reshape(-1, 3)
        j = len(self.dofs)
        named = np.asarray(labels, object).reshape(j)
        self._linear = set(named[np.zeros(j, bool) if linear is None else np.asarray(linear, bool)].tolist())
        self.limits = np.asarray(limits, float).reshape(j)
        self.rows = np.repeat(np.arange(n_points), j)
        self._cols = np.tile(np.arange(j), n_points)
        self.tolerance = np.asarray(tolerance, float).reshape(j)[self._cols]
        self.labels = np.asarray(labels, object)[self._cols]
        self.limit = np.zeros(len(self.rows))  # the smooth form's own bound is 0 (module docstring)

    def column_unit(self, label: str) -> str:
        """m/s^2 for a linear column (the pelvis), rad/s^2 for a joint's."""
        return "m/s^2" if label in self._linear else "rad/s^2"

    def _accelerations(self, state):
        """(n, j, 3) the bounded accelerations at the points."""
        return state.motion.qacc[:, self.dofs]

    def measure(self, state):
        a = self._accelerations(state)
        return (((a * a).sum(-1) - self.limits ** 2) / (2.0 * self.limits)).ravel()

    def excess(self, measure, limit, pairs):
        """|a| - |a|_limit [m/s^2 or rad/s^2] at `pairs`: the smooth form c = (|a|^2 - A^2) / (2 A) inverted,
        |a| = sqrt(A^2 + 2 A c) (module docstring)."""
        A = self.limits[self._cols[pairs]]
        def magnitude(m):
            return np.sqrt(np.maximum(A * A + 2.0 * A * m[pairs], 0.0))
        return magnitude(measure) - magnitude(limit)

    def pull(self, state, g):
        n = state.motion.qacc.shape[0]
        G = g.reshape(n, -1) / self.limits  # (n, j)
        if not G.any():
            return
        ga = np.zeros(state.motion.qacc.shape)
        ga[:, self.dofs] = G[..., None] * self._accelerations(state)
        state.add_acceleration(ga)

    def curvature(self, state, d1, d2):
        """c = (|a|^2 - A^2) / (2 A) in the column's qacc: grad c = a / A, c's Hessian I / A (exact), so
        K = d2 (a / A)(a / A)^T + (d1 / A) I on its three components, at the pairs where d1 or d2 > 0."""
        live = np.flatnonzero((d1 > 0) | (d2 > 0))
        if not live.size:
            return []
        pts, col = self.rows[live], self._cols[live]
        A = self.limits[col]
        u = self._accelerations(state)[pts, col] / A[:, None]
        K = d2[live, None, None] * u[:, :, None] * u[:, None, :] + (d1[live] / A)[:, None, None] * np.eye(3)
        return [Curvature(pts, self.dofs[col], {2: np.broadcast_to(np.eye(3), (len(live), 3, 3))}, K)]
