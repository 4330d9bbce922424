"""Constraints on the contact sites: heights above the surfaces and sliding along them.

Heights. A site's height h is the signed distance of its contact point (the site, or the lowest point of
its sphere where the figure rounds it: `solver.contacts.contact_radii`) above the supporting face of a
surface (`SupportSurfaces`: a plane, or a box's top over its footprint), with dh/dp = n, the face's
unit normal (where the support is chosen per point, the rounded distance to a box's top: continuously
differentiable across its edge). A `HeightBound` pair holds h <= limit (upper) or h >= limit (lower):

    penetration   h >= 0 at every point, every site, against the surface under it       [m]
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
from solver.path_state import PathState

#: [1/s] penetration is checked at least this often (`Penetration`): 1600 samples a second, finer than
#: the 1000 Hz the metrics sample at, so a corner clipped between two samples is under the tolerance
PENETRATION_RATE = 1600.0

__all__ = ["HeightBound", "Penetration", "SupportHeight", "SupportSlide", "site_heights"]


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
        np.add.at(gp, (self.rows, self.cols), (self.sign * g)[:, None] * n)
        state.add_sites(gp)


class Penetration(Constraint):
    """-d <= 0 at every (sample, site, surface): d the signed distance of the site's contact point to the
    surface (`StaticSurfaces.signed_distances`: a plane's free side, a box's outside), paper eq. 12 for
    every plane and box of the scene, a box's sides included.

    Sampled at the quadrature points and enough points between each two for PENETRATION_RATE, placed by cubic Hermite
    interpolation of the sites' positions and velocities at the points (exact for a site moving on a
    cubic; its error is h^4/384 max |p''''|, microns at 400 Hz): a toe crossing a box's edge at 3 m/s
    moves 7.5 mm between two points 2.5 ms apart and would clip the corner unseen.

    Args:
        surfaces: StaticSurfaces. radii: (k,) [m]. t: (n,) quadrature points [s]. sites: (k,) names.
        tolerance: [m].
    """

    name, unit, scale = "penetration", "mm", 1e-3

    def __init__(self, surfaces, radii, t: np.ndarray, sites, tolerance: float):
        self.surfaces, self.radii = surfaces, np.asarray(radii, float)
        n, K, S = len(t), len(sites), surfaces.count
        self.dt = np.diff(np.asarray(t, float))  # (n - 1,)
        self.sub = sub = max(0, int(np.ceil(PENETRATION_RATE * float(self.dt.max(initial=0.0)) - 1e-9)) - 1)
        u = np.arange(1, sub + 1) / (sub + 1)  # (j,) fractions of a spacing
        self.hermite = np.stack([2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2], 1)
        m = n + sub * (n - 1)  # samples: the points, then each fraction's n - 1 samples
        sample_row = np.r_[np.arange(n), np.tile(np.arange(n - 1), sub)]
        sample_series = np.r_[np.zeros(n, int), np.repeat(np.arange(1, sub + 1), n - 1)]
        self.shape = (m, K, S)
        self.rows = np.repeat(sample_row, K * S)
        self.cols = np.tile(np.repeat(np.arange(K), S), m)
        # one time series per (fraction, site, surface), consecutive rows within it; a group per (site, surface)
        self.group = np.tile(np.arange(K * S), m)
        self.series = np.repeat(sample_series, K * S) * (K * S) + self.group
        self._frac = np.repeat(np.r_[np.zeros(n), np.repeat(u, n - 1)], K * S)  # each pair's fraction of its spacing
        self.labels = np.asarray(sites, object)[self.cols]
        self.limit = np.zeros(len(self.rows))
        self.tolerance = float(tolerance)

    def pair_times(self, t: np.ndarray) -> np.ndarray:
        """(p,) the time [s] of each pair's sample, from the quadrature points t (n,)."""
        return t[self.rows] + self._frac * np.append(self.dt, 0.0)[self.rows]

    def pair_weights(self, weights: np.ndarray) -> np.ndarray:
        """Each sample stands for an equal share of its point's weight [s]."""
        return weights[self.rows] / (self.sub + 1)

    def _samples(self, state) -> np.ndarray:
        """(m, k, 3) the lowest points of the sites at the samples [m]."""
        p, v = state.sites, state.site_velocities
        H = self.hermite[:, :, None, None, None]
        dt = self.dt[None, :, None, None]
        sub = H[:, 0] * p[None, :-1] + H[:, 1] * dt * v[None, :-1] + H[:, 2] * p[None, 1:] + H[:, 3] * dt * v[None, 1:]
        out = np.concatenate([p, sub.reshape(-1, *p.shape[1:])], axis=0)
        out[..., 2] -= self.radii
        return out

    def _distances(self, state):
        key = ("distances", id(self))
        hit = state.cache.get(key)
        if hit is None:
            hit = state.cache[key] = self.surfaces.signed_distances(self._samples(state))  # (m, K, S), (m, K, S, 3)
        return hit

    def measure(self, state):
        d, _ = self._distances(state)
        return -d.ravel()

    def pull(self, state, g):
        on = np.flatnonzero(g)
        if not on.size:
            return
        _, grad = self._distances(state)
        i, k, s = np.unravel_index(on, self.shape)
        gs = np.zeros(self.shape[:2] + (3,))
        np.add.at(gs, (i, k), -g[on, None] * grad[i, k, s])
        n = len(self.dt) + 1
        gp, gv = gs[:n].copy(), np.zeros((n,) + gs.shape[1:])
        sub = gs[n:].reshape(self.sub, n - 1, *gs.shape[1:])
        H, dt = self.hermite, self.dt[None, :, None, None]
        gp[:-1] += np.einsum("j,jnkc->nkc", H[:, 0], sub)
        gp[1:] += np.einsum("j,jnkc->nkc", H[:, 2], sub)
        gv[:-1] += np.einsum("j,jnkc->nkc", H[:, 1], dt * sub)
        gv[1:] += np.einsum("j,jnkc->nkc", H[:, 3], dt * sub)
        state.add_sites(gp, gv)


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
    """Mean height of the support site over each foot contact <= limit [m] (`_FootSupport`)."""

    name, unit, scale = "planted", "mm", 1e-3

    def __init__(self, *args, limit, tolerance: float):
        super().__init__(*args)
        self.limit = np.asarray(limit, float)
        self.tolerance = float(tolerance)

    def measure(self, state):
        h, _ = self.heights(state)
        return self._sum(h) / self.span

    def pull(self, state, g):
        _, n = self.heights(state)
        gp = np.zeros(state.sites.shape)
        np.add.at(gp, (self.points, self.cols), (g[self.pair] * self.w / self.span[self.pair])[:, None] * n)
        state.add_sites(gp)


class SupportSlide(_FootSupport):
    """Distance the support site slides along its surface over each foot contact, integral of
    huber_b(|v_t|) dt, <= limit [m] (`_FootSupport`; b the Huber width [m/s])."""

    name, unit, scale = "slide", "mm", 1e-3

    def __init__(self, *args, limit, tolerance: float, width: float):
        super().__init__(*args)
        self.limit = np.asarray(limit, float)
        self.tolerance, self.b = float(tolerance), float(width)

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
        s = np.sqrt((vt * vt).sum(1))
        hub = np.where(s <= self.b, 0.5 * s * s / self.b, s - 0.5 * self.b)
        return self._sum(hub)

    def pull(self, state, g):
        vt = self._tangential(state)
        s = np.sqrt((vt * vt).sum(1))
        dc = np.where(s <= self.b, 1.0 / self.b, 1.0 / np.maximum(s, 1e-300))
        gv = np.zeros(state.sites.shape)
        np.add.at(gv, (self.points, self.cols), (g[self.pair] * self.w * dc)[:, None] * vt)
        state.add_sites(None, gv)
