"""No contact site inside a surface, at any instant of the continuous path (paper eq. 12, every plane and box).

Between two quadrature points t_i and t_i+1 = t_i + h a site's contact point (the site, less its sphere's
radius: `solver.contacts.contact_radii`) moves on the cubic Hermite curve of its positions and velocities
at the two,

    q(u) = H00(u) p_i + H10(u) h v_i + H01(u) p_i+1 + H11(u) h v_i+1,   u in [0, 1]

(exact for a site moving on a cubic; its error is h^4/384 max |p''''|, microns at 200 Hz). The constraint
is the deepest point of each interval, -min_u d(q(u)) <= 0, d the surface's distance (`StaticSurfaces`):
sampled instants miss a heel that clips a box's edge at 5 m/s for a millisecond, and a path that meets the
bound at samples breaks it between them. The deepest point is found exactly, as a cubic's:

    plane   d(q(u)) is a cubic in u: its minimum over [0, 1] is at an end or where d' = 0
    box     d is the largest of the six faces' distances, each a cubic in u: the signed distance inside the
            box and positive outside it (below the Euclidean distance near an edge or corner), so that
            -min d <= tol (tol >= 0) holds on the same curves as with the Euclidean distance. The least of
            the faces' upper envelope is at an end, where one face is stationary, or where two cross: those
            candidates, roots of quadratics and cubics in closed form (`solver.polynomial_roots`), are
            compared

The value's gradient is grad d at the minimizer times the Hermite weights there: the minimizer's own
motion does not change the minimum to first order (the envelope theorem); at a kink it is the
combination of the two faces' gradients whose slope along the curve is zero (Danskin's theorem for a
min-max: Bertsekas, Nonlinear Programming, 2nd ed., 1999, prop. B.25).
"""
from __future__ import annotations

import numpy as np

from solver.constraints.base import Constraint
from solver.path_state import add_at
from solver.polynomial_roots import cubic_roots, quadratic_roots

__all__ = ["Penetration", "SoleEdges"]


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
    # d'(u) = 3 c3 u^2 + 2 c2 u + c1: its roots in [0, 1] and the two ends are the candidates; a candidate that
    # is no root (no real roots, a root outside [0, 1], clipped) is never lower than the minimum
    roots = np.moveaxis(quadratic_roots(3 * c3, 2 * c2, c1), -1, 0)
    cand = np.clip(np.nan_to_num(np.concatenate([np.stack([np.zeros_like(c1), np.ones_like(c1)]), roots])), 0.0, 1.0)
    values = ((c3 * cand + c2) * cand + c1) * cand + c0
    best = np.argmin(values, axis=0)
    return np.take_along_axis(cand, best[None], 0)[0], np.take_along_axis(values, best[None], 0)[0]


