"""Constraints on joint angles: knees and elbows turn as hinges, do not bend backwards, and every ball joint
stays inside its range of motion (paper sec. 5, "overflexing of joint angles"; docs/anatomy.md).

Each is an angle of a joint's swing-twist decomposition (`solver.terms.anatomy_table`) against a limit
per joint, at every quadrature point:

    hinge            off-hinge swing angle phi <= limit                                    [deg]
    hyperextension   -theta <= limit (theta the flexion angle: negative bends backwards)   [deg]
    range of motion  lo <= x <= hi for each bounded motion (AAOS 1965)                      [deg]

A limit is the anatomical one (a pure hinge, no hyperextension, the published range) widened so that the
keyframes, which are met exactly, meet it (`anatomy_constraints`): a hinge's to the largest swing of a
known path through them (the capture they came from, else the plain spline), hyperextension and range
of motion to what the reference motion itself shows at its worst; plus the constraint's tolerance where
the anatomical limit is 0: a hinge's swing angle is |swing|, not differentiable at 0, so its limit is
at least the tolerance.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from solver.constraints.base import Constraint
from solver.curvature import Curvature, quaternion_dofs
from solver.path_state import PathState, add_at
from solver.quaternion import swing_angle_grad, twist_angle_grad
from solver.terms.anatomy_table import motion_angle_grads, motion_angles, motion_axes, off_hinge_angles, range_of_motion
from solver.terms.bending import flexion_angles

__all__ = ["AngleBound", "anatomy_constraints"]


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

    def curvature(self, state: PathState, d1, d2):
        """d2 grad c grad c^T, grad c = sign d angle / d q in the joint quaternion's components; the angle's
        own curvature is left out."""
        on = np.flatnonzero(d2 > 0)
        if not on.size:
            return []
        rows, cols = self.rows[on], self._cols[on]
        g = self.grads(state.Y, rows, cols) * self.sign[cols, None]
        support = quaternion_dofs(state.motion.tmap, self.idx[cols])
        return [Curvature(rows, support, {"qpos": g[:, None, :]}, d2[on, None, None], self.idx[cols])]


def _witness_largest(angles, idx: np.ndarray, reference, plain, capture=None) -> np.ndarray:
    """(j,) the largest angles(Y) (n, j) [rad] of a known path through the keyframes: with a capture (times,
    qpos), the capture's at its frames and the keyframes' where they fix column j's quaternion (idx (j, 4));
    else the reference motion's own (the plain spline: no other path through them is known)."""
    if capture is None:
        return angles(reference.qpos).max(axis=0)
    keyed = np.flatnonzero(plain.is_keyframe)
    fixed = plain.fixed[keyed][:, idx].all(axis=2)  # (k, j)
    out = np.where(fixed, angles(plain.values[keyed]), -np.inf).max(axis=0, initial=-np.inf)
    return np.maximum(out, angles(np.asarray(capture[1], float)).max(axis=0))


def anatomy_constraints(figure, layout, reference, plain, capture, tolerances: dict) -> list:
    """The hinge, hyperextension and rom constraints of a figure's problem (module docstring).

    Args:
        figure: `solver.figure.Figure` (its flexion axes). layout: its StateLayout. reference:
            `ReferenceMotion` (the quadrature points, its qpos). plain: FrameSet of the plain spline (its
            keyframes). capture: (times (m,), qpos (m, nq)) the keyframes came from, or None. tolerances:
            {"hinge", "hyperextension", "rom": [rad]}.
    Returns:
        a list of `AngleBound`s, none for a figure without flexion axes or a range-of-motion table.
    """
    n = len(reference.t)
    Yr = reference.qpos
    out = []
    hinges = dict(figure.flexion_axes)
    if hinges:
        names = list(hinges)
        idx = np.array([layout.joint(j).quat_index for j in names], int).reshape(-1, 4)
        axes = np.array([hinges[j] for j in names], float).reshape(-1, 3)
        axes /= np.linalg.norm(axes, axis=1, keepdims=True)

        def off(Y, idx=idx, axes=axes):
            return off_hinge_angles(Y, idx, axes)

        def off_grad(Y, rows, cols, idx=idx, axes=axes):
            return swing_angle_grad(Y[rows[:, None], idx[cols]], axes[cols])

        tol = tolerances["hinge"]
        limits = np.maximum(_witness_largest(off, idx, reference, plain, capture), tol)
        out.append(AngleBound("hinge", n, off, off_grad, idx, limits, np.ones(len(names), bool), tol, names))

        def minus_flex(Y, idx=idx, axes=axes):
            return -flexion_angles(Y, idx, axes)

        def minus_flex_grad(Y, rows, cols, idx=idx, axes=axes):
            q = Y[rows[:, None], idx[cols]]
            sign = np.where(q[:, :1] < 0, -1.0, 1.0)
            return -sign * twist_angle_grad(q * sign, axes[cols])

        limits = np.maximum(minus_flex(Yr).max(axis=0), 0.0)
        out.append(AngleBound("hyperextension", n, minus_flex, minus_flex_grad, idx, limits,
                              np.ones(len(names), bool), tolerances["hyperextension"], names))
    motions = range_of_motion(figure)
    if motions:
        idx = np.array([layout.joint(m.joint).quat_index for m in motions], int).reshape(-1, 4)
        arrays = motion_axes(motions)

        def ang(Y, idx=idx, motions=motions, arrays=arrays):
            return motion_angles(Y, idx, motions, arrays)

        x = ang(Yr)
        hi = np.maximum([m.hi for m in motions], x.max(axis=0))
        lo = np.minimum([m.lo for m in motions], x.min(axis=0))
        both = np.concatenate([np.arange(len(motions))] * 2)
        upper = np.r_[np.ones(len(motions), bool), np.zeros(len(motions), bool)]
        keep = np.isfinite(np.r_[hi, lo])
        sel = both[keep]
        labels = [f"{m.joint} {m.motion}" for m in motions]

        def ang2(Y, sel=sel, ang=ang):
            return ang(Y)[:, sel]

        def ang2_grad(Y, rows, cols, sel=sel, idx=idx, motions=motions, arrays=arrays):
            return motion_angle_grads(Y, idx, motions, rows, sel[cols], arrays)

        out.append(AngleBound("rom", n, ang2, ang2_grad, idx[sel], np.r_[hi, lo][keep], upper[keep],
                              tolerances["rom"], np.array(labels, object)[sel]))
    return out
