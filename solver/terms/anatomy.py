"""Anatomical limits as soft constraints (paper sec. 5: "overflexing of joint angles"): knees and elbows
that turn as hinges (`Hinge`), every ball joint inside a published range of motion (`RangeOfMotion`).
Hyperextension of knees and elbows is `solver.terms.bending`.

Both are penalties on the excess beyond an allowed set, squared (C1, like the bending term), of angles
of the joints' swing-twist decomposition (`solver.terms.anatomy_table`). Each allowed set is widened to
what a reference path shows - the plain spline through the keyframes (`TermBuild.plain_samples`) - so
that neither term penalizes what the keyframes themselves hold (they are met exactly: penalty
continuation could not move them), and the plain spline has no violation: the terms only keep the
optimizer from going further than the keyframes do (docs/anatomy.md).
"""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.quaternion import swing_angle_grad
from solver.terms.anatomy_table import motion_angle_grads, motion_angles, motion_axes, off_hinge_angles, range_of_motion
from solver.terms.base import OneSided, Residual, Term, TermEval

__all__ = ["DEFAULT_ALLOWANCE", "Hinge", "PLAIN_RATE", "RangeOfMotion", "WIDEN_MARGIN", "plain_samples"]

#: [rad] rotation off the hinge allowed without penalty where the reference shows less (2 degrees: the
#: acceptance bound is the capture's + 3 degrees, and the continuation limit 0.5 degree on top of this)
DEFAULT_ALLOWANCE = float(np.radians(2.0))
#: [1/s] samples per second of the reference path the allowances are widened by
PLAIN_RATE = 1000.0
#: [rad] margin on a limit widened to the reference's own extreme (0.1 degree): the reference is sampled
#: at PLAIN_RATE, the objective's quadrature points fall between the samples, and a plain spline over its
#: widened limit by 1e-10 rad there would give the term a plain-spline integral of 1e-19, and eq. 7 a
#: weight of 1e19 (the optimizer fails at once)
WIDEN_MARGIN = float(np.radians(0.1))


def _quat_index(layout, name: str, term: str) -> np.ndarray:
    j = layout.joint(name)
    if j.kind != "ball":
        raise InputError(f"{term} term: joint {name!r} is a {j.kind} joint; it needs a ball joint")
    return np.asarray(j.quat_index, int)


class Hinge(Term):
    """f = sum over knees and elbows of max(0, phi - a_j)^2 [rad^2]: rotation off the hinge.

    phi is the swing angle of the joint's quaternion about its flexion axis (`swing_angle`, the
    swing-twist decomposition: 0 for a pure rotation about the axis); a_j the joint's allowance:
    max(`allowance`, the largest phi of the joint on `reference` + WIDEN_MARGIN). C1 in phi; where the term is
    active phi > a_j > 0, where phi is differentiable.

    Args:
        layout: StateLayout of the figure. hinges: {joint name: flexion axis (3,)} (`Figure.flexion_axes`).
        allowance: [rad] > 0, the allowance where the reference shows less (default DEFAULT_ALLOWANCE).
        reference: optional (n, nq) qpos samples of a reference path (the plain spline).
    Raises:
        InputError: a joint that is not a ball joint, an allowance that is not > 0.
    """

    name = "hinge"
    units = "rad^2"
    needs = (0,)
    pointwise = True

    def __init__(self, layout, hinges: dict, allowance: float = DEFAULT_ALLOWANCE, reference=None):
        if not np.isfinite(allowance) or allowance <= 0:
            raise InputError(f"hinge term: allowance {allowance} rad; it must be > 0 (e.g. {DEFAULT_ALLOWANCE:.4f})")
        self.joint_names = list(hinges)
        self.idx = np.array([_quat_index(layout, n, "hinge") for n in hinges], int).reshape(-1, 4)
        axes = np.array([np.asarray(hinges[n], float) for n in hinges]).reshape(-1, 3)
        self.axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
        self.allowance = np.full(len(self.axes), float(allowance))
        if reference is not None and len(reference) and len(self.axes):
            own = self.angles(np.asarray(reference, float)).max(axis=0)
            self.allowance = np.maximum(self.allowance, own + WIDEN_MARGIN)

    def angles(self, Y: np.ndarray) -> np.ndarray:
        """(n, j) rotation off the hinge [rad] of the term's joints."""
        return off_hinge_angles(Y, self.idx, self.axes)

    def violation(self, Y: np.ndarray) -> float:
        """Largest rotation off the hinge beyond a joint's allowance [rad] (0 if none)."""
        if not len(self.axes):
            return 0.0
        return float(self._excess(Y).max())

    def _excess(self, Y):
        return np.maximum(0.0, self.angles(Y) - self.allowance)

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        h = self._excess(Y)
        f = (h * h).sum(axis=1)
        if not grad:
            return TermEval(f)
        dY = np.zeros_like(Y)
        dY[:, self.idx] = (2.0 * h)[..., None] * self._grads(Y, h)
        return TermEval(f, dY=dY)

    def _grads(self, Y, h):
        """(n, j, 4) d phi / dq where h > 0, else 0."""
        g = np.zeros(h.shape + (4,))
        rows, cols = np.nonzero(h > 0)
        if rows.size:
            g[rows, cols] = swing_angle_grad(Y[rows[:, None], self.idx[cols]], self.axes[cols])
        return g

    def residual(self, ctx) -> Residual:
        """r = max(0, phi - a_j) per joint (n, j) [rad] (f = |r|^2); dense blocks dr/dY = d phi/dq where
        the joint is past its allowance (`swing_angle_grad`), 0 elsewhere; `OneSided` phi - a_j."""
        Y = ctx.Y
        signed = self.angles(Y) - self.allowance
        r = np.maximum(0.0, signed)
        J = np.zeros((len(Y), len(self.axes), Y.shape[1]))
        g = self._grads(Y, r)
        for k in range(len(self.axes)):
            J[:, k, self.idx[k]] = g[:, k]

        def grad(rows, cols):
            return swing_angle_grad(Y[rows[:, None], self.idx[cols]], self.axes[cols])

        return Residual(r, blocks=(J, None, None), one_sided=OneSided(signed, self.idx, grad))


