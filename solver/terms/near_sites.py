"""The feet near the plain spline's, priced like the contact terms (docs/corpus.md "Near the plain spline").

`NearPlain` (`solver.terms.near`) measures the departure from the plain spline in joint angles, with an
absolute weight: a mean departure of 1 rad^2 costs one unit of E. The contact terms are renormalized by
their plain-spline values (eq. 7), and the plain spline through a capture's keys plants its feet to
within millimetres, so their weights per square metre are huge (planted weight 10 over a plain
integral of a few 1e-3 m^2 s is thousands of units of E per m^2 s of violation), while a whole-body
shift of decimetres costs `near` a hundredth of a unit. The optimizer bought a little of planted or
clearance (whose residual the keyframes can make irreducible) with such shifts, moving the swing feet
decimetres from where the plain spline had them.

`NearSites` (name "near_sites", m^2) measures the departure where those terms act and where the
site-error metric looks: the contact sites' positions, and the root's,

    f(t) = sum over the contact sites k of |p_k(t) - p_ref,k(t)|^2 + |y(t) - y_ref(t)|^2,

p_k the site's world position [m] on the path, p_ref,k on the reference path (the plain spline) at the
same instant, y the root's position [m] (a free root's first three qpos). It is zero on the plain
spline, so eq. 7 cannot scale it by its own value; it is scaled by the planted term's plain-spline
integral instead (`renormalize_like`, `Objective.renormalize`), so that a square metre-second of site
departure and one of planted violation are in the same currency whatever the clip and keying: at weight
1 against planted 10, a site moved by d for a while costs a tenth of a site held d off its plant for as
long. A correction the constraints ask for moves a site by millimetres (a toe 3 mm inside the floor, a
heel sliding 1-2 cm) and still pays tenfold; a shift of decimetres costs hundreds of times what it buys.
A proximal (Tikhonov) term in the space of the constrained points (Nocedal & Wright, Numerical
Optimization, 2nd ed., sec. 10.3; Parikh & Boyd, Proximal Algorithms, 2014, sec. 1.1).

Site positions and their reverse pass come from the engine shared with the contact terms
(`solver.path_context`), exact, no finite differences.
"""
from __future__ import annotations

import numpy as np

from solver.kinematics import TangentMap
from solver.layout import CONTACT_SITES, StateLayout
from solver.path_context import EngineGradient, engine_sites, site_engine
from solver.site_jacobian import supports
from solver.terms.base import Residual, SiteRows, Term, TermEval

__all__ = ["NearSites"]

#: reference site positions kept per term (one per set of quadrature points)
_CACHE = 16


