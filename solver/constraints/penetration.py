"""No contact site inside a surface, at any instant of the continuous path (paper eq. 12, every plane and box).

Between two quadrature points t_i and t_i+1 = t_i + h a site's contact point (the site, less its sphere's
radius: `solver.contacts.contact_radii`) moves on the cubic Hermite curve of its positions and velocities
at the two,

    q(u) = H00(u) p_i + H10(u) h v_i + H01(u) p_i+1 + H11(u) h v_i+1,   u in [0, 1]

(exact for a site moving on a cubic; its error is h^4/384 max |p''''|, microns at 200 Hz). The constraint
is the deepest point of each interval, -min_u d(q(u)) <= 0, d the signed distance to the surface
(`StaticSurfaces`): sampled instants miss a heel that clips a box's edge at 5 m/s for a millisecond, and
a path that meets the bound at samples breaks it between them.

    plane   d(q(u)) is a cubic in u: its minimum over [0, 1] is at an end or where d' = 0 (closed form)
    box     d is the largest of the faces' distances inside (a kink where the nearest face changes): the
            best of PENETRATION_RATE samples, golden-section search around it, and at the final bracket
            the point where its two sides' tangent lines meet (exact at a kink between two faces)

The value's gradient is grad d at the minimizer times the Hermite weights there: the minimizer's own
motion does not change the minimum to first order (the envelope theorem); at a kink it is the
combination of the two faces' gradients whose slope along the curve is zero (Danskin's theorem for a
min-max: Bertsekas, Nonlinear Programming, 2nd ed., 1999, prop. B.25).
"""
from __future__ import annotations

from functools import partial

import numpy as np

from solver.constraints.base import Constraint
from solver.path_state import add_at

__all__ = ["GOLDEN_STEPS", "PENETRATION_RATE", "Penetration", "SoleEdges"]

#: [1/s] the samples a box's pairs are searched at before the golden-section search: 1600 a second, eight
#: per interval at 200 Hz, so the nearest face changes at most once between two samples of a foot
PENETRATION_RATE = 1600.0
#: [steps] golden-section steps within the best sample's two spacings: each keeps 0.618 of the bracket, so 8
#: leave 2 % of it, enough to hold one kink, which the tangent lines then place exactly
GOLDEN_STEPS = 8


def _hermite(u: np.ndarray) -> np.ndarray:
    """The cubic Hermite basis (H00, H10, H01, H11) at u: (4, *u.shape)."""
    u = np.asarray(u, float)
    return np.stack([2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2])


def _bezier(C: np.ndarray) -> np.ndarray:
    """(4, ..., 3) the Bezier points p_i, p_i + h v_i / 3, p_i+1 - h v_i+1 / 3, p_i+1 of the Hermite curves
    C (4, ..., 3): each curve lies in their convex hull."""
    return np.stack([C[0], C[0] + C[1] / 3, C[2] - C[3] / 3, C[2]])


def _power(C: np.ndarray) -> np.ndarray:
    """The curves' coefficients in the power basis, q(u) = A u^3 + B u^2 + C u + D: (4, ..., 3) from the
    Hermite coefficients (p_i, h v_i, p_i+1, h v_i+1) (4, ..., 3)."""
    p0, m0, p1, m1 = C
    return np.stack([2 * p0 + m0 - 2 * p1 + m1, -3 * p0 - 2 * m0 + 3 * p1 - m1, m0, p0])


def _curve(W: np.ndarray, u: np.ndarray, order: int = 0) -> np.ndarray:
    """(..., 3) the curves with power coefficients W (4, ..., 3) (`_power`) at u (...,), or their
    order-th u-derivative (Horner's scheme)."""
    u = np.asarray(u, float)[..., None]
    A, B, C, D = W
    if order == 0:
        return ((A * u + B) * u + C) * u + D
    if order == 1:
        return (3 * A * u + 2 * B) * u + C
    return 6 * A * u + 2 * B


