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


def _cubic_minimum(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u*, value) the least of cubics with power coefficients c (4, ...) (c3 u^3 + c2 u^2 + c1 u + c0) over [0, 1]:
    at an end or where the derivative 3 c3 u^2 + 2 c2 u + c1 vanishes. u*, value: (...,)."""
    c3, c2, c1, c0 = (x[..., None] for x in c)
    cand = np.empty(c1.shape[:-1] + (4,))
    cand[..., 0], cand[..., 1] = 0.0, 1.0
    # a candidate that is no root (NaN: no real roots; fmax makes it 0) or one outside [0, 1], clipped, is never
    # lower than the minimum
    cand[..., 2:] = np.minimum(np.fmax(quadratic_roots(3 * c3[..., 0], 2 * c2[..., 0], c1[..., 0]), 0.0), 1.0)
    values = ((c3 * cand + c2) * cand + c1) * cand + c0
    best = np.argmin(values, axis=-1)[..., None]
    return np.take_along_axis(cand, best, -1)[..., 0], np.take_along_axis(values, best, -1)[..., 0]


def plane_minimum(C: np.ndarray, point: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u*, d) the lowest point of each curve over the plane through `point` with unit `normal`.

    Args:
        C: (4, ..., 3) Hermite coefficients [m]. point, normal: (3,).
    Returns:
        u*: (...,) in [0, 1]. d: (...,) [m] the signed distance there.
    """
    c = np.einsum("j...c,c->j...", _power(C), normal)  # the distance's power coefficients
    c[3] -= normal @ point
    return _cubic_minimum(c)


def _box_frame(X: np.ndarray, center: np.ndarray, rot: np.ndarray, half: np.ndarray, power: bool = False) -> np.ndarray:
    """(..., q, 6) the six faces' distances s x_k - h_k [m] of points X (..., q, 3) in per-curve boxes (center (q, 3),
    rot (q, 3, 3), half (q, 3)): face f is box axis f % 3 on the + side (f < 3) or the - side. power: X (4, q, 3)
    holds curves' power coefficients (`_power`), of which only the constant one is offset."""
    local = np.einsum("...qc,qck->...qk", X, rot)
    off = np.einsum("qc,qck->qk", center, rot)
    if power:
        local[3] -= off
    else:
        local = local - off
    F = np.concatenate([local, -local], axis=-1)
    h2 = np.concatenate([half, half], axis=-1)
    if power:
        F[3] -= h2
        return F
    return F - h2


def _normals(rot: np.ndarray) -> np.ndarray:
    """(q, 6, 3) the outward normals (world) of the faces (`_box_frame`) of boxes with axes rot (q, 3, 3) as columns."""
    axes = np.swapaxes(rot, -1, -2)
    return np.concatenate([axes, -axes], axis=-2)


#: (15, 2) the pairs of faces (`_box_frame`) whose crossing can hold a curve's deepest point in a box
_PAIRS = np.array([(f, g) for f in range(6) for g in range(f + 1, 6)])


def box_minimum(C: np.ndarray, center: np.ndarray, rot: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, ...]:
    """(u*, d, grad d) the deepest point of each curve in a box (module docstring), exactly.

    d is the largest of the six faces' distances, each a cubic in u along a curve. Where one face alone can be on
    that upper envelope (the others' largest value at the curve's Bezier points is under the envelope's least bound
    there: a face's cubic lies between its least and largest Bezier value), d is that face's cubic, least at an end
    or where it is stationary, and its gradient the face's normal. Elsewhere `_envelope_minimum` solves it.

    Args:
        C: (4, q, 3) Hermite coefficients [m]. center: (3,) or (q, 3) [m]. rot: (3, 3) or (q, 3, 3) the box's axes
            as columns. half: (3,) or (q, 3) [m]: one box, or each curve's own.
    Returns:
        u*: (q,). d: (q,) [m] the largest face distance there. grad: (q, 3) its gradient in the curve's point.
    """
    q = C.shape[1]
    center, rot, half = (np.broadcast_to(x, (q,) + np.shape(x)[-k:]) for x, k in ((center, 1), (rot, 2), (half, 1)))
    F = _box_frame(_power(C), center, rot, half, power=True)  # (4, q, 6) the faces' power coefficients
    at = _box_frame(_bezier(C), center, rot, half)  # (4, q, 6) the faces at the Bezier points
    on = at.max(axis=0) >= at.min(axis=0).max(axis=-1, keepdims=True)  # (q, 6) faces that can be on the envelope
    normals, rows = _normals(rot), np.arange(q)
    face = np.argmax(on, axis=1)  # the face where it is alone
    u, d = _cubic_minimum(F[:, rows, face])
    grad = normals[rows, face]
    many = np.flatnonzero(on.sum(axis=1) > 1)
    if many.size:
        u[many], d[many], grad[many] = _envelope_minimum(F[:, many], on[many], normals[many])
    return u, d, grad


