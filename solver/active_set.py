"""The Gauss-Newton model of the one-sided (hinge) residuals: the sites a step may push into a surface.

The penetration and clearance residuals are hinges, r_i = max(0, s_i) with s_i a smooth function of a
site's position (`SiteRows.signed`: the depth into a surface grown by its margin, or how far a swing
foot is below its band). Gauss-Newton linearizes r where it is: a clear site (s_i < 0) has r_i = 0 and
a zero Jacobian row, so the model does not see that a step moves it into the floor, and a step the
model rates as a small decrease can raise E a hundredfold (docs/solvers.md).

The model used instead keeps the hinge and linearizes s:

    L(h) = |rho_o + J_o h|^2 + sum_i max(0, s_i + a_i h)^2 (+ the damping mu h^T D h),

with a_i = d s_i / d xi (`HingeRows`: the rows of the sites within `BAND` of switching on). L is a
convex piecewise quadratic; its minimizer is found by the primal-dual active-set strategy, which is a
semismooth Newton method on L's gradient (Hintermueller, Ito & Kunisch, "The primal-dual active set
strategy as a semismooth Newton method", SIAM J. Optim. 13(3), 2002; Nocedal & Wright, Numerical
Optimization, 2nd ed., sec. 16.5 for the active-set view): solve the quadratic with the rows predicted
active (s_i + a_i h > 0), predict again at the new h, and repeat until the set no longer changes
(at most `MAX_SWITCHES` times: by default once, a search along the plain Gauss-Newton direction on
the piecewise model; the gain ratio of the Levenberg-Marquardt loop guards the step whatever the last
set). The rows switching against the current point's set are low-rank updates of
the banded J^T J. The predicted decrease L(0) - L(h) is the piecewise model's, so the gain ratio
compares E with the model that sees the crossings.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from solver.site_jacobian import cached_site_jacobians

#: Hinge rows whose signed value is within this of switching on (s_i > -BAND, in the residual's units:
#: metres of depth or of clearance) enter the model; a step that moves a site farther than this in one
#: iteration is left to the gain ratio.
BAND = 0.05
#: Active-set solves per damped step (each one banded factorization). 1: the plain Gauss-Newton step
#: with the set the last step of this Jacobian ended with, cut at the piecewise model's minimum along it
#: (the set it predicts is where the next retry starts). Letting the set settle (up to 2, 3, 6 solves)
#: cost 1.3-2.6x the CPU time of a whole contact solve on 127_33 and 16_23, for an E 0.1 % lower.
MAX_SWITCHES = 1
#: `BAND` for the hinge columns of the anatomy terms (`solver.terms.base.OneSided`), in radians of joint
#: angle: 0.1 rad moves a point 5 cm at half a metre from the joint, as `BAND` does a site.
ANGLE_BAND = 0.1


@dataclass
class HingeRows:
    """The weighted hinge rows near switching: rho_i = max(0, s_i + a_i h) in the model.

    Attributes:
        P: sparse (r, n_free) the rows a_i (weighted by the residual's sqrt(lambda q / s)) in the free
            coefficients xi. s: (r,) the weighted signed values s_i (> 0: the row is on now).
        on: (r,) the rows the quadratic model (`NormalEquations.ab`, `g`) keeps on (default s > 0).
        last: (r,) the active set the last `active_set_step` ended with (its next call starts there).
    """

    P: sp.csr_matrix
    s: np.ndarray
    on: np.ndarray | None = None
    last: np.ndarray | None = None

    def __post_init__(self):
        if self.on is None:
            self.on = self.s > 0

    def predict(self, h: np.ndarray) -> np.ndarray:
        """(r,) s + P h: the linearized signed values after the step h (n_free,)."""
        return self.s + self.P @ h

    def correction(self, h: np.ndarray) -> float:
        """L_hinge(h) - L_quad(h): what the piecewise model adds to the quadratic model at h that keeps
        the rows `on` on and the others off whatever their prediction (`NormalEquations.ab` and `g`)."""
        p, on = self.predict(h), self.on
        return float(np.sum(p[~on & (p > 0)] ** 2) - np.sum(p[on & (p <= 0)] ** 2))

    def moved(self, h: np.ndarray) -> HingeRows:
        """The rows after the step h (the signed values moved by their linearization, the rows and the
        set the quadratic model keeps on unchanged): for a step that keeps the last Jacobian."""
        return HingeRows(self.P, self.predict(h), self.on)


def hinge_rows(local, parts, nq: int, term_parts=()) -> HingeRows | None:
    """The rows of the hinge columns within `BAND` (sites) or `ANGLE_BAND` (the anatomy terms' angles)
    of switching on, in the free coefficients.

    Args:
        local: `solver.least_squares.LocalSpline`. parts: [(SiteRows with `signed`, w (n,) row
            weights)]: positions-only site columns. nq: the state's width.
        term_parts: [(`solver.terms.base.OneSided`, w (n,) row weights)]: hinge columns of a term read
            from a few qpos components (positions only).
    Returns:
        HingeRows, or None if no row is near.
    """
    rid, cid, val, svals = [], [], [], []

    def add(ii, comps, coef, s):  # rows at points ii: coef (r, c) d s / d Y[comps] (weighted), s (r,)
        v = coef[:, None, :] * local.vals[0][ii][:, :, None]  # (r, 4, c): the 4 B-splines
        cols = (local.seg[ii][:, None, None] + np.arange(4)[None, :, None]) * nq + comps[:, None, :]
        start = sum(len(x) for x in svals)
        rid.append(np.broadcast_to((start + np.arange(len(ii)))[:, None, None], v.shape).ravel())
        cid.append(np.broadcast_to(cols, v.shape).ravel()), val.append(v.ravel())
        svals.append(s)

    for rows, w in parts:
        jac = cached_site_jacobians(rows.ctx, rows.engine, rows.result)
        near = (rows.signed > -BAND) & (w[:, None] > 0)
        i, j = np.nonzero(near)
        for k in np.unique(rows.site[j]):
            mk = rows.site[j] == k
            ii, jj = i[mk], j[mk]
            comps, Jp, _ = jac[k]
            coef = w[ii, None] * np.einsum("ri,ric->rc", rows.dsigned[ii, jj], Jp[ii])  # (r, c)
            add(ii, np.asarray(comps)[None, :], coef, w[ii] * rows.signed[ii, jj])
    for one, w in term_parts:
        ii, jj = np.nonzero((one.signed > -ANGLE_BAND) & (w[:, None] > 0))
        if len(ii):
            add(ii, np.asarray(one.comps)[jj], w[ii, None] * one.grad(ii, jj), w[ii] * one.signed[ii, jj])
    if not svals:
        return None
    cat = np.concatenate
    count = sum(len(x) for x in svals)
    Rc = sp.csr_matrix((cat(val), (cat(rid), cat(cid))), shape=(count, local.Z.shape[0]))
    return HingeRows((Rc @ local.Z).tocsr(), cat(svals))


def active_set_step(ne, hinge: HingeRows, mu: float) -> np.ndarray:
    """The minimizer h of the damped piecewise model M(h) = L(h) + mu h^T D h (module docstring) by the
    primal-dual active-set iteration from h = 0, each Newton step followed by an exact line search on M
    (a globalized semismooth Newton method: M decreases at every step, so h is never worse than 0
    even where the active set has not settled within `MAX_SWITCHES` steps).

    Args:
        ne: `NormalEquations` (its band ab and g hold the rows `hinge.on`; `ne.damped(ab, g, mu)` solves,
            `ne.damped_matvec(v, mu)` multiplies by J^T J + mu D). hinge: HingeRows. mu: damping.
    Returns:
        h (n_free,). Raises numpy.linalg.LinAlgError where `ne.damped` does.
    """
    on = hinge.on
    h = np.zeros(len(ne.g))
    active = on if hinge.last is None else hinge.last  # a retry at another damping starts where the last ended
    for _ in range(MAX_SWITCHES):
        if np.array_equal(active, on):
            ab, g = ne.ab, ne.g
        else:
            add, drop = active & ~on, on & ~active
            ab, g = ne.ab, ne.g.copy()
            for sel, sign in ((add, 1.0), (drop, -1.0)):
                if sel.any():
                    Ps = hinge.P[np.flatnonzero(sel)]
                    ab = _add_band(ab, (Ps.T @ Ps).tocoo(), sign)
                    g += sign * (Ps.T @ hinge.s[sel])
        target = ne.damped(ab, g, mu)
        t = _line_min(ne, hinge, mu, h, target - h, on)
        h = h + t * (target - h)
        new = hinge.predict(h) > 0
        if (t == 1.0 and np.array_equal(new, active)) or t == 0.0:
            break  # the quadratic of this set has its minimum where the set is the same: M's minimum
        active = new
    hinge.last = active
    return h


def _line_min(ne, hinge: HingeRows, mu: float, h: np.ndarray, d: np.ndarray, on: np.ndarray) -> float:
    """argmin over t in [0, 1] of M(h + t d), M convex (its derivative in t is piecewise linear and
    nondecreasing: bisection on its sign, to 1e-6 of the step)."""
    Hd = ne.damped_matvec(d, mu)
    A, B = d @ Hd, 2.0 * (d @ ne.g + h @ Hd)
    p0, q = hinge.predict(h), hinge.P @ d
    keep = q != 0
    p0, q, on = p0[keep], q[keep], on[keep]

    def slope(t):
        p = p0 + t * q
        return 2.0 * A * t + B + 2.0 * np.sum(q * np.where(on, -np.minimum(0.0, p), np.maximum(0.0, p)))

    if slope(1.0) <= 0.0:
        return 1.0
    if slope(0.0) >= 0.0:
        return 0.0
    lo, hi = 0.0, 1.0
    while hi - lo > 1e-6:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if slope(mid) < 0.0 else (lo, mid)
    return lo


def _add_band(ab: np.ndarray, M: sp.coo_matrix, sign: float) -> np.ndarray:
    """ab + sign M for symmetric M (coo), ab in lower band form (widened if M reaches farther)."""
    lower = M.row >= M.col
    i, j, v = M.row[lower], M.col[lower], M.data[lower]
    b = int((i - j).max(initial=0))
    out = np.zeros((max(len(ab), b + 1), ab.shape[1]))
    out[:len(ab)] = ab
    np.add.at(out, (i - j, j), sign * v)
    return out
