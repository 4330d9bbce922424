"""Constraints on the contact sites: heights above the surfaces and sliding along them.

Heights. A site's height h is the signed distance of its contact point (the site, or the lowest point of
its sphere where the figure rounds it: `solver.contacts.contact_radii`) above the supporting face of a
surface (`SupportSurfaces`: a plane, or a box's top over its footprint), with dh/dp = n, the face's
unit normal (where the support is chosen per point, the rounded distance to a box's top: continuously
differentiable across its edge). A `HeightBound` pair holds h <= limit (upper) or h >= limit (lower):

    planted       h <= limit during a contact, above the contact's surface               [m]
    flight        h >= limit in a flight, every site                                     [m]

Sliding. `Slide` holds the speed of a site along its contact's surface, s = |v_t| with v_t = v - (v.n) n,
below a bound b > 0 during the contact, written c = huber_b(s) - b/2 <= 0 with Huber's function
huber_b(s) = s^2 / (2 b) for s <= b and s - b/2 above (Huber, "Robust estimation of a location
parameter", Ann. Math. Statist. 35, 1964): c is s - b where the bound is broken (a speed in m/s, growing
linearly), zero at s = b with slope 1 on both sides, and smooth at s = 0, where |v_t| has a kink.
"""
from __future__ import annotations

import numpy as np

from solver.constraints.base import SCHEDULE, Constraint
from solver.curvature import Curvature, Outer
from solver.path_state import PathState, add_at

__all__ = ["HeightBound", "SupportHeight", "SupportSlide", "site_heights"]


def site_heights(state: PathState, support, radii: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                 surfaces: np.ndarray, key=None) -> tuple[np.ndarray, np.ndarray]:
    """Heights h (p,) [m] and face normals (p, 3) of the pairs' contact points on the state's path,
    computed once per state and key.

    Args:
        state: PathState with a site engine. support: SupportSurfaces. radii: (k,) contact-sphere radii
            [m] of the engine's sites. rows, cols: (p,) quadrature point and engine site of each pair.
        surfaces: (p,) surface index of each pair, -1: the surface under the point. key: cache key.
    """
    hit = None if key is None else state.cache.get(key)
    if hit is not None:
        return hit
    p = state.sites[rows, cols].copy()
    p[:, 2] -= radii[cols]
    h, n = np.empty(len(rows)), np.empty((len(rows), 3))
    for s in np.unique(surfaces):
        at = np.flatnonzero(surfaces == s)
        hh, nn = support.height(p[at], None if s < 0 else int(s))
        h[at], n[at] = hh, nn
    if key is not None:
        state.cache[key] = (h, n)
    return h, n


class _SitePairs(Constraint):
    """Pairs of (quadrature point, engine site, surface) and the heights there."""

    priority = SCHEDULE  # its subclass HeightBound: a flight's clearance, the ground outside flights

    def __init__(self, support, radii, rows, cols, surfaces, labels):
        self.support, self.radii = support, np.asarray(radii, float)
        self.rows = np.asarray(rows, int)
        self.cols = np.asarray(cols, int)
        self.surfaces = np.asarray(surfaces, int)
        self.labels = np.asarray(labels, object)
        self.series = self.cols  # one time series per site

    def heights(self, state: PathState):
        return site_heights(state, self.support, self.radii, self.rows, self.cols, self.surfaces,
                            ("heights", id(self)))


class HeightBound(_SitePairs):
    """h <= limit (upper) or h >= limit (lower) at the pairs (module docstring).

    Args:
        name: the constraint's name. support: SupportSurfaces. radii: (k,) [m]. rows, cols, surfaces:
            (p,) see `site_heights`. limit: (p,) [m]. upper: which side. tolerance: [m]. labels: (p,)
            the site name of each pair.
    """

    unit, scale = "mm", 1e-3

    def __init__(self, name, support, radii, rows, cols, surfaces, limit, upper: bool, tolerance: float, labels):
        super().__init__(support, radii, rows, cols, surfaces, labels)
        self.name = name
        self.sign = 1.0 if upper else -1.0
        self.limit = self.sign * np.asarray(limit, float)
        self.tolerance = float(tolerance)

    def measure(self, state):
        h, _ = self.heights(state)
        return self.sign * h

    def pull(self, state, g):
        _, n = self.heights(state)
        gp = np.zeros(state.sites.shape)
        add_at(gp, (self.rows, self.cols), (self.sign * g)[:, None] * n)
        state.add_sites(gp)

    def curvature(self, state, d1, d2):
        """d2 grad c grad c^T, grad c = sign n^T J in the pose (J the site's Jacobian): h is linear in the
        site's position on a face (its own curvature, at a box's rounded edge, is left out)."""
        live = np.flatnonzero(d2 > 0)
        if not live.size:
            return []
        _, n = self.heights(state)
        J = site_velocity_jacobians(state, self.rows[live], self.cols[live])[1]  # d position / d pose
        g = self.sign * np.einsum("qa,qan->qn", n[live], J)
        return site_terms(self.rows[live], self.cols[live], {0: g[:, None, :]}, d2[live, None, None])


