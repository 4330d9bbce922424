"""The MuJoCo side of the inverse dynamics (`solver.inverse_dynamics`): the result both engines return,
the constraint-free copy of a model, and `MujocoInverseDynamics`, the engine computed by MuJoCo itself.

`MujocoInverseDynamics`: `mj_inverse` per sample for the values, `mjd_inverseFD` (finite differences
inside MuJoCo, 2 nv + 1 extra `mj_inverse` calls) and `mj_jacSite` for the gradients. General (any
joint types) but about 100x slower than the analytic `InverseDynamics`; the reference the tests compare
against. Both compute the contact-free inverse dynamics, tau = M(q) qacc + c(q, qvel) - qfrc_passive.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from solver.layout import site_ids


@dataclass
class InverseDynamicsResult:
    """Generalized forces (and contact-site positions) at n samples, from an engine's `forward`.

    Attributes:
        tau: (n, nv) generalized forces [N, N m] (MuJoCo's `qfrc_inverse` without constraint forces).
        sites: (n, k, 3) world positions of the engine's sites [m].
        qpos, qvel, qacc: the inputs (copies), (n, nq), (n, nv), (n, nv).
    """

    tau: np.ndarray
    sites: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    qacc: np.ndarray
    saved: dict = field(default_factory=dict, repr=False)

    def matches(self, qpos, qvel, qacc) -> bool:
        return all(
            a.shape == b.shape and np.array_equal(a, b)
            for a, b in ((self.qpos, qpos), (self.qvel, qvel), (self.qacc, qacc))
        )


def constraint_free_copy(model):
    """A copy of `model` with all constraints (contacts, limits, equalities, friction loss) disabled,
    so that `mj_inverse` on it gives M qacc + c - qfrc_passive. The caller's model is not touched."""
    import mujoco

    m = copy.copy(model)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    return m


class MujocoInverseDynamics:
    """The same interface as `InverseDynamics`, computed by MuJoCo: `mj_inverse` per sample (on a copy
    of the model with constraints disabled), gradients from `mjd_inverseFD` and `mj_jacSite`.

    General (any joint types MuJoCo supports) but slow: `mjd_inverseFD` makes about 2 nv + 1 calls to
    `mj_inverse` per sample (forward differences, step `eps`), so its gradients carry errors of order
    eps * |d2 tau| (about 1e-6 relative).

    Args:
        model: MjModel (not modified; a constraint-free copy is made).
        sites: site names as in `InverseDynamics`.
        eps: finite-difference step of `mjd_inverseFD` [rad or m]: 1e-6, a truncation error of about 1e-6
            relative (above) and a round-off of about 1e-16 / eps = 1e-10, both far under the tolerances
            this reference is compared at (tests/solver/test_inverse_dynamics.py).
    """

    #: the engine interface of `solver.path_context`: reads and requires qpos, qvel, qacc; no site
    #: velocities; no narrower tangent map
    needs = (0, 1, 2)
    required = (0, 1, 2)
    has_site_velocities = False
    motion_map = None

    #: the engine computes generalized forces (`solver.path_state.PathState` passes it qacc)
    forces = True

    def __init__(self, model, sites=(), eps: float = 1e-6):
        import mujoco

        self.model = constraint_free_copy(model)
        self.data = mujoco.MjData(self.model)
        self.nq, self.nv = int(model.nq), int(model.nv)
        self.site_ids = site_ids(model, sites)
        self.eps = float(eps)
        nv = self.nv
        self._DfDq, self._DfDv, self._DfDa = (np.zeros((nv, nv)) for _ in range(3))
        self._jac = np.zeros((3, nv))
        self._cache: InverseDynamicsResult | None = None

    def forward(self, qpos, qvel, qacc) -> InverseDynamicsResult:
        """See `InverseDynamics.forward`."""
        import mujoco

        c = self._cache
        if c is not None and c.matches(qpos, qvel, qacc):
            return c
        m, d = self.model, self.data
        n = qpos.shape[0]
        tau = np.empty((n, self.nv))
        sites = np.empty((n, len(self.site_ids), 3))
        for i in range(n):
            d.qpos[:], d.qvel[:], d.qacc[:] = qpos[i], qvel[i], qacc[i]
            mujoco.mj_inverse(m, d)
            tau[i] = d.qfrc_inverse
            sites[i] = d.site_xpos[self.site_ids]
        res = InverseDynamicsResult(tau, sites, qpos.copy(), qvel.copy(), qacc.copy())
        self._cache = res
        return res

    def positions(self, qpos: np.ndarray) -> np.ndarray:
        """(n, k, 3) world positions [m] of the sites at qpos (n, nq), by `mj_kinematics`."""
        from solver.kinematics import mujoco_site_positions

        return mujoco_site_positions(self.model, self.data, self.site_ids, qpos)

    def vjp(self, res, g_tau, g_sites=None):
        """See `InverseDynamics.vjp` (DfDq, DfDv, DfDa of `mjd_inverseFD` are transposed Jacobians,
        DfDq[i, j] = d tau_j / d qpos-tangent_i, so the products are DfDq @ g_tau)."""
        import mujoco

        m, d = self.model, self.data
        if g_tau is None:
            g_tau = np.zeros(res.tau.shape)
        n = g_tau.shape[0]
        Gq, Gv, Ga = (np.zeros((n, self.nv)) for _ in range(3))
        for i in range(n):
            d.qpos[:], d.qvel[:], d.qacc[:] = res.qpos[i], res.qvel[i], res.qacc[i]
            mujoco.mjd_inverseFD(
                m, d, self.eps, 0, self._DfDq, self._DfDv, self._DfDa, None, None, None, None
            )
            Gq[i] = self._DfDq @ g_tau[i]
            Gv[i] = self._DfDv @ g_tau[i]
            Ga[i] = self._DfDa @ g_tau[i]
            if g_sites is not None and len(self.site_ids):
                mujoco.mj_kinematics(m, d)
                mujoco.mj_comPos(m, d)
                for k, sid in enumerate(self.site_ids):
                    mujoco.mj_jacSite(m, d, self._jac, None, int(sid))
                    Gq[i] += g_sites[i, k] @ self._jac
        return Gq, Gv, Ga
