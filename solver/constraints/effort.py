"""No more effort than the motion it was given: the path's RMS joint torque at most the reference's.

    sqrt( (1/T) integral sum_j |tau_j(t)|^2 dt )  <=  B      [N m]

tau_j the generalized force of joint j (every joint but the free root: a ball joint's three components
in the child's frame) that the contact-free inverse dynamics asks for (M(q) qacc + c(q, qvel), MuJoCo's
`mj_inverse` without contacts; `solver.inverse_dynamics`, paper appendix A eq. 18-21), T the path's
length, and B the larger of the plain spline's figure and, when the keyframes come from a motion
capture, the capture's after the 6 Hz low-pass filter biomechanics applies before differentiating
captured kinematics (Winter 2009, ch. 2; `solver.peak_bounds.filter_capture`). It is the field's effort
measure (the RMS joint torque of the acceptance bounds, `runner.jolts`) held as a limit, as the no-jolt
bounds hold the peak accelerations (`solver.constraints.acceleration`): the measure of change prices
a change of acceleration by the mass matrix, which does not see the gravity and velocity terms of the
torque, so a path may meet its contacts by a change that is cheap in acceleration and costly in
torque (a leg held out from the body through a stance).

One integral constraint: one pair standing for the path's whole length.
"""
from __future__ import annotations

import numpy as np

from solver.constraints.base import RELATIVE, Constraint
from solver.curvature import Outer

__all__ = ["TorqueRMS", "rms_torque"]


def rms_torque(tau: np.ndarray, weights: np.ndarray, dofs: np.ndarray) -> float:
    """sqrt(sum_i w_i |tau_i[dofs]|^2 / sum_i w_i) [N m] of generalized forces tau (n, nv) at quadrature
    weights (n,) [s]."""
    part = tau[:, dofs]
    return float(np.sqrt(weights @ np.einsum("ij,ij->i", part, part) / weights.sum()))


class TorqueRMS(Constraint):
    """The RMS joint torque of the path <= B [N m] (module docstring).

    Args:
        weights: (n,) the quadrature weights [s]. dofs: (d,) qvel indices of the joints (the root's left
            out). bound: B [N m] > 0. tolerance: [N m] > 0.
    """

    name, unit, scale = "effort", "N m", 1.0
    priority = RELATIVE

    def __init__(self, weights: np.ndarray, dofs: np.ndarray, bound: float, tolerance: float):
        self.w = np.asarray(weights, float)
        self.T = float(self.w.sum())
        self.dofs = np.asarray(dofs, int)
        self.rows = np.array([len(self.w) // 2])
        self.labels = np.array(["RMS joint torque"], object)
        self.limit = np.array([float(bound)])
        self.tolerance = float(tolerance)

    def pair_weights(self, weights):
        """The one pair stands for the whole path [s]."""
        return np.array([float(np.sum(weights))])

    def measure(self, state):
        return np.array([rms_torque(state.tau, self.w, self.dofs)])

    def pull(self, state, g):
        if not g.any():
            return
        r = rms_torque(state.tau, self.w, self.dofs)
        if r <= 0.0:
            return
        gt = np.zeros(state.tau.shape)
        gt[:, self.dofs] = (float(g[0]) * self.w / (self.T * r))[:, None] * state.tau[:, self.dofs]
        state.add_tau(gt)

    def curvature(self, state, d1, d2):
        """d2 grad c grad c^T (an `Outer`: the one pair spans every point); the RMS's own curvature is left out."""
        n = len(self.w)
        return [Outer(self, np.arange(n), np.zeros(n, int), d2)] if d2[0] > 0 else []
