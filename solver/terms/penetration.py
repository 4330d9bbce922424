"""Ground penetration of contact sites (paper eq. 12, sec. 5), against every static plane and box."""
from __future__ import annotations

import numpy as np

from solver.contacts import contact_radii, figure_sites, lowest_points
from solver.errors import InputError
from solver.kinematics import TangentMap
from solver.layout import StateLayout
from solver.path_context import EngineGradient, engine_sites, site_engine
from solver.surfaces import StaticSurfaces
from solver.terms.base import Term, TermEval


def site_positions(model, data, Y: np.ndarray, sites: np.ndarray) -> np.ndarray:
    """World positions of sites along a path, by MuJoCo forward kinematics point by point (plots and
    tests; the term reads its engine's).

    Args:
        model: MjModel. data: scratch MjData. Y: (n, nq) qpos. sites: (k,) site ids.
    Returns:
        (n, k, 3) positions [m].
    """
    import mujoco

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
    than rest a hair inside it. Site positions at all points from the engine's forward pass (the
    `PathContext` computes it once per evaluation for all terms sharing the engine; by default the
    vectorized `SiteKinematics`, eq. 13 of appendix A, MuJoCo's positions to rounding error); the
    gradient is left in the engine's variables (d f / d site position, only nonzero where a site is
    inside) for its reverse pass. Measured: the positions along run-and-step's plain path at 680
    points 0.7-0.9 ms instead of 1.5-1.9 ms by `mj_kinematics` point by point; value and gradient on
    35_17's optimized path (553 points, 298 with a site inside the margin) 2.9-3.0 ms instead of
    5.3-9.0 ms with `mj_jacSite` point by point. A model the vectorized tree does not cover (hinge or
    slide joints) gets MuJoCo's positions and `mj_jacSite` as its engine (`MujocoSitePositions`).

    Args:
        model: MjModel of the scene (figure + static floor planes/boxes), loaded once by the caller.
        sites: contact site names (default the model's figure's, `solver.contacts.figure_sites`).
        margin: [m] clearance counted as penetration (default none: the depth itself). A weighted
            objective whose converged path should clear the surface between its quadrature points
            passes one: at 400 points per second a swing foot (~6 m/s) moves ~15 mm between points
            and can cut a box corner between two of them; 5 mm absorbed that on the shipped clip.
        engine: the engine to read the site positions from, shared with other terms (an inverse-dynamics
            engine from `solver.terms.dynamics.make_engine`, or `SiteKinematics`); default one of its own
            (`solver.path_context.site_engine`).
    Raises:
        InputError: a site is missing, the scene has no static plane or box, or the engine does not
            track a site.
    """

    name = "penetration"
    units = "m^2"
    needs = (0,)

    def __init__(self, model, sites=None, margin: float = 0.0, engine=None):
        self.model = model
        sites = figure_sites(model, sites)
        self.surfaces = StaticSurfaces.from_model(model)
        if self.surfaces.count == 0:
            raise InputError("the scene has no static floor plane or box for the penetration term; use "
                             "models/floor.xml or add a plane geom to the scene's <worldbody>")
        self.tmap = TangentMap.from_layout(StateLayout.from_model(model))
        self.margin = float(margin)
        self.engine = engine if engine is not None else site_engine(model, sites, velocities=False)
        self.site_index = engine_sites(self.engine, model, sites)  # the figure's: a slice
        # a rounded site's sphere penetrates with its bottom (its centre minus its radius): the point
        # taken for the site (`solver.contacts.lowest_points`; a constant shift, same gradient)
        self.radii = contact_radii(model, sites)
        self.needs = tuple(sorted({0, *self.engine.required}))

    def depths(self, Y: np.ndarray, margin: float | None = None) -> np.ndarray:
        """(n, k) deepest penetration of each contact site over all surfaces [m] (0 = clear), at the
        poses Y (n, nq)."""
        p = lowest_points(self.engine.positions(np.asarray(Y, float))[:, self.site_index], self.radii)
        d, _ = self.surfaces.penetration(p, self.margin if margin is None else margin)
        return d.max(axis=-1)

    def _depths(self, ctx):
        """(motion, engine result, depth (n, k, S) [m], d depth / d site position (n, k, S, 3))."""
        mo, res = ctx.forward(self.engine, self.tmap)
        depth, ddepth = self.surfaces.penetration(lowest_points(res.sites[:, self.site_index], self.radii), self.margin)
        return mo, res, depth, ddepth

    def evaluate_in(self, ctx, grad=True) -> TermEval:
        """`Term.evaluate_in`: the gradient left to the engine's reverse pass (`EngineGradient`)."""
        mo, res, depth, ddepth = self._depths(ctx)
        f = (depth * depth).sum(axis=(1, 2))
        if not grad:
            return TermEval(f)
        g_sites = np.zeros(res.sites.shape)
        g_sites[:, self.site_index] = np.einsum("nks,nksi->nki", 2.0 * depth, ddepth)
        return TermEval(f, deferred=EngineGradient(self.engine, res, mo, None, g_sites))