class _FootSupport(Constraint):
    """Pairs = a foot's contacts (its sites' contacts merged); at each quadrature point of one, the support
    site (the foot's site that the schedule has in contact there and the reference holds lowest) and its
    contact's surface; the pair's value is an integral over the contact of a function of that site.

    Args:
        support: SupportSurfaces. radii: (k,) [m]. points: (q,) quadrature point of each term. cols:
            (q,) engine site. surfaces: (q,) surface index (-1: the one under the point). pair: (q,)
            the foot contact of each term. w: (q,) quadrature weight [s]. span: (p,) each foot
            contact's length [s]. rows: (p,) a quadrature point inside each (for reports). labels: (p,)
            the foot's name.
    """

    priority = SCHEDULE

    def __init__(self, support, radii, points, cols, surfaces, pair, w, span, rows, labels):
        self.support, self.radii = support, np.asarray(radii, float)
        self.points, self.cols = np.asarray(points, int), np.asarray(cols, int)
        self.surfaces, self.pair = np.asarray(surfaces, int), np.asarray(pair, int)
        self.w, self.span = np.asarray(w, float), np.asarray(span, float)
        self.rows, self.labels = np.asarray(rows, int), np.asarray(labels, object)

    def pair_weights(self, weights):
        return self.span

    def heights(self, state):
        return site_heights(state, self.support, self.radii, self.points, self.cols, self.surfaces,
                            ("support heights", id(self)))

    def _sum(self, x):
        return np.bincount(self.pair, self.w * x, minlength=len(self.span))


class SupportHeight(_FootSupport):
    """Mean height of the support site over each foot contact <= limit [m] (`_FootSupport`). With `above`
    > 0 [m] the mean is of the height's positive part, smoothed over that width (`ramp`): a foot sunk into
    the floor then does not offset one that floats, as the float figure counts them (a clean's)."""

    name, unit, scale = "planted", "mm", 1e-3

    def __init__(self, *args, limit, tolerance: float, above: float = 0.0):
        super().__init__(*args)
        self.limit = np.asarray(limit, float)
        self.tolerance, self.above = float(tolerance), float(above)

    def measure(self, state):
        h, _ = self.heights(state)
        return self._sum(ramp(h, self.above)[0] if self.above > 0 else h) / self.span

    def pull(self, state, g):
        h, n = self.heights(state)
        slope = ramp(h, self.above)[1] if self.above > 0 else 1.0
        gp = np.zeros(state.sites.shape)
        add_at(gp, (self.points, self.cols), (g[self.pair] * self.w * slope / self.span[self.pair])[:, None] * n)
        state.add_sites(gp)

    def curvature(self, state, d1, d2):
        """d2 grad c grad c^T (an `Outer`: each pair couples its contact's points); c is linear in the heights
        (with `above`, the ramp's own curvature, 1/above within its width, is left out: Gauss-Newton)."""
        return [Outer(self, self.points, self.pair, d2)] if (d2 > 0).any() else []


def ramp(h: np.ndarray, e: float) -> tuple[np.ndarray, np.ndarray]:
    """The positive part of h [m], smoothed over a width e > 0 [m], and its slope: the Huber function of
    max(0, h) (`huber`): convex, nondecreasing, once differentiable, within e / 2 of max(0, h)."""
    h = np.asarray(h, float)
    return huber(np.maximum(h, 0.0), e), np.clip(h / e, 0.0, 1.0)


def huber(s: np.ndarray, b: float) -> np.ndarray:
    """The Huber function of a speed s >= 0 [m/s] with width b [m/s]: s^2 / (2 b) below b, s - b/2 above
    (Huber, "Robust estimation of a location parameter", 1964): convex and nondecreasing, smooth at 0."""
    s = np.asarray(s, float)
    return np.where(s <= b, 0.5 * s * s / b, s - 0.5 * b)


