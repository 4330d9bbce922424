"""Constraints on joint angles: knees and elbows turn as hinges, do not bend backwards, and every ball joint
stays inside its range of motion (paper sec. 5, "overflexing of joint angles"; docs/anatomy.md).

Each is an angle of a joint's swing-twist decomposition (`solver.terms.anatomy_table`) against a limit
per joint, at every quadrature point:

    hinge            off-hinge swing angle phi <= limit                                    [deg]
    hyperextension   -theta <= limit (theta the flexion angle: negative bends backwards)   [deg]
    range of motion  lo <= x <= hi for each bounded motion (AAOS 1965)                      [deg]

A limit is the anatomical one (a pure hinge, no hyperextension, the published range) widened to what the
reference motion itself shows at its worst (the keyframes are met exactly, so the optimized path can
never be held tighter than they are), plus the constraint's tolerance where the anatomical limit is 0:
a hinge's swing angle is |swing|, not differentiable at 0, so its limit is at least the tolerance.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from solver.constraints.base import Constraint
from solver.path_state import PathState, add_at

__all__ = ["AngleBound"]


class AngleBound(Constraint):
    """sign_j (x_j - limit_j) <= 0 for angles x (n, j) of a path, at every point and column.

    Args:
        name: the constraint's name. n_points: quadrature points. angles: Y (n, nq) -> (n, j) [rad].
        grads: (Y, rows (p,), cols (p,)) -> (p, 4) d angle / d q of column cols at point rows.
        idx: (j, 4) qpos indices of each column's joint quaternion. limits: (j,) [rad]. upper: (j,) bool:
            x <= limit (True) or x >= limit (False). tolerance: [rad]. labels: (j,) column names.
    """

    unit, scale = "deg", float(np.pi / 180.0)

    def __init__(self, name: str, n_points: int, angles: Callable, grads: Callable, idx: np.ndarray,
                 limits: np.ndarray, upper: np.ndarray, tolerance: float, labels):
        self.name = name
        self.angles, self.grads = angles, grads
        self.idx = np.asarray(idx, int).reshape(-1, 4)
        j = len(self.idx)
        self.sign = np.where(np.asarray(upper, bool).reshape(j), 1.0, -1.0)
        self.tolerance = float(tolerance)
        self.rows = np.repeat(np.arange(n_points), j)
        self._cols = np.tile(np.arange(j), n_points)
        self.limit = (self.sign * np.asarray(limits, float).reshape(j))[self._cols]
        self.labels = np.asarray(labels, object)[self._cols]

    def measure(self, state: PathState) -> np.ndarray:
        return (self.sign * self.angles(state.Y)).ravel()

    def pull(self, state: PathState, g: np.ndarray) -> None:
        on = np.flatnonzero(g)
        if not on.size:
            return
        rows, cols = self.rows[on], self._cols[on]
        d = self.grads(state.Y, rows, cols) * (g[on] * self.sign[cols])[:, None]
        add_at(state.gY, (rows[:, None], self.idx[cols]), d)
