"""The Jacobian of the inverse-dynamics residuals point by point, for the Gauss-Newton back end.

The torque, root and friction-cone terms (`solver.terms.dynamics`, `solver.terms.contact_wrench`) are
functions of the generalized forces tau(qpos, qvel, qacc) of the path (`mj_inverse` without
constraints), of the contact sites' positions and of the root's pose. Each term states its gradient
as adjoints in the engine's variables (`EngineGradient`: d f / d tau (n, nv), d f / d site positions
(n, k, 3)) plus a part directly in Y; a residual column's Jacobian row is therefore

    d r / d(Y, Y', Y'') = g_tau . d tau / d(Y, Y', Y'') + g_sites . d p / dY (+ the direct part),

linear in its adjoints. So the Jacobian of every column of every such term needs only the per-point
Jacobian of tau (`TauJacobian`: nv rows, each (n, nq) per order) and the site Jacobians
(`solver.site_jacobian`), computed once per evaluation and shared, instead of one reverse pass of the
engine per residual column and term (6 + 4 + nv passes with all three terms).

Where d tau / d(qpos, qvel, qacc) comes from (docs/solvers.md, "Where the Jacobian comes from"):

* `analytic_tau_jacobian` (the default): the analytic engine's reverse pass (`InverseDynamics.vjp`,
  exact) once per tau row, each followed by the path's chain rule (`PathMotion.vjp`: MuJoCo's pose
  tangent, qvel, qacc -> Y, Y', Y''). Vectorized over the points; nv passes, each about the cost of one
  gradient evaluation of the dynamics terms.
* `mujoco_tau_jacobian`: MuJoCo's `mjd_inverseFD` per point (forward differences inside MuJoCo,
  about 3 nv `mj_inverse` calls a point; its DfDq, DfDv, DfDa are the transposed Jacobians in MuJoCo's
  tangent convention: free joint world translation then a rotation in the body frame, ball joints a
  rotation in the child frame, the convention `TangentMap` and `mj_differentiatePos` use), chained
  the same way. General (any joint type) and about 2x the CPU of the analytic passes on the figure;
  accurate to about 1e-6 relative. The tests compare the two.

Analytic recursive Newton-Euler derivatives (Carpentier & Mansard, "Analytical derivatives of rigid
body dynamics algorithms", RSS 2018) would give all three partials for the cost of a few passes;
written over numpy arrays they are not cheaper than nv reverse passes of the vectorized engine for
the figure's 12 bodies, so they are not used.
"""
from __future__ import annotations

import numpy as np

from solver.path_context import EngineGradient


def analytic_tau_jacobian(engine, res, motion, rows) -> np.ndarray:
    """d tau_j / d(Y, Y', Y'') of the rows j by reverse passes of an analytic engine.

    Args:
        engine: an engine with an exact `vjp` (`solver.inverse_dynamics.InverseDynamics`).
        res: its forward result on the path; motion: the path's `PathMotion` (with qacc).
        rows: (r,) tau indices.
    Returns:
        (3, n, r, nq): order k (Y, Y', Y''), point, row, qpos component [units of tau per unit of Y^(k)].
    """
    n, nv = res.tau.shape
    out = np.zeros((3, n, len(rows), motion.tmap.nq))
    g = np.zeros((n, nv))
    for i, j in enumerate(rows):
        g[:, j] = 1.0
        for k, d in enumerate(EngineGradient(engine, res, motion, g).pullback()):
            if d is not None:
                out[k, :, i] = d
        g[:, j] = 0.0
    return out


def mujoco_tau_jacobian(model, res, motion, rows, eps: float = 1e-6) -> np.ndarray:
    """The same as `analytic_tau_jacobian` from MuJoCo's `mjd_inverseFD` at every point.

    Args:
        model: MjModel of the figure (a constraint-free copy is used: tau without contact forces).
        res: an engine's result (its qpos, qvel, qacc are read). motion: the path's `PathMotion`.
        rows: (r,) tau indices. eps: the finite-difference step of `mjd_inverseFD`.
    Returns:
        (3, n, r, nq) as `analytic_tau_jacobian`.
    """
    import mujoco

    from solver.inverse_dynamics_mujoco import constraint_free_copy

    m = constraint_free_copy(model)
    d = mujoco.MjData(m)
    n, nv = res.tau.shape
    D = np.zeros((3, n, nv, nv))  # pose, qvel, qacc: D[., i, a, j] = d tau_j / d x_a at point i
    for i in range(n):
        d.qpos[:], d.qvel[:], d.qacc[:] = res.qpos[i], res.qvel[i], res.qacc[i]
        mujoco.mjd_inverseFD(m, d, eps, 0, D[0, i], D[1, i], D[2, i], None, None, None, None)
    out = np.zeros((3, n, len(rows), motion.tmap.nq))
    for r, j in enumerate(rows):
        for k, dk in enumerate(motion.vjp(D[1, :, :, j], D[2, :, :, j], D[0, :, :, j])):
            out[k, :, r] = dk
    return out


