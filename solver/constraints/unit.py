"""Unit quaternions between the frames: | |q(t)| - 1 | <= UNIT_LIMIT at every point, for every ball joint
and the root.

Every frame's quaternions are unit (`solver.manifold` moves them on the sphere), but the spline between
two frames runs along the chord: two unit quaternions an angle theta apart give a midpoint of norm
cos(theta / 2). The path is normalized where it is used (MuJoCo, exports), so a short chord is not seen;
a long one is: the normalized path then speeds up and slows down within the segment (at a norm of 0.95,
by about 5 %). The bound keeps every segment's rotation under about 28 degrees (cos 14 deg = 0.97).
"""
from __future__ import annotations

import numpy as np

from solver.constraints.base import REPRESENTATION, Constraint
from solver.curvature import Curvature, quaternion_dofs

__all__ = ["UNIT_LIMIT", "UnitNorm"]

#: [1] how far a quaternion's norm may leave 1 between the frames: 0.03, a 3 % change of speed within
#: a segment once normalized; within the summary's 5 % mark on |1 - |q||
UNIT_LIMIT = 0.03


class UnitNorm(Constraint):
    """| |q| - 1 | <= UNIT_LIMIT at every (point, quaternion) (module docstring), written smooth as
    c = ((|q| - 1)^2 - UNIT_LIMIT^2) / (2 UNIT_LIMIT) (zero at the limit with slope 1 in | |q| - 1 |
    there, no kink at |q| = 1; as `solver.constraints.acceleration`).

    Args:
        n_points: quadrature points. quat_q: (s, 4) qpos indices of the quaternions. labels: (s,) names.
        tolerance: [1].
    """

    name, unit, scale = "unit", "1", 1.0
    priority = REPRESENTATION

    def __init__(self, n_points: int, quat_q: np.ndarray, labels, tolerance: float):
        self.quat_q = np.asarray(quat_q, int).reshape(-1, 4)
        s = len(self.quat_q)
        self.rows = np.repeat(np.arange(n_points), s)
        self.labels = np.asarray(labels, object)[np.tile(np.arange(s), n_points)]
        self.limit = np.zeros(len(self.rows))  # the smooth form's own bound is 0
        self.tolerance = float(tolerance)

    def measure(self, state):
        r = np.linalg.norm(state.Y[:, self.quat_q], axis=-1)  # (n, s)
        return (((r - 1.0) ** 2 - UNIT_LIMIT ** 2) / (2.0 * UNIT_LIMIT)).ravel()

    def pull(self, state, g):
        q = state.Y[:, self.quat_q]  # (n, s, 4)
        r = np.linalg.norm(q, axis=-1, keepdims=True)
        G = g.reshape(q.shape[:2])[..., None] * ((r - 1.0) / UNIT_LIMIT) * q / r
        state.gY[:, self.quat_q] += G  # each quaternion component once: no repeats

    def curvature(self, state, d1, d2):
        """d2 grad c grad c^T with grad c = ((|q| - 1) / UNIT_LIMIT) q / |q| in the quaternion's components (the
        norm's own curvature is left out)."""
        live = np.flatnonzero(d2 > 0)
        if not live.size:
            return []
        s = len(self.quat_q)
        rows, slot = live // s, live % s
        q = state.Y[rows[:, None], self.quat_q[slot]]  # (p, 4)
        r = np.linalg.norm(q, axis=1, keepdims=True)
        g = ((r - 1.0) / UNIT_LIMIT) * q / r
        support = quaternion_dofs(state.motion.tmap, self.quat_q[slot])
        return [Curvature(rows, support, {"qpos": g[:, None, :]}, d2[live, None, None], self.quat_q[slot])]
