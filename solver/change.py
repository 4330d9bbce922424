"""The measure of change: how much a path differs from the reference motion, in units that price a jolt.

    D(Y) = integral of  (a - a_ref)^T M (a - a_ref)  +  omega^4 (dq)^T P (dq)  dt    [kg m^2 / s^3]

a, a_ref: MuJoCo's `qacc` of the path and of the reference (`solver.reference.ReferenceMotion`); dq: the
pose difference in MuJoCo's tangent space (root position difference; for each quaternion the rotation
vector 2 vec(conj(u_ref) u) of the unit quaternions, exact to first order); M: the joint-space mass
matrix on the reference (a fixed metric: the path differs from the reference by centimetres, and M
changes little over that). The first part is the mass-weighted change of the generalized
accelerations: changing the pelvis's acceleration by 1 m/s^2 costs the whole body's mass, a hand's
the hand's, so a solve buys a foot's contact with the leg rather than with a jolt of the body. It is
the spacetime-constraints objective of Witkin & Kass ("Spacetime constraints", SIGGRAPH 1988), measured
as a change from a motion to keep, as Gleicher poses motion editing ("Motion editing with spacetime
constraints", I3D 1997).

The pose part P is diagonal. The root's position and orientation keep their own inertia (diag(M): the
body's mass, its inertia about the pelvis): moving the whole figure is priced by what it moves. Every
articulated joint's rotation (ball and hinge joints) is priced alike, by the mean of their diag(M) at
that point: a pose is seen by its joint angles, which is what an animator keys and what the field's
joint-angle error measures, and Gleicher's displacement norm weights every parameter alike. Weighted by
its own inertia instead, an ankle's rotation cost about a hundredth of a hip's, and a solve met every
foot contact by turning the ankles away from the motion to keep (docs/design.md, "The measure of
change"). The pose part makes the problem well posed where accelerations leave a change free (a partial
keyframe's free component at the path's ends may drift linearly); omega = pi / T for a path of length T
prices the slowest change a path pinned at both ends can make (a half sine over T) as much by its
displacement as by its acceleration, and every faster change less, so it does not compete with the
acceleration part anywhere else.

A clean of a capture (`solver.displacement`) gives its own pose metric instead of the diagonal P: the
mass matrix of the figure with its mass spread equally over its bodies (`pose`), which measures how far
the body's parts move, as a clean is judged.

Quadrature: the reference's points and weights (uniform, paper after eq. 7).
"""
from __future__ import annotations

import numpy as np

from solver.kinematics import TangentMap, _gq, _gt
from solver.path_state import PathState
from solver.reference import ReferenceMotion

__all__ = ["MeasureOfChange"]


