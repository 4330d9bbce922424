"""One evaluation's path at the quadrature points, what is computed from it, and the adjoints that flow back.

The objective and every constraint read the same things: the path Y, Y', Y'' (the spline at the
quadrature points, paper eq. 6), MuJoCo's `qvel` and `qacc` of it (`solver.kinematics.PathMotion`), and
the contact sites' positions and velocities (`solver.kinematic_tree.SiteKinematics`, paper appendix A
eq. 13 and 19) and, with an inverse-dynamics engine (`solver.inverse_dynamics.InverseDynamics`), the
generalized forces that make the motion (appendix A eq. 18-21). `PathState` computes each once per evaluation; every function adds its gradient to the
state's adjoints (with respect to Y, Y', Y'' directly, to qacc and the pose in MuJoCo's tangent space, to
the site positions and velocities), and `pullback` runs each reverse pass once for their sum.
"""
from __future__ import annotations

import numpy as np

from solver.kinematics import TangentMap

__all__ = ["PathState", "add_at"]


def add_at(target: np.ndarray, index: tuple, values: np.ndarray) -> None:
    """target[index] += values with repeated indices summed, as np.add.at, by one np.bincount per trailing
    component over the flat positions (np.add.at is unbuffered, several times slower on the pulls' sizes).

    Args:
        target: the array changed in place (a non-contiguous one goes through np.add.at). index: integer
            arrays (broadcast together) for its leading axes. values: broadcast to the selection's shape,
            then target's trailing axes.
    """
    sel = np.broadcast_arrays(*index)
    lead, tail = target.shape[:len(sel)], target.shape[len(sel):]
    if not target.flags.c_contiguous:
        np.add.at(target, tuple(sel), values)
        return
    flat = np.ravel_multi_index(sel, lead).ravel()
    m = int(np.prod(tail))
    vals = np.broadcast_to(values, sel[0].shape + tail).reshape(-1, m)
    view = target.reshape(-1, m)
    for j in range(m):
        view[:, j] += np.bincount(flat, vals[:, j], minlength=view.shape[0])


class PathState:
    """The path of one evaluation and its adjoints (module docstring).

    Args:
        t: (n,) quadrature times [s]. Y, Y1, Y2: (n, nq) the path and its first and second derivatives.
        tmap: the model's TangentMap. engine: a `SiteKinematics` of the contact sites, an
            `InverseDynamics` (sites and forces), or None.
    Attributes:
        motion: `PathMotion` (qvel, qacc (n, nv) and their reverse pass).
    """

    def __init__(self, t: np.ndarray, Y: np.ndarray, Y1: np.ndarray, Y2: np.ndarray, tmap: TangentMap,
                 engine=None):
        self.t, self.Y, self.Y1, self.Y2 = t, Y, Y1, Y2
        self.motion = tmap.motion(Y, Y1, Y2)
        self.engine = engine
        self._res = None
        n, nq = Y.shape
        self.gY = np.zeros((n, nq))
        self.gY1 = np.zeros((n, nq))
        self.gY2 = np.zeros((n, nq))
        self.g_acc: np.ndarray | None = None
        self.g_sites: np.ndarray | None = None
        self.g_site_vel: np.ndarray | None = None
        self.g_tau: np.ndarray | None = None
        #: what a function computes for its value and reuses for its gradient (keyed by the function)
        self.cache: dict = {}

    def forward_pass(self):
        """The engine's forward pass at the points (`InverseDynamics.forward`: site positions, torques when
        the engine computes forces), made once per state and shared by every constraint that reads it and
        by the reverse pass (`pullback`)."""
        if self._res is None:
            qvel = np.ascontiguousarray(self.motion.qvel)
            if self.engine.forces:
                self._res = self.engine.forward(self.Y, qvel, np.ascontiguousarray(self.motion.qacc))
            else:
                self._res = self.engine.forward(self.Y, qvel)
        return self._res

    @property
    def tau(self) -> np.ndarray:
        """(n, nv) generalized forces [N, N m] that make the motion (contact-free `mj_inverse`); needs an
        inverse-dynamics engine."""
        return self.forward_pass().tau

    @property
    def sites(self) -> np.ndarray:
        """(n, k, 3) world positions [m] of the engine's sites."""
        return self.forward_pass().sites

    @property
    def site_velocities(self) -> np.ndarray:
        """(n, k, 3) world velocities [m/s] of the engine's sites."""
        return self.engine.site_velocities(self.forward_pass())

    def add_acceleration(self, g: np.ndarray) -> None:
        """Add g (n, nv) = d f / d qacc."""
        self.g_acc = g.copy() if self.g_acc is None else self.g_acc + g

    def add_tau(self, g: np.ndarray) -> None:
        """Add g (n, nv) = d f / d tau."""
        self.g_tau = g.copy() if self.g_tau is None else self.g_tau + g

    def add_sites(self, g_pos: np.ndarray | None, g_vel: np.ndarray | None = None) -> None:
        """Add d f / d site positions and velocities, each (n, k, 3) or None."""
        if g_pos is not None:
            self.g_sites = g_pos.copy() if self.g_sites is None else self.g_sites + g_pos
        if g_vel is not None:
            self.g_site_vel = g_vel.copy() if self.g_site_vel is None else self.g_site_vel + g_vel

    def pullback(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(dY, dY1, dY2), each (n, nq): the sum of every adjoint added, pulled back to the path."""
        dY, dY1, dY2 = self.gY.copy(), self.gY1.copy(), self.gY2.copy()
        g_pose = g_vel = None
        g_acc = self.g_acc
        if self.g_sites is not None or self.g_site_vel is not None or self.g_tau is not None:
            res = self.forward_pass()
            z = np.zeros(res.sites.shape)
            g_pose, g_vel, g_qacc = self.engine.vjp(res, self.g_tau, z if self.g_sites is None else self.g_sites,
                                                    z if self.g_site_vel is None else self.g_site_vel)
            if g_qacc is not None and self.g_tau is not None:
                g_acc = g_qacc if g_acc is None else g_acc + g_qacc
        if g_pose is not None or g_vel is not None or g_acc is not None:
            a, b, c = self.motion.vjp(g_vel, g_acc, g_pose)
            dY += a
            dY1 += b
            dY2 += c
        return dY, dY1, dY2