def plane_minimum(C: np.ndarray, point: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u*, d) the lowest point of each curve over the plane through `point` with unit `normal`.

    Args:
        C: (4, ..., 3) Hermite coefficients [m]. point, normal: (3,).
    Returns:
        u*: (...,) in [0, 1]. d: (...,) [m] the signed distance there.
    """
    c3, c2, c1, c0 = np.einsum("j...c,c->j...", _power(C), normal)  # the distance's power coefficients
    c0 = c0 - normal @ point
    # d'(u) = 3 c3 u^2 + 2 c2 u + c1: its roots in [0, 1] and the two ends are the candidates, the roots
    # in the form that stays exact as c3 -> 0 (Press et al., Numerical Recipes, 3rd ed., sec. 5.6); a
    # candidate that is no root (no real roots, a root outside [0, 1], clipped) is never lower than the minimum
    q = -(c2 + np.where(c2 >= 0, 1.0, -1.0) * np.sqrt(np.maximum(c2 * c2 - 3 * c3 * c1, 0.0)))
    with np.errstate(divide="ignore", invalid="ignore"):
        r1, r2 = q / (3 * c3), c1 / q
    cand = np.stack([np.zeros_like(c1), np.ones_like(c1), np.nan_to_num(r1), np.nan_to_num(r2)])
    cand = np.clip(cand, 0.0, 1.0)
    values = ((c3 * cand + c2) * cand + c1) * cand + c0
    best = np.argmin(values, axis=0)
    return np.take_along_axis(cand, best[None], 0)[0], np.take_along_axis(values, best[None], 0)[0]


def _golden(C: np.ndarray, a: np.ndarray, b: np.ndarray, depth) -> tuple[np.ndarray, ...]:
    """(u, d, a, b) the lowest point of each curve (power coefficients C (4, q, 3), `_power`) on [a, b] (q,),
    the distance unimodal there, and the final bracket: golden-section search (Kiefer, "Sequential minimax search for a maximum", Proc. AMS 4, 1953), then the
    vertex of the parabola through the best point and its neighbours, which places a smooth minimum to
    third order in the bracket (so that it moves continuously with the curve)."""
    r = 0.5 * (np.sqrt(5.0) - 1.0)
    c1, c2 = b - r * (b - a), a + r * (b - a)
    f1, f2 = depth(_curve(C, c1)), depth(_curve(C, c2))
    for _ in range(GOLDEN_STEPS):
        left = f1 <= f2  # the minimum is in [a, c2]: c2 is the new right end, c1 the new inner right point
        a, b = np.where(left, a, c1), np.where(left, c2, b)
        keep, f_keep = np.where(left, c1, c2), np.where(left, f1, f2)
        new = np.where(left, b - r * (b - a), a + r * (b - a))
        f_new = depth(_curve(C, new))
        c1, c2 = np.where(left, new, keep), np.where(left, keep, new)
        f1, f2 = np.where(left, f_new, f_keep), np.where(left, f_keep, f_new)
    fa, fb = depth(_curve(C, a)), depth(_curve(C, b))
    left = f1 <= f2
    x0, x1, x2 = np.where(left, a, c1), np.where(left, c1, c2), np.where(left, c2, b)
    y0, y1, y2 = np.where(left, fa, f1), np.where(left, f1, f2), np.where(left, f2, fb)
    num = (x1 - x0) ** 2 * (y1 - y2) - (x1 - x2) ** 2 * (y1 - y0)
    den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0)
    vertex = np.where(den != 0, np.clip(x1 - 0.5 * num / np.where(den != 0, den, 1.0), a, b), x1)
    fv = depth(_curve(C, vertex))
    return np.where(fv <= y1, vertex, x1), np.minimum(fv, y1), a, b


def _kinks(C: np.ndarray, u: np.ndarray, a: np.ndarray, b: np.ndarray, distance) -> tuple[np.ndarray, ...]:
    """(u, d, grad d) at each curve's (power coefficients C, `_power`) lowest point found at u (q,) in the
    bracket [a, b]: where the distance falls into the bracket on one box face and rises out of it on
    another (both planes there), the point where the two faces' distances are equal; elsewhere u."""
    d, g = distance(_curve(C, u))
    a, b = np.minimum(a, u), np.maximum(b, u)
    fa, ga = distance(_curve(C, a))
    fb, gb = distance(_curve(C, b))
    sa = np.einsum("qc,qc->q", ga, _curve(C, a, 1))
    sb = np.einsum("qc,qc->q", gb, _curve(C, b, 1))
    kink = np.flatnonzero((sa < 0) & (sb > 0) & (fa < 0) & (fb < 0) & (ga != gb).any(axis=1))
    if not kink.size:
        return u, d, g
    Ck, ga, gb, a, b = C[:, kink], ga[kink], gb[kink], a[kink], b[kink]
    ka = np.einsum("qc,qc->q", ga, _curve(Ck, a)) - fa[kink]  # each face's distance: d = g . q - k
    kb = np.einsum("qc,qc->q", gb, _curve(Ck, b)) - fb[kink]
    # one Newton step from where the two faces' tangent lines at the bracket's ends meet: the faces'
    # difference is a cubic in u, so the step's error is of the order of the bracket's width squared
    sa_, sb_ = sa[kink], sb[kink]
    uk = np.clip((fa[kink] - fb[kink] - sa_ * a + sb_ * b) / (sb_ - sa_), a, b)
    gap = np.einsum("qc,qc->q", ga - gb, _curve(Ck, uk)) - (ka - kb)
    slope = np.einsum("qc,qc->q", ga - gb, _curve(Ck, uk, 1))
    uk = np.clip(uk - gap / np.where(slope != 0, slope, 1.0), a, b)
    q1 = _curve(Ck, uk, 1)
    s1, s2 = np.einsum("qc,qc->q", ga, q1), np.einsum("qc,qc->q", gb, q1)
    mu = np.clip(s2 / np.where(s2 > s1, s2 - s1, 1.0), 0.0, 1.0)
    u, d, g = u.copy(), d.copy(), g.copy()
    u[kink] = uk
    d[kink] = np.einsum("qc,qc->q", ga, _curve(Ck, uk)) - ka
    g[kink] = mu[:, None] * ga + (1 - mu[:, None]) * gb
    return u, d, g