class TauJacobian:
    """The per-point Jacobian of an engine's tau and site positions on one `PathContext`'s path, rows
    computed on demand and kept (`tau_jacobian` shares one per context and engine).

    Args:
        ctx: the `PathContext` (its site Jacobians are shared with the site terms').
        engine: a `KinematicTree` engine with an exact `vjp` (`solver.inverse_dynamics.InverseDynamics`).
        res, motion: its forward result and the path's `PathMotion` (`PathContext.forward`).
    """

    def __init__(self, ctx, engine, res, motion):
        self.ctx, self.engine, self.res, self.motion = ctx, engine, res, motion
        self.nq = motion.tmap.nq
        self._rows: dict[int, np.ndarray] = {}  # tau row -> (3, n, nq)
        self._sites = None

    def rows(self, rows) -> np.ndarray:
        """(3, n, r, nq): d tau_j / d(Y, Y', Y'') for the tau indices `rows` (r,) (computed once each)."""
        rows = [int(j) for j in rows]
        new = [j for j in rows if j not in self._rows]
        if new:
            J = analytic_tau_jacobian(self.engine, self.res, self.motion, new)
            for i, j in enumerate(new):
                self._rows[j] = J[:, :, i]
        n = self.res.tau.shape[0]
        if not rows:
            return np.zeros((3, n, 0, self.nq))
        return np.stack([self._rows[j] for j in rows], axis=2)

    def sites(self) -> np.ndarray:
        """(n, k, 3, nq) d p / d Y of the engine's sites [m per unit qpos] (`solver.site_jacobian`)."""
        if self._sites is None:
            from solver.site_jacobian import cached_site_jacobians

            jac = cached_site_jacobians(self.ctx, self.engine, self.res)
            n = self.res.tau.shape[0]
            S = np.zeros((n, len(jac), 3, self.nq))
            for k, (comps, Jp, _) in enumerate(jac):
                S[:, k][:, :, comps] = Jp
            self._sites = S
        return self._sites

    def blocks(self, g_tau: np.ndarray, g_sites: np.ndarray | None = None,
               direct: np.ndarray | None = None) -> tuple:
        """The Jacobian of m residual columns given by their adjoints (module docstring).

        Args:
            g_tau: (n, m, nv) d r_c / d tau per column c. g_sites: (n, m, k, 3) d r_c / d site
                positions, or None. direct: (n, m, nq) the part of d r_c / d Y not through tau or the
                sites (e.g. a lever arm of the root's pose), or None.
        Returns:
            (J0, J1, J2): (n, m, nq) each, d r / d Y, d Y', d Y'' (`Residual.blocks`).
        """
        used = np.flatnonzero(np.any(g_tau != 0, axis=(0, 1)))
        T = self.rows(used)  # (3, n, r, nq)
        J = np.einsum("nmr,knrq->knmq", g_tau[:, :, used], T)
        J0, J1, J2 = J[0], J[1], J[2]
        if g_sites is not None and np.any(g_sites):
            J0 = J0 + np.einsum("nmki,nkiq->nmq", g_sites, self.sites())
        if direct is not None:
            J0 = J0 + direct
        return J0, J1, J2


def tau_jacobian(ctx, engine, tmap) -> TauJacobian | None:
    """The `TauJacobian` of `engine` on `ctx` (one per context and engine, shared by the terms), or
    None for an engine without an exact vectorized reverse pass (the terms then fall back to one
    vector-Jacobian product per residual column).

    Args:
        ctx: PathContext with Y, Y', Y''. engine: see `solver.path_context`. tmap: the terms' TangentMap.
    """
    from solver.inverse_dynamics import InverseDynamics

    if not isinstance(engine, InverseDynamics) or ctx.Y2 is None:
        return None
    cache = ctx.__dict__.setdefault("_tau_jacobians", {})
    hit = cache.get(id(engine))
    if hit is None:
        mo, res = ctx.forward(engine, tmap)
        hit = cache[id(engine)] = TauJacobian(ctx, engine, res, mo)
    return hit