class RangeOfMotion(Term):
    """f = sum over bounded motions of (x - clip(x, lo, hi))^2 [rad^2]: joints outside their range.

    x is each motion's angle (`anatomy_table.motion_angles`: a twist about the segment or a signed
    swing), [lo, hi] its published range (`anatomy_table.range_of_motion`, AAOS 1965) widened to the
    angles `reference` shows (and WIDEN_MARGIN beyond). C1 in x.

    Args:
        layout: StateLayout of the figure. figure: its `solver.figure.Figure`.
        reference: optional (n, nq) qpos samples of a reference path (the plain spline).
        motions: the bounded motions (default `range_of_motion(figure)`).
    Raises:
        InputError: a motion's joint that is not a ball joint of the layout.
    """

    name = "rom"
    units = "rad^2"
    needs = (0,)
    pointwise = True

    def __init__(self, layout, figure, reference=None, motions=None):
        motions = tuple(range_of_motion(figure) if motions is None else motions)
        self.idx = np.array([_quat_index(layout, m.joint, "rom") for m in motions], int).reshape(-1, 4)
        if reference is not None and len(reference) and motions:
            x = self.angles_of(np.asarray(reference, float), motions)
            lo, hi = x.min(axis=0) - WIDEN_MARGIN, x.max(axis=0) + WIDEN_MARGIN
            motions = tuple(m.widened(a, b) for m, a, b in zip(motions, lo, hi, strict=True))
        self.motions = motions
        self.arrays = motion_axes(motions)
        self.lo = np.array([m.lo for m in motions])
        self.hi = np.array([m.hi for m in motions])

    def angles_of(self, Y: np.ndarray, motions=None) -> np.ndarray:
        """(n, c) angles [rad] of the term's motions (or `motions`, in the term's joint order)."""
        if motions is None:
            return motion_angles(Y, self.idx, self.motions, self.arrays)
        return motion_angles(Y, self.idx, motions)

    def excess(self, Y: np.ndarray) -> np.ndarray:
        """(n, c) signed amount beyond the range [rad]: x - hi above it, x - lo below it, 0 inside."""
        x = self.angles_of(Y)
        return x - np.clip(x, self.lo, self.hi)

    def violation(self, Y: np.ndarray) -> float:
        """Largest angle beyond a joint's range [rad] (0 if every motion is inside)."""
        return float(np.abs(self.excess(Y)).max()) if len(self.motions) else 0.0

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        r = self.excess(Y)
        f = (r * r).sum(axis=1)
        if not grad:
            return TermEval(f)
        dY = np.zeros_like(Y)
        rows, cols = np.nonzero(r)
        if rows.size:
            g = (2.0 * r[rows, cols])[:, None] * motion_angle_grads(Y, self.idx, self.motions, rows, cols, self.arrays)
            np.add.at(dY, (rows[:, None], self.idx[cols]), g)
        return TermEval(f, dY=dY)

    def residual(self, ctx) -> Residual:
        """r = x - clip(x, lo, hi) per motion (n, c) [rad] (f = |r|^2); dense blocks dr/dY = dx/dq where
        the motion is outside its range, 0 elsewhere; `OneSided` max(x - hi, lo - x), the signed
        distance past the nearer limit (r = +-max(0, it))."""
        Y = ctx.Y
        x = self.angles_of(Y)
        r = x - np.clip(x, self.lo, self.hi)
        signed = np.maximum(x - self.hi, self.lo - x)
        upper = x - self.hi >= self.lo - x

        def grad(rows, cols):
            sign = np.where(upper[rows, cols], 1.0, -1.0)[:, None]
            return sign * motion_angle_grads(Y, self.idx, self.motions, rows, cols, self.arrays)

        one_sided = OneSided(signed, self.idx, grad)
        J = np.zeros((len(Y), len(self.motions), Y.shape[1]))
        rows, cols = np.nonzero(r)
        if rows.size:
            J[rows[:, None], cols[:, None], self.idx[cols]] = motion_angle_grads(Y, self.idx, self.motions, rows, cols,
                                                                                 self.arrays)
        return Residual(r, blocks=(J, None, None), one_sided=one_sided)


def plain_samples(plain, rate: float = PLAIN_RATE) -> np.ndarray:
    """(n, nq) the path of a FrameSet at `rate` samples per second from its first to its last frame,
    the frames' own times included (a keyframe's pose exactly)."""
    t0, t1 = float(plain.times[0]), float(plain.times[-1])
    t = np.union1d(np.linspace(t0, t1, int(round((t1 - t0) * rate)) + 1), plain.times)
    return plain.path(t)