class NearSites(Term):
    """f(t) = sum_k |p_k(t) - p_ref,k(t)|^2 + |y(t) - y_ref(t)|^2 [m^2] over the contact sites and the
    root's position (module docstring).

    Args:
        model: MjModel of the scene (the figure with its contact sites).
        reference: callable t (n,) [s] -> (n, nq) qpos of the reference path (the plain spline's
            `FrameSet.path`), or None: no reference, the term is zero.
        engine: the site engine shared with the other terms (`SiteKinematics`, `InverseDynamics` or
            `MujocoSitePositions`), or None: one of its own (`solver.path_context.site_engine`).
        sites: the site names (default the four contact sites).
        renormalize_like: the term whose plain-spline integral scales this one (eq. 7;
            `Objective.renormalize`), default "planted"; None: its own (zero, so scale 1: absolute).
    Raises:
        InputError: an unknown site, or an engine that does not track the sites.
    """

    name = "near_sites"
    units = "m^2"

    def __init__(self, model, reference, engine=None, sites=CONTACT_SITES, renormalize_like: str | None = "planted"):
        self.reference = reference
        self.renormalize_like = renormalize_like
        self.engine = engine if engine is not None else site_engine(model, list(sites), velocities=False)
        self._idx = engine_sites(self.engine, model, list(sites))
        layout = StateLayout.from_model(model)
        #: qpos indices of the root's position (a free root's first three; none for a fixed root)
        self._root = np.array([i for j in layout.joints if j.kind == "free" for i in range(j.qposadr, j.qposadr + 3)][:3], int)
        self._tmap = TangentMap.from_layout(layout)
        self.needs = tuple(sorted({0, *self.engine.required}))
        self._cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    def _ref(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reference's site positions (n, k, 3) and root position (n, r) at t [m], kept for the next
        evaluation at the same t."""
        t = np.asarray(t, float)
        key = (len(t), float(t[0]), float(t[-1])) if len(t) else (0,)
        hit = self._cache.get(key)
        if hit is not None and np.array_equal(hit[0], t):
            return hit[1]
        Yr = np.asarray(self.reference(t), float)
        still = np.zeros((len(t), self._tmap.nv))  # positions only: velocities and accelerations do not move sites
        req = self.engine.required
        res = self.engine.forward(Yr, still if 1 in req else None, still if 2 in req else None)
        P = (np.array(res.sites[:, self._idx]), Yr[:, self._root])
        if len(self._cache) >= _CACHE:
            self._cache.clear()
        self._cache[key] = (np.array(t), P)
        return P

    def _diff(self, ctx):
        """(motion, engine result, site differences (n, k, 3), root differences (n, r) [m])."""
        mo, res = ctx.forward(self.engine, self._tmap)
        sites, root = self._ref(ctx.t)
        return mo, res, res.sites[:, self._idx] - sites, ctx.Y[:, self._root] - root

    def evaluate_in(self, ctx, grad=True) -> TermEval:
        """`Term.evaluate_in`: the sites' gradient 2 (p - p_ref) left to the engine's reverse pass, the
        root's 2 (y - y_ref) in dY."""
        if self.reference is None:
            return TermEval(np.zeros(len(ctx.Y)), dY=np.zeros_like(ctx.Y) if grad else None)
        mo, res, d, e = self._diff(ctx)
        f = np.einsum("nki,nki->n", d, d) + np.einsum("ni,ni->n", e, e)
        if not grad:
            return TermEval(f)
        g = np.zeros(res.sites.shape)
        g[:, self._idx] = 2.0 * d
        dY = np.zeros_like(ctx.Y)
        dY[:, self._root] = 2.0 * e
        return TermEval(f, dY=dY, deferred=EngineGradient(self.engine, res, mo, None, g, None))

    def residual(self, ctx) -> Residual:
        """r (n, 3 k + r) [m]: the components of p_k - p_ref,k, then of the root's y - y_ref
        (f = |r|^2); d r / d p = I per site, d r / d y = I for the root."""
        Y = ctx.Y
        if self.reference is None:
            return Residual(np.zeros((len(Y), 0)), compact=[], nq=Y.shape[1])
        mo, res, d, e = self._diff(ctx)
        n, k = d.shape[:2]
        m_s, nr = 3 * k, len(self._root)
        idx = np.arange(res.sites.shape[1])[self._idx]

        def pull(g):
            gs = np.zeros(res.sites.shape)
            gs[:, idx] = g[:, :m_s].reshape(n, k, 3)
            dY, dY1, dY2 = EngineGradient(self.engine, res, mo, None, gs, None).pullback()
            dY = np.array(dY)
            dY[:, self._root] += g[:, m_s:]
            return dY, dY1, dY2

        r = np.concatenate([d.reshape(n, m_s), e], axis=1)
        dp = np.zeros((n, m_s, 3))
        dp[:, np.arange(m_s), np.tile(np.arange(3), k)] = 1.0
        rows = SiteRows(ctx, self.engine, res, np.repeat(idx, 3), dp=dp)
        if not supports(self.engine):
            return Residual(r, pull=pull)
        root = (m_s + np.arange(nr), self._root, (np.broadcast_to(np.eye(nr), (n, nr, nr)).copy(), None, None))
        return Residual(r, pull=pull, compact=rows.blocks(Y.shape[1]) + [root], nq=Y.shape[1])