def _envelope_minimum(F: np.ndarray, on: np.ndarray, normals: np.ndarray) -> tuple:
    """(u*, d, grad d) of `box_minimum` for curves whose faces' distances have power coefficients F (4, q, 6), `on`
    (q, 6) the faces that can be on the envelope, and the faces' `normals` (q, 6, 3): the least of the upper envelope
    is at an end, where one face's cubic is stationary, or where two faces cross: the two ends, the 6 stationary
    points and the crossings of the faces on it (`solver.polynomial_roots`) are evaluated and the deepest kept. At a
    crossing the gradient is the combination of the two faces' normals whose slope along the curve is zero."""
    q = F.shape[1]
    ends = np.broadcast_to(np.array([0.0, 1.0]), (q, 2))
    stationary = quadratic_roots(3 * F[0, :, :3], 2 * F[1, :, :3], F[2, :, :3]).reshape(-1, 6)  # -x: the same points
    i, k = np.nonzero(on[:, _PAIRS[:, 0]] & on[:, _PAIRS[:, 1]])
    crossing = np.full((q, len(_PAIRS), 3), np.nan)
    crossing[i, k] = cubic_roots(*(F[:, i, _PAIRS[k, 0]] - F[:, i, _PAIRS[k, 1]]))
    crossing = crossing.reshape(-1, 3 * len(_PAIRS))
    cand = np.clip(np.nan_to_num(np.concatenate([ends, stationary, crossing], axis=1), nan=0.0), 0.0, 1.0)
    depth = _curve(F[:, :, None], cand).max(axis=-1)  # (q, 53)
    rows = np.arange(q)
    best = np.argmin(depth, axis=1)
    u, d = cand[rows, best], depth[rows, best]
    faces, slope = _curve(F, u), _curve(F, u, 1)
    top = np.argmax(faces, axis=1)
    cross = best - ends.shape[1] - stationary.shape[1]  # the crossing candidate's index (>= 0 where it is one)
    f, g = _PAIRS[np.clip(cross, 0, None) // 3].T  # its two faces
    sf, sg = slope[rows, f], slope[rows, g]
    kink = (cross >= 0) & (sf * sg < 0)  # falling into the crossing on one face and rising out of it on the other
    mu = np.where(kink, sg / np.where(kink, sg - sf, 1.0), 1.0)[:, None]
    grad = np.where(kink[:, None], mu * normals[rows, f] + (1 - mu) * normals[rows, g], normals[rows, top])
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
        """Fill the box pairs of u, d, g (`_minimum`) from the Hermite curves C (4, m, K, 3). In place.

        Each face's distance is affine in the point, so along a curve at least its least at the Bezier points (a
        convex combination of them): a curve whose bound is over the tolerance is out of the box with a margin and
        cannot be active, and its midpoint's distance stands for it; the rest, of every box, are solved at once
        (`box_minimum`)."""
        s, P = self.surfaces, len(self.surfaces.plane_point)
        flat = C.reshape(4, -1, 3)
        bez, middle = _bezier(flat), _curve(_power(flat), np.full(flat.shape[1], 0.5))
        n, q = len(s.box_center), flat.shape[1]
        ub, db, gb = np.full((n, q), 0.5), np.empty((n, q)), np.empty((n, q, 3))
        near = []
        for b, (center, rot, half) in enumerate(zip(s.box_center, s.box_rot, s.box_half)):
            h2, off = np.concatenate([half, half]), center @ rot
            local = bez @ rot - off  # (4, q, 3)
            low = (np.concatenate([local, -local], axis=-1).min(axis=0) - h2).max(axis=-1)
            mid = middle @ rot - off
            faces = np.concatenate([mid, -mid], axis=-1) - h2
            top = np.argmax(faces, axis=-1)
            db[b], gb[b] = np.take_along_axis(faces, top[:, None], 1)[:, 0], np.concatenate([rot.T, -rot.T])[top]
            near.append(np.flatnonzero(low <= self.tolerance))
        box = np.repeat(np.arange(n), [len(i) for i in near])
        if box.size:
            i = np.concatenate(near)
            ub[box, i], db[box, i], gb[box, i] = box_minimum(flat[:, i], s.box_center[box], s.box_rot[box], s.box_half[box])
        m, K = self.shape[:2]
        u[..., P:] = ub.reshape(n, m, K).transpose(1, 2, 0)
        d[..., P:] = db.reshape(n, m, K).transpose(1, 2, 0)
        g[..., P:, :] = gb.reshape(n, m, K, 3).transpose(1, 2, 0, 3)

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