class MeasureOfChange:
    """D (module docstring) with its gradient, on the quadrature points of `reference`.

    Args:
        reference: ReferenceMotion (points, weights, qpos, qacc, mass-matrix factors).
        tmap: the model's TangentMap.
        omega: [rad/s] the pose part's frequency; default pi / T.
        joints: (k,) qvel indices of the articulated joints' rotations (ball and hinge joints), priced
            alike by the pose part; default none (every degree of freedom by its own inertia).
        pose: None (the diagonal P above), or (n, nv, nv) the pose part's metric at the points, e.g. the
            bodies' displacement (`solver.reference.equal_mass_matrices`) [kg, kg m, kg m^2 by block].
    """

    units = "kg m^2/s^3"

    def __init__(self, reference: ReferenceMotion, tmap: TangentMap, omega: float | None = None,
                 joints: np.ndarray | None = None, pose: np.ndarray | None = None):
        self.ref = reference
        self.tmap = tmap
        self.omega = float(np.pi / reference.duration if omega is None else omega)
        self._qref = reference.qpos[:, tmap.quat_q].transpose(2, 1, 0)  # (4, s, n)
        self._uref = self._qref / np.linalg.norm(self._qref, axis=0)
        M = reference.chol @ reference.chol.transpose(0, 2, 1)  # (n, nv, nv) M(q_ref)
        w = reference.weights
        #: (nv, nv) the time-averaged mass matrix sum_i w_i M(q_ref,i) / sum_i w_i [kg m^2]: the
        #: preconditioner's and the refinement's curvature (`solver.lagrangian.Preconditioner`), made once
        self.mbar = np.tensordot(w, M, axes=1) / w.sum()
        if pose is None:
            self._M, self._MP = M, None
            self._P = np.einsum("nii->ni", M).copy()  # (n, nv) the pose part's diagonal P
            if joints is not None and len(joints):
                self._P[:, joints] = self._P[:, joints].mean(axis=1, keepdims=True)
            self.pbar = np.diag(w @ self._P / w.sum())  #: (nv, nv) the pose part's P averaged the same way [kg m^2]
        else:  # (n, 2, nv, nv): M and the pose metric P side by side, for one batched product in `evaluate`
            self._MP = np.stack([M, np.asarray(pose, float)], axis=1)
            self._M, self._P = self._MP[:, 0], self._MP[:, 1]  # views
            self.pbar = np.tensordot(w, self._P, axes=1) / w.sum()

    @property
    def mass(self) -> np.ndarray:
        """(n, nv, nv) M(q_ref) at the points [kg, kg m, kg m^2 by block]: the acceleration part's metric."""
        return self._M

    @property
    def pose_metric(self) -> np.ndarray:
        """(n, nv) the pose part's diagonal P, or (n, nv, nv) the metric given as `pose`: the pose part's
        metric at the points (times omega^4 in D)."""
        return self._P

    def _pose_difference(self, Y: np.ndarray):
        """(dq (n, nv), q (4, s, n), |q| (s, n)): the tangent-space pose difference from the reference."""
        tm = self.tmap
        n = len(Y)
        d = np.zeros((tm.nv, n))
        d[tm.lin_v] = (Y[:, tm.lin_q] - self.ref.qpos[:, tm.lin_q]).T
        q = Y[:, tm.quat_q].transpose(2, 1, 0)
        r = np.linalg.norm(q, axis=0)
        d[tm.quat_v.T] = 2.0 * _gq(self._uref, q) / r
        return d.T, q, r

    def evaluate(self, state: PathState, grad: bool = True) -> float:
        """D [kg m^2/s^3] on the state's path; with `grad` its gradient is added to the state's adjoints.

        Args:
            state: the evaluation's PathState at the reference's quadrature points.
            grad: add the gradient to `state`.
        """
        w = self.ref.weights
        dq, q, r = self._pose_difference(state.Y)
        X = np.stack([state.motion.qacc - self.ref.qacc, dq], axis=2)  # (n, nv, 2)
        if self._MP is None:  # M times the acceleration column only: the pose column's product is P dq
            MX = np.stack([(self._M @ X[:, :, :1])[:, :, 0], self._P * dq], axis=2)
        else:  # (n, 2, nv, nv) @ (n, 2, nv, 1): M (a - a_ref) and P dq in one batched product
            MX = np.matmul(self._MP, X.transpose(0, 2, 1)[..., None])[..., 0].transpose(0, 2, 1)
        w4 = self.omega ** 4
        e = np.einsum("nvk,nvk->nk", X, MX)  # (n, 2): (a - a_ref)^T M (a - a_ref), dq^T P dq
        D = float(w @ e[:, 0] + w4 * (w @ e[:, 1]))
        if grad:
            state.add_acceleration(2.0 * w[:, None] * MX[:, :, 0])
            g = 2.0 * w4 * w[:, None] * MX[:, :, 1]  # dD/d(dq) (n, nv)
            tm = self.tmap
            state.gY[:, tm.lin_q] += g[:, tm.lin_v]
            gq = g.T[tm.quat_v.T]  # (3, s, n)
            v = _gt(self._uref, gq) * (2.0 / r)  # G(u_ref)^T g * 2/|q|, then minus the radial part
            u = q / r
            v -= (v * u).sum(0) * u
            state.gY[:, tm.quat_q] += v.transpose(2, 1, 0)
        return D