def _box_faces(L: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(4, ..., 6) the power coefficients of the six faces' distances along curves whose box coordinates have power
    coefficients L (4, ..., 3): face f is axis f % 3 on the + side (f < 3) or the - side, s L_k - h_k."""
    F = np.concatenate([L, -L], axis=-1)
    F[3] -= np.concatenate([half, half])
    return F


def _face_distance(points: np.ndarray, center: np.ndarray, rot: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, ...]:
    """(d, grad) the largest face distance of points (q, 3) to a box (`box_minimum`), (q,) [m], and its face's outward
    normal (q, 3)."""
    local = (points - center) @ rot
    faces = np.concatenate([local, -local], axis=-1) - np.concatenate([half, half])
    top = np.argmax(faces, axis=-1)
    return faces[np.arange(len(top)), top], np.concatenate([rot.T, -rot.T])[top]


#: (15, 2) the pairs of faces (`_box_faces`) whose crossing can hold a curve's deepest point in a box
_PAIRS = np.array([(f, g) for f in range(6) for g in range(f + 1, 6)])


def box_minimum(C: np.ndarray, center: np.ndarray, rot: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, ...]:
    """(u*, d, grad d) the deepest point of each curve in a box (module docstring), exactly.

    d is the largest of the six faces' distances, each a cubic in u along a curve, and the least of such an upper
    envelope over [0, 1] lies at an end, where one face's cubic is stationary, or where two faces cross: the two ends,
    the 6 stationary points and the 45 crossings (`solver.polynomial_roots`) are evaluated and the deepest kept. At a
    crossing the gradient is the combination of the two faces' normals whose slope along the curve is zero.

    Args:
        C: (4, q, 3) Hermite coefficients [m]. center: (3,) [m]. rot: (3, 3) the box's axes as columns. half: (3,) [m].
    Returns:
        u*: (q,). d: (q,) [m] the largest face distance there. grad: (q, 3) its gradient in the curve's point.
    """
    L = _power(C) @ rot
    L[3] -= center @ rot
    F = _box_faces(L, half)  # (4, q, 6)
    ends = np.broadcast_to(np.array([0.0, 1.0]), (C.shape[1], 2))
    stationary = quadratic_roots(3 * L[0], 2 * L[1], L[2]).reshape(-1, 6)
    # a face below the envelope's least bound all along the curve is never on it: its crossings are not sought (each
    # face's cubic lies between its least and largest value at the Bezier points)
    B = _bezier(C) @ rot - center @ rot
    at = np.concatenate([B, -B], axis=-1) - np.concatenate([half, half])  # (4, q, 6)
    on = at.max(axis=0) >= at.min(axis=0).max(axis=-1, keepdims=True)
    i, k = np.nonzero(on[:, _PAIRS[:, 0]] & on[:, _PAIRS[:, 1]])
    crossing = np.full((C.shape[1], len(_PAIRS), 3), np.nan)
    crossing[i, k] = cubic_roots(*(F[:, i, _PAIRS[k, 0]] - F[:, i, _PAIRS[k, 1]]))
    crossing = crossing.reshape(-1, 3 * len(_PAIRS))
    cand = np.clip(np.nan_to_num(np.concatenate([ends, stationary, crossing], axis=1), nan=0.0), 0.0, 1.0)
    depth = (abs(_curve(L[:, :, None], cand)) - half).max(axis=-1)  # (q, 53)
    best = np.argmin(depth, axis=1)
    rows = np.arange(len(best))
    u, d = cand[rows, best], depth[rows, best]
    Lu, slope = _curve(L, u), _curve(L, u, 1)
    faces = np.concatenate([Lu, -Lu], axis=-1) - np.concatenate([half, half])
    normals = np.concatenate([rot.T, -rot.T])  # (6, 3) each face's outward normal in world coordinates
    top = np.argmax(faces, axis=1)
    cross = best - ends.shape[1] - stationary.shape[1]  # the crossing candidate's index (>= 0 where it is one)
    f, g = _PAIRS[np.clip(cross, 0, None) // 3].T  # its two faces
    sf, sg = (np.take_along_axis(np.concatenate([slope, -slope], axis=-1), x[:, None], 1)[:, 0] for x in (f, g))
    kink = (cross >= 0) & (sf * sg < 0)  # falling into the crossing on one face and rising out of it on the other
    mu = np.where(kink, sg / np.where(kink, sg - sf, 1.0), 1.0)[:, None]
    grad = np.where(kink[:, None], mu * normals[f] + (1 - mu) * normals[g], normals[top])
    return u, d, grad


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
        bez, middle = _bezier(flat), _curve(_power(flat), np.full(flat.shape[1], 0.5))
        for b, (center, rot, half) in enumerate(zip(s.box_center, s.box_rot, s.box_half)):
            j = len(s.plane_point) + b
            # each face's distance is affine in the point, so along a curve at least its least at the Bezier points
            # (a convex combination of them): a curve whose bound is over the tolerance is out of the box with a
            # margin and cannot be active, and its midpoint's distance stands for it; the rest are solved
            local = (bez - center) @ rot  # (4, q, 3)
            low = (np.concatenate([local, -local], axis=-1).min(axis=0) - np.concatenate([half, half])).max(axis=-1)
            ub, (db, gb) = np.full(len(middle), 0.5), _face_distance(middle, center, rot, half)
            near = np.flatnonzero(low <= self.tolerance)
            if near.size:
                ub[near], db[near], gb[near] = box_minimum(flat[:, near], center, rot, half)
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
