"""Ground penetration of contact sites (paper eq. 12, sec. 5), against every static plane and box."""
from __future__ import annotations

import mujoco
import numpy as np

from solver.errors import InputError
from solver.kinematic_tree import KinematicTree
from solver.kinematics import TangentMap
from solver.layout import CONTACT_SITES, StateLayout, index_run, site_ids
from solver.surfaces import StaticSurfaces
from solver.terms.base import Term, TermEval


def site_positions(model, data, Y: np.ndarray, sites: np.ndarray) -> np.ndarray:
    """World positions of sites along a path, by MuJoCo forward kinematics.

    Args:
        model: MjModel. data: scratch MjData. Y: (n, nq) qpos. sites: (k,) site ids.
    Returns:
        (n, k, 3) positions [m].
    """
    out = np.empty((len(Y), model.nsite, 3))
    qpos, xpos = data.qpos, data.site_xpos
    for i, y in enumerate(Y):
        qpos[:] = y
        mujoco.mj_kinematics(model, data)
        out[i] = xpos
    return out[:, sites]


class Penetration(Term):
    """f = sum over contact sites and static surfaces of depth^2 [m^2] (paper eq. 12, squared).

    depth = how far the site is inside the floor plane or box, counting a safety `margin` as inside
    (`StaticSurfaces.penetration`). The paper uses the depth itself; its square is C1, which a
    gradient-based optimizer needs, and the margin makes a converged path clear the surface rather
    than rest a hair inside it. Site positions at all points from one vectorized forward pass of the
    pose (`KinematicTree.site_positions`, eq. 13 of appendix A: the legs and the root, MuJoCo's
    positions to rounding error); the gradient by that pass's reverse, only at points where a site is
    inside (`KinematicTree.site_positions_vjp`), mapped to qpos components by `TangentMap.pullback`.
    Measured: the positions along run-and-step's plain path at 680 points 0.7-0.9 ms instead of
    1.5-1.9 ms by `mj_kinematics` point by point; value and gradient on 35_17's optimized path (553
    points, 298 with a site inside the margin) 2.9-3.0 ms instead of 5.3-9.0 ms with `mj_jacSite` point
    by point. A model the tree does not cover (hinge or slide joints) keeps MuJoCo's per-point
    `mj_kinematics` and `mj_jacSite`.

    Args:
        model: MjModel of the scene (figure + static floor planes/boxes), loaded once by the caller.
        sites: contact site names (default heel and toe of each foot).
        margin: [m] clearance counted as penetration (default 5 mm). At 400 quadrature points per
            second a swing foot (~6 m/s) moves ~15 mm between points and can cut a box corner between
            two of them; 5 mm of margin absorbs that (2 mm left 0.5-0.9 mm grazes on the shipped clip).
        engine: optional inverse-dynamics engine tracking the sites (`solver.terms.dynamics.make_engine`)
            shared with the dynamics terms: the site positions come from its (cached) forward pass
            and the gradient is deferred to its reverse pass, which the objective runs once for all
            terms sharing it (`evaluate_deferred`); the same values, about 4 ms cheaper per evaluation
            at 680 points than forward kinematics and site Jacobians per point.
    Raises:
        InputError: a site is missing, the scene has no static plane or box, or the engine does not
            track a site.
    """

    name = "penetration"
    units = "m^2"
    needs = (0,)

    def __init__(self, model, sites=CONTACT_SITES, margin: float = 0.005, engine=None):
        self.model = model
        self.data = mujoco.MjData(model)
        self.sites = site_ids(model, sites)
        self.surfaces = StaticSurfaces.from_model(model, self.data)
        if self.surfaces.count == 0:
            raise InputError("the scene has no static floor plane or box for the penetration term; use "
                             "models/floor.xml or add a plane geom to the scene's <worldbody>")
        self.tmap = TangentMap.from_layout(StateLayout.from_model(model))
        self.margin = float(margin)
        self._jac = np.zeros((3, model.nv))
        try:  # the vectorized forward and reverse pass of the sites' bodies (with an engine: `depths` only)
            self._tree = KinematicTree(model, sites, prune=True)
        except InputError:  # joints the tree does not model: MuJoCo point by point
            self._tree = None
        self.engine = engine
        if engine is not None:
            where = [np.flatnonzero(engine.site_ids == i) for i in self.sites]
            if any(len(w) == 0 for w in where):
                raise InputError(f"the engine does not track the contact sites {', '.join(sites)}")
            self._engine_index = index_run([int(w[0]) for w in where])  # the figure's: a slice
            self.needs = tuple(engine.needs)  # the engine's forward pass reads qvel (and qacc) too

    def depths(self, Y: np.ndarray, margin: float | None = None) -> np.ndarray:
        """(n, k) deepest penetration of each contact site over all surfaces [m] (0 = clear)."""
        p = self._positions(Y)[0]
        d, _ = self.surfaces.penetration(p, self.margin if margin is None else margin)
        return d.max(axis=-1)

    def violation(self, Y: np.ndarray) -> float:
        """Deepest true penetration (margin 0) of any contact site into any surface [m]."""
        return float(self.depths(Y, margin=0.0).max())

    def evaluate_deferred(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        """With an engine: `evaluate` with the gradient left to the engine's reverse pass
        (`solver.terms.dynamics.EngineGradient`); without one, `evaluate`."""
        if self.engine is None:
            return self.evaluate(t, Y, Y1, Y2, grad)
        from solver.terms.dynamics import EngineGradient, engine_forward

        mo, res = engine_forward(self.engine, self.tmap, Y, Y1, Y2)
        depth, ddepth = self.surfaces.penetration(res.sites[:, self._engine_index], self.margin)
        f = (depth * depth).sum(axis=(1, 2))
        if not grad:
            return TermEval(f)
        g_sites = np.zeros(res.sites.shape)
        g_sites[:, self._engine_index] = np.einsum("nks,nksi->nki", 2.0 * depth, ddepth)
        return TermEval(f, deferred=EngineGradient(self.engine, res, mo, None, g_sites))

    def evaluate(self, t, Y, Y1, Y2, grad=True) -> TermEval:
        if self.engine is not None:
            ev = self.evaluate_deferred(t, Y, Y1, Y2, grad)
            return ev if ev.deferred is None else TermEval(ev.f, *ev.deferred.pullback())
        m, d = self.model, self.data
        p, pose = self._positions(Y)
        depth, ddepth = self.surfaces.penetration(p, self.margin)  # (n,k,S), (n,k,S,3)
        f = (depth * depth).sum(axis=(1, 2))
        if not grad:
            return TermEval(f)
        dY = np.zeros_like(Y)
        # d f / d site position, per point and site: sum over surfaces of 2 depth * d depth / d p
        gp = np.einsum("nks,nksi->nki", 2.0 * depth, ddepth)
        hit = np.abs(gp).sum(axis=2) > 0  # (n, k) sites inside something
        active = np.flatnonzero(hit.any(axis=1))
        if active.size and pose is not None:
            dY[active] = self.tmap.pullback(Y[active], self._tree.site_positions_vjp(pose, gp[active], active))
        elif active.size:
            gv = np.zeros((active.size, m.nv))
            jac, qpos = self._jac, d.qpos
            for r, i in enumerate(active):
                qpos[:] = Y[i]
                mujoco.mj_kinematics(m, d)
                mujoco.mj_comPos(m, d)
                for k in np.flatnonzero(hit[i]):
                    mujoco.mj_jacSite(m, d, jac, None, int(self.sites[k]))
                    gv[r] += gp[i, k] @ jac
            dY[active] = self.tmap.pullback(Y[active], gv)
        return TermEval(f, dY=dY)

    def _positions(self, Y: np.ndarray):
        """((n, k, 3) site positions [m], the tree's saved pose or None) along the path Y (n, nq)."""
        if self._tree is not None:
            return self._tree.site_positions(Y)
        return site_positions(self.model, self.data, Y, self.sites), None
