"""Knees and elbows bending the wrong way (paper sec. 5: "elbows and knees should not bend backward")."""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.figure import shipped_figure
from solver.quaternion import hinge_angle, twist_angle_grad
from solver.terms.base import Term, TermEval


def flexion_angles(Y: np.ndarray, quat_index: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Flexion angle of each hinge-like ball joint: the twist about its flexion axis [rad].

    theta = 2 atan2(v.axis, w) on the quaternion taken with w >= 0 (swing-twist decomposition).

    Args:
        Y: (n, nq) qpos. quat_index: (j, 4) qpos indices of the joints. axes: (j, 3) unit axes.
    Returns:
        (n, j) angles [rad]; negative = hyperextension.
    """
    q = Y[:, quat_index]
    return np.stack([hinge_angle(q[:, k], axes[k]) for k in range(len(axes))], axis=1)


class Hyperextension(Term):
    """f = sum over joints of max(0, -theta - tol)^2 [rad^2]: bending past straight the wrong way.

    theta is the flexion angle (`flexion_angles`); tol >= 0 a tolerance [rad]. C1 in theta.

    Args:
        layout: StateLayout of the figure.
        hinges: {joint name: flexion axis (3,)}: the figure's `Figure.flexion_axes` (default: the
            shipped figure's knees and elbows).
        tolerance: [rad] hyperextension allowed without penalty (default 0).
    Raises:
        InputError: a joint name that is not a ball joint of the layout.
    """

    name = "bending"
    units = "rad^2"
    needs = (0,)
    pointwise = True

    def __init__(self, layout, hinges: dict | None = None, tolerance: float = 0.0):
        hinges = shipped_figure().flexion_axes if hinges is None else hinges
        idx, axes = [], []
        for name, axis in hinges.items():
            j = layout.joint(name)
            if j.kind != "ball":
                raise InputError(f"bending term: joint {name!r} is a {j.kind} joint; it needs a ball joint")
            idx.append(j.quat_index)
            a = np.asarray(axis, float)
            axes.append(a / np.linalg.norm(a))
        self.joint_names = list(hinges)
        self.idx = np.array(idx, int).reshape(-1, 4)
        self.axes = np.array(axes).reshape(-1, 3)
        self.tol = float(tolerance)

    def angles(self, Y: np.ndarray) -> np.ndarray:
        """(n, j) flexion angles [rad] of the term's joints."""
        return flexion_angles(Y, self.idx, self.axes)

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        theta = self.angles(Y)
        h = np.maximum(0.0, -theta - self.tol)
        f = (h * h).sum(axis=1)
        if not grad:
            return TermEval(f)
        dY = np.zeros_like(Y)
        for k in range(len(self.axes)):
            active = h[:, k] > 0
            if active.any():
                g = twist_angle_grad(Y[active][:, self.idx[k]], self.axes[k])
                dY[np.ix_(active, self.idx[k])] += (-2.0 * h[active, k])[:, None] * g
        return TermEval(f, dY=dY)