class SupportSlide(_FootSupport):
    """Distance the support site slides along its surface over each foot contact, integral of
    huber_b(|v_t|) dt, <= limit [m] (`_FootSupport`; b the Huber width [m/s]). `forced` (p,) [m]: the
    part of the limit the keyframes force (`solver.constraint_set`; 0 when not given). tolerance: [m], one
    for every pair or (p,) each its own."""

    name, unit, scale = "slide", "mm", 1e-3

    def __init__(self, *args, limit, tolerance: float, width: float, forced=None):
        super().__init__(*args)
        self.limit = np.asarray(limit, float)
        self.forced = np.zeros(len(self.span)) if forced is None else np.asarray(forced, float)
        self.tolerance = float(tolerance) if np.ndim(tolerance) == 0 else np.asarray(tolerance, float)
        self.b = float(width)

    def _tangential(self, state):
        key = ("support vt", id(self))
        hit = state.cache.get(key)
        if hit is None:
            _, n = self.heights(state)
            v = state.site_velocities[self.points, self.cols]
            hit = v - np.einsum("pi,pi->p", v, n)[:, None] * n
            state.cache[key] = hit
        return hit

    def measure(self, state):
        vt = self._tangential(state)
        return self._sum(huber(np.sqrt((vt * vt).sum(1)), self.b))

    def pull(self, state, g):
        vt = self._tangential(state)
        s = np.sqrt((vt * vt).sum(1))
        dc = np.where(s <= self.b, 1.0 / self.b, 1.0 / np.maximum(s, 1e-300))
        gv = np.zeros(state.sites.shape)
        add_at(gv, (self.points, self.cols), (g[self.pair] * self.w * dc)[:, None] * vt)
        state.add_sites(None, gv)

    def curvature(self, state, d1, d2):
        """Per term (point, site): d1 w huber_b''(v_t) in the site's velocity v = J(q) qvel through its
        Jacobians in the pose and in qvel (J_r (3, nv), r = 0, 1: `site_velocity_jacobians`), P K P with
        P = I - n n^T and K = I / b below the Huber width, (I - u u^T) / s above it (u = v_t / s): the
        Gauss-Newton part of c's curvature. The pairs' d2 grad c grad c^T couples every point of a contact:
        an `Outer`."""
        live = d1[self.pair] > 0
        if not (live.any() or (d2 > 0).any()):
            return []
        vt = self._tangential(state)
        _, n = self.heights(state)
        s = np.sqrt((vt * vt).sum(1))
        u = vt / np.maximum(s, 1e-300)[:, None]
        P = np.eye(3) - n[:, :, None] * n[:, None, :]
        below = s <= self.b
        K = np.where(below[:, None, None], P / self.b,
                     (P - u[:, :, None] * u[:, None, :]) / np.maximum(s, 1e-300)[:, None, None])
        K = (d1[self.pair] * self.w)[:, None, None] * K
        J = site_velocity_jacobians(state, self.points[live], self.cols[live])  # (2, q, 3, nv)
        out = site_terms(self.points[live], self.cols[live], {0: J[0], 1: J[1]}, K[live])
        return out + [Outer(self, self.points, self.pair, d2)]


def site_terms(points: np.ndarray, cols: np.ndarray, factors: dict, K: np.ndarray) -> list:
    """`Curvature` terms of (point, engine site) pairs, one per site on the degrees of freedom that move it (its
    chain and the root: a third of the figure's), from factors {order: (q, k, nv)} and K (q, k, k)."""
    out = []
    for k in np.unique(cols):
        at = np.flatnonzero(cols == k)
        support = np.flatnonzero(np.abs(np.stack([f[at] for f in factors.values()])).max(axis=(0, 1, 2)) > 0)
        if support.size:
            out.append(Curvature(points[at], support, {r: f[at][..., support] for r, f in factors.items()}, K[at]))
    return out


def site_velocity_jacobians(state: PathState, points: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """(2, q, 3, nv) d(site velocity)/d(pose) [m/s per rad or m] and d(site velocity)/d(qvel) [m] of engine
    site cols[i] at quadrature point points[i], by the engine's own reverse pass (`SiteKinematics.vjp`,
    the pose in MuJoCo's tangent convention), one per site and axis."""
    res = state.forward_pass()
    z = np.zeros(res.sites.shape)
    J = np.empty((2, len(points), 3, state.motion.qvel.shape[1]))
    for k in np.unique(cols):
        at = np.flatnonzero(cols == k)
        for ax in range(3):
            g = np.zeros(res.sites.shape)
            g[:, k, ax] = 1.0
            gq, gv, _ = state.engine.vjp(res, None, z, g)
            J[0, at, ax], J[1, at, ax] = gq[points[at]], gv[points[at]]
    return J