def box_minimum(C: np.ndarray, grid: np.ndarray, distance, depth=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u*, d, grad d) the deepest point of each curve in a box (module docstring): every local minimum
    of the samples is searched within a spacing on each side (`_golden`), the deepest kept and, at a kink
    between two faces, placed exactly (`_kinks`).

    Args:
        C: (4, q, 3) Hermite coefficients [m]. grid: (j,) the sample fractions, 0 and 1 included.
        distance: f(points (q, 3)) -> (d (q,), grad (q, 3)), each curve's point against its own box.
        depth: f(points (..., 3)) -> d (...,), `distance`'s d alone (the same numbers, cheaper); None: from `distance`.
    Returns:
        u*: (q,). d: (q,) [m]. grad: (q, 3), the combination at a kink (module docstring).
    """
    depth = depth or (lambda points: distance(points)[0])
    W = _power(C)
    samples = depth(_curve(W[:, None], np.broadcast_to(grid[:, None], (len(grid), C.shape[1]))))  # (j, q)
    padded = np.pad(samples, ((1, 1), (0, 0)), constant_values=np.inf)
    step = 1.0 / (len(grid) - 1)
    # |d'| <= |q'| <= 3 times the longest leg of the Bezier polygon: a sample's basin reaches at most that
    # times a spacing below it, so the local minima that cannot beat the best sample are not searched
    slope = 3 * np.linalg.norm(np.diff(_bezier(C), axis=0), axis=-1).max(axis=0)
    local = (samples <= padded[:-2]) & (samples <= padded[2:]) & (samples <= samples.min(axis=0) + slope * step)
    j, q = np.nonzero(local)
    us, ds, a, b = _golden(W[:, q], np.maximum(grid[j] - step, 0.0), np.minimum(grid[j] + step, 1.0), depth)
    us, ds = np.where(samples[j, q] < ds, grid[j], us), np.minimum(samples[j, q], ds)  # a sample deeper: an end
    order = np.lexsort((ds, q))
    first = order[np.r_[True, q[order][1:] != q[order][:-1]]]  # the deepest search of each curve
    return _kinks(W, us[first], a[first], b[first], distance)


class Penetration(Constraint):
    """-min_u d(q(u)) <= 0 [m] for every (interval, site, surface) (module docstring).

    Args:
        surfaces: StaticSurfaces. radii: (k,) [m]. t: (n,) quadrature points [s]. sites: (k,) names.
        tolerance: [m]. columns: (k,) each site's index among the engine's sites (None: the first k).
    """

    name, unit, scale = "penetration", "mm", 1e-3

    def __init__(self, surfaces, radii, t: np.ndarray, sites, tolerance: float, columns=None):
        self.surfaces, self.radii = surfaces, np.asarray(radii, float)
        self.sites = tuple(sites)
        self.columns = np.arange(len(sites)) if columns is None else np.asarray(columns, int)
        t = np.asarray(t, float)
        m, K, S = max(len(t) - 1, 0), len(sites), surfaces.count
        self.dt = np.diff(t)  # (m,) interval lengths [s]
        per = max(1, int(np.ceil(PENETRATION_RATE * float(self.dt.max(initial=0.0)) - 1e-9)))
        self.grid = np.arange(per + 1) / per  # a box's samples over an interval, both ends included
        self.shape = (m, K, S)
        self.rows = np.repeat(np.arange(m), K * S)  # an interval's first quadrature point
        self.cols = np.tile(np.repeat(np.arange(K), S), m)
        self.series = self.group = np.tile(np.arange(K * S), m)  # one time series per (site, surface)
        self.labels = np.asarray(sites, object)[self.cols]
        self.limit = np.zeros(len(self.rows))
        self.tolerance = float(tolerance)
        self._mid = 0.5 * (t[:-1] + t[1:])

    def pair_times(self, t: np.ndarray) -> np.ndarray:
        """(p,) the time [s] each pair stands for: its interval's midpoint."""
        return self._mid[self.rows]

    def pair_weights(self, weights: np.ndarray) -> np.ndarray:
        """Each interval stands for its length [s]."""
        return self.dt[self.rows]

    def _minimum(self, state):
        """(u*, d, grad d), each (m, K, S) (grad (m, K, S, 3)), at every pair's deepest point; once per state."""
        key = ("penetration", id(self))
        hit = state.cache.get(key)
        if hit is not None:
            return hit
        p, v = state.sites[:, self.columns], state.site_velocities[:, self.columns]
        low = p.copy()
        low[..., 2] -= self.radii
        h = self.dt[:, None, None]
        C = np.stack([low[:-1], h * v[:-1], low[1:], h * v[1:]])  # (4, m, K, 3)
        s = self.surfaces
        u, d, g = np.empty(self.shape), np.empty(self.shape), np.empty(self.shape + (3,))
        for j, (point, normal) in enumerate(zip(s.plane_point, s.plane_normal)):
            u[..., j], d[..., j] = plane_minimum(C, point, normal)
            g[..., j, :] = normal
        if len(s.box_center):
            self._boxes(C, u, d, g)
        state.cache[key] = hit = (u, d, g)
        return hit

    def _boxes(self, C: np.ndarray, u: np.ndarray, d: np.ndarray, g: np.ndarray) -> None:
        """Fill the box pairs of u, d, g (`_minimum`) from the Hermite curves C (4, m, K, 3). In place."""
        s = self.surfaces
        flat = C.reshape(4, -1, 3)
        # a curve lies within `reach` of the mean of its Bezier points, so (d being 1-Lipschitz) at least
        # d(mean) - reach from a box
        bez = _bezier(flat)
        mean = bez.mean(axis=0)
        reach = np.linalg.norm(bez - mean, axis=-1).max(axis=0)
        half = np.full(len(mean), 0.5)
        middle = _curve(_power(flat), half)
        for b in range(len(s.box_center)):
            j = len(s.plane_point) + b
            distance, depth = partial(s.box_distance, b=b), partial(s.box_depth, b=b)
            # a curve farther than the tolerance from the box is met with a margin and cannot be active:
            # its midpoint's distance stands for it; the rest are searched
            ub, (db, gb) = half.copy(), distance(middle)
            near = np.flatnonzero(depth(mean) - reach <= self.tolerance)
            if near.size:
                ub[near], db[near], gb[near] = box_minimum(flat[:, near], self.grid, distance, depth)
            u[..., j], d[..., j], g[..., j, :] = ub.reshape(self.shape[:2]), db.reshape(self.shape[:2]), gb.reshape(self.shape[:2] + (3,))

    def measure(self, state):
        return -self._minimum(state)[1].ravel()

    def pull(self, state, g):
        on = np.flatnonzero(g)
        if not on.size:
            return
        u, _, grad = self._minimum(state)
        i, k, s = np.unravel_index(on, self.shape)
        H = _hermite(u[i, k, s])  # (4, q)
        gq = -g[on, None] * grad[i, k, s]  # (q, 3) d c / d contact point
        gp, gv = np.zeros(state.sites.shape), np.zeros(state.sites.shape)
        h = self.dt[i, None]
        k = self.columns[k]
        add_at(gp, (i, k), H[0][:, None] * gq)
        add_at(gv, (i, k), H[1][:, None] * h * gq)
        add_at(gp, (i + 1, k), H[2][:, None] * gq)
        add_at(gv, (i + 1, k), H[3][:, None] * h * gq)
        state.add_sites(gp, gv)

    def curvature(self, state, d1, d2):
        """d2 grad c grad c^T with grad c = -grad d^T (H00 dp_i + H10 h dv_i + H01 dp_i+1 + H11 h dv_i+1) (`pull`),
        each pair kept at its two points apart (the product's blocks across them are left out); d's own
        curvature (zero on a plane's face) is left out."""
        from solver.constraints.sites import site_terms, site_velocity_jacobians

        on = np.flatnonzero(d2 > 0)
        if not on.size:
            return []
        u, _, grad = self._minimum(state)
        i, k, s = np.unravel_index(on, self.shape)
        H = _hermite(u[i, k, s])
        h = self.dt[i, None]
        grad, col = grad[i, k, s], self.columns[k]
        out = []
        for pts, wp, wv in ((i, H[0], H[1]), (i + 1, H[2], H[3])):
            J = site_velocity_jacobians(state, pts, col)  # (2, q, 3, nv): d v / d pose, d v / d qvel (= d p / d pose)
            dp, dv0 = np.einsum("qa,qan->qn", grad, J[1]), np.einsum("qa,qan->qn", grad, J[0])
            f0 = -(wp[:, None] * dp + (wv[:, None] * h) * dv0)
            f1 = -(wv[:, None] * h) * dp
            out += site_terms(pts, col, {0: f0[:, None, :], 1: f1[:, None, :]}, d2[on, None, None])
        return out


class SoleEdges(Penetration):
    """The soles' edges (`solver.figure.Figure.soles`) of a clean out of every surface, as `Penetration` holds the
    contact sites, but no deeper than the capture holds them: -min_u d(q(u)) <= limit [m], the limit of each pair
    the capture's own depth there (0 where it is out). A capture rests its feet rolled by a few degrees, an edge a few
    millimetres into the floor; what the constraint stops is a new roll onto an edge (docs/contacts.md, "The
    soles' edges").

    Args:
        as `Penetration`; radii are 0 (the edges are points). witness: the capture's PathState at the points.
    """

    name = "sole"

    def __init__(self, surfaces, t: np.ndarray, sites, tolerance: float, columns, witness):
        super().__init__(surfaces, np.zeros(len(sites)), t, sites, tolerance, columns)
        self.limit = np.maximum(0.0, self.measure(witness))
