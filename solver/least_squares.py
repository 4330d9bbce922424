"""The Gauss-Newton normal equations of `solve`'s objective, banded: J^T J and J^T r in local spline
coordinates, for the Levenberg-Marquardt back end (`solver.gauss_newton`).

The objective is a weighted sum of integrals of squares (paper eq. 1 with f_j = |r_j|^2, `Term.residual`),
so by quadrature E = sum_j (lambda_j / s_j) sum_i q_i |r_j(t_i)|^2 = |rho|^2 with the weighted residuals
rho_ij = sqrt(q_i lambda_j / s_j) r_j(t_i) (q_i the quadrature weights, s_j the renormalization
scales of eq. 7). Gauss-Newton (Nocedal & Wright, Numerical Optimization, 2nd ed., sec. 10.3) needs
J^T J and J^T rho, J = d rho / d x over the free frame components x.

Why not in the frame values. The natural spline through the frames is a global map (each quadrature
point depends on every frame value: `solver.spline`), so J in the frame values is dense and J^T J
with it (n_free^2 entries, a dense factorization O(n_free^3)). The same path space has a local basis:
the cubic B-splines on the frame times with natural ends (de Boor, A Practical Guide to Splines,
ch. IX-X). Y(t) = sum_u c_u N_u(t), and a point in frame segment s reads only the coefficients
s..s+3. The keyframes (the fixed components) and the natural end conditions are linear equations on
c; each free frame component gets the coefficient of its own frame (the "centre" u = f + 1, u = 0 and
m + 1 at the ends) as a free parameter xi, and the other coefficients follow from the equations
(`LocalSpline`: c = c_0 + Z xi, Z local: a run of fixed frames depends only on the free coefficients
on either side of it). In xi, J = (per-point blocks d rho / d(Y, Y', Y'')) x (4 B-spline values per
point) x Z is block sparse and J^T J is banded (ordered by frame, bandwidth about four frames of
components), factored with LAPACK's banded Cholesky (scipy.linalg.cholesky_banded): O(n_free b^2)
work for bandwidth b, linear in the clip's length. A step dxi moves the free frame values by
dx = E dxi (E: the spline's values at the free frames), so every iterate is again a frame set that
meets the keyframes exactly; Gauss-Newton's step is invariant under this change of variables, and
the Levenberg-Marquardt damping uses diag(J^T J) (Marquardt's scaling, which is invariant to scaling
the variables; Nocedal & Wright sec. 10.3, "Implementation of the Levenberg-Marquardt method").
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import BSpline
from scipy.linalg import cho_solve_banded, cholesky_banded
from scipy.linalg.blas import dsbmv
from scipy.sparse.linalg import splu

from solver.active_set import HingeRows, active_set_step, hinge_rows
from solver.frames import FrameSet
from solver.path_context import PathContext
from solver.site_jacobian import cached_site_jacobians, supports

#: quadrature points whose Jacobian rows `_add_batch` forms at a time (about 1-2 MB of rows per block)
BLOCK_POINTS = 512


class NoResidualError(ValueError):
    """An objective term with a nonzero weight gives no residual form (`Term.residual` is None)."""


class LocalSpline:
    """The cubic B-spline basis on a frame set's times with natural ends, at the quadrature points,
    and the free parametrization c = c_0 + Z xi of the frame set's spline (module docstring).

    Args:
        frames: FrameSet (times (m,), fixed (m, nq)). t: (n,) quadrature times [s], sorted.
    Attributes:
        seg: (n,) frame segment of each point (its coefficients are seg..seg+3).
        vals: (3, n, 4) the 4 B-spline values, first and second derivatives at each point [1, 1/s, 1/s^2].
        Z: sparse ((m+2) nq, n_free) d c / d xi (c flattened coefficient-major: u nq + component).
        E: sparse (n_free, n_free) d x / d xi: the free frame values' change per unit xi.
        n_free: number of free components (`FrameSet.n_free`), in the order of `FrameSet.x`.
    """

    def __init__(self, frames: FrameSet, t: np.ndarray):
        x = np.asarray(frames.times, float)
        m, nq = frames.values.shape
        knots = np.r_[[x[0]] * 3, x, [x[-1]] * 3]
        self.m, self.nq, self.t = m, nq, np.asarray(t, float)
        self.seg = np.clip(np.searchsorted(x, self.t, side="right") - 1, 0, m - 2)
        self.vals = _local_values(knots, self.t, self.seg)
        eye = np.eye(m + 2)
        at_frames = BSpline(knots, eye, 3)(x)  # (m, m+2) interpolation rows
        ends = BSpline(knots, eye, 3)(x[[0, -1]], nu=2)  # (2, m+2) natural end conditions
        free = frames.free
        self.n_free = int(free.sum())
        xi_index = np.full(free.shape, -1)
        xi_index[free] = np.arange(self.n_free)
        centre = np.r_[0, np.arange(2, m), m + 1]  # the coefficient each frame's value is tied to
        zr, zc, zv, er, ec, ev = [], [], [], [], [], []
        patterns: dict[bytes, tuple] = {}
        for comp in range(nq):
            f = free[:, comp]
            key = f.tobytes()
            if key not in patterns:
                patterns[key] = _null_space(at_frames, ends, f, centre)
            Zc = patterns[key]  # dense (m+2, r) for the r free frames of this component, exact zeros kept
            Ec = at_frames[f] @ Zc  # (r, r) values at the free frames per unit xi
            fi = xi_index[f, comp]
            u, j = np.nonzero(Zc)
            zr.append(u * nq + comp), zc.append(fi[j]), zv.append(Zc[u, j])
            a, b = np.nonzero(Ec)
            er.append(fi[a]), ec.append(fi[b]), ev.append(Ec[a, b])
        cat = np.concatenate
        self.Z = sp.csr_matrix((cat(zv), (cat(zr), cat(zc))), shape=((m + 2) * nq, self.n_free))
        self.E = sp.csr_matrix((cat(ev), (cat(er), cat(ec))), shape=(self.n_free, self.n_free))


def _local_values(knots: np.ndarray, t: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """(3, n, 4): the values, first and second derivatives of the 4 cubic B-splines seg..seg+3 that
    are nonzero at each time t, from sparse design matrices (O(n), nothing (n, m) dense): the
    derivative of sum c_i N_i,k is sum k (c_i+1 - c_i) / (t_i+k+1 - t_i+1) N_i,k-1 on the knots
    without their ends (de Boor, A Practical Guide to Splines, ch. X)."""
    n = len(t)
    rows, out = np.repeat(np.arange(n), 4), np.zeros((3, n, 4))
    cols = (seg[:, None] + np.arange(4)).ravel()
    D = sp.identity(len(knots) - 4, format="csr")  # coefficients of the spline itself
    kn = knots
    for order in range(3):
        k = 3 - order
        B = BSpline.design_matrix(t, kn, k)  # (n, len(kn) - k - 1), degree k
        out[order] = np.asarray((B @ D)[rows, cols]).reshape(n, 4)
        # d/dx: coefficients of degree k - 1 on kn[1:-1]
        span = kn[k + 1:-1] - kn[1:-k - 1]
        nc = len(kn) - k - 1
        step = sp.diags([-k / span, k / span], [0, 1], shape=(nc - 1, nc), format="csr")
        D, kn = step @ D, kn[1:-1]
    return out


def _null_space(at_frames: np.ndarray, ends: np.ndarray, free: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Z (m+2, r) with c = Z xi spanning the coefficients whose spline is zero at the fixed frames
    and has natural ends, xi the centre coefficients of the r free frames (sparse LU: structural zeros
    stay exact, so Z is local)."""
    m2 = at_frames.shape[1]
    F = centre[free]
    D = np.setdiff1d(np.arange(m2), F)
    C = np.vstack([at_frames[~free], ends])  # (m + 2 - r, m + 2)
    Z = np.zeros((m2, len(F)))
    Z[F, np.arange(len(F))] = 1.0
    if len(D):
        lu = splu(sp.csc_matrix(C[:, D]))
        Z[D] = -lu.solve(np.ascontiguousarray(C[:, F]))
    return Z


@dataclass
class NormalEquations:
    """J^T J (banded, lower form for `cholesky_banded`) and J^T rho in xi, and |rho|^2.

    Attributes:
        ab: (b + 1, n_free) lower band of J^T J (ab[i - j, j] = (J^T J)[i, j], i >= j).
        g: (n_free,) J^T rho. E: |rho|^2 (the objective's value).
    """

    ab: np.ndarray
    g: np.ndarray
    E: float
    hinge: HingeRows | None = None
    pairs: tuple = ()  # secant pairs (s, y) oldest first (`secant_solve`); () for plain Gauss-Newton
    _abf: np.ndarray | None = field(default=None, repr=False, compare=False)  # ab in Fortran order

    def matvec(self, v: np.ndarray) -> np.ndarray:
        """(J^T J) v (BLAS dsbmv on a Fortran-ordered copy of ab, made once)."""
        if self._abf is None:
            self._abf = np.asfortranarray(self.ab)
        return dsbmv(len(self._abf) - 1, 1.0, self._abf, v, lower=1)

    def solve(self, mu: float) -> np.ndarray:
        """The damped Gauss-Newton step h: (J^T J + mu diag(J^T J)) h = -J^T rho (Marquardt's scaling;
        zero diagonal entries, directions no residual sees, get the mean diagonal as their scale).

        Raises:
            numpy.linalg.LinAlgError: the damped matrix is not positive definite (mu too small).
        """
        return self.damped(self.ab, self.g, mu)

    def scale(self) -> np.ndarray:
        """(n_free,) D: diag(J^T J), zero entries replaced by the mean of the positive ones."""
        d = self.ab[0]
        return np.where(d > 0, d, d[d > 0].mean() if (d > 0).any() else 1.0)

    def scaled_norm(self, h: np.ndarray) -> float:
        """|D^1/2 h|, D = `scale`: the step's length in Marquardt's scaling (the trust-region norm)."""
        return float(np.sqrt(h @ (self.scale() * h)))

    def damped(self, ab: np.ndarray, g: np.ndarray, mu: float) -> np.ndarray:
        """-(A + mu D)^-1 g for A in lower band form ab (J^T J or a low-rank change of it), D = `scale`;
        with secant `pairs`, -H g with H the limited-memory BFGS inverse seeded with (A + mu D)^-1
        (`secant_solve`)."""
        ab = ab.copy()
        ab[0] += mu * self.scale()
        factor = cholesky_banded(ab, lower=True)
        return -secant_solve(lambda v: cho_solve_banded((factor, True), v), g, self.pairs)

    def damped_matvec(self, v: np.ndarray, mu: float) -> np.ndarray:
        """(J^T J + mu D) v."""
        return self.matvec(v) + mu * self.scale() * v

    def step(self, mu: float) -> tuple[np.ndarray, float]:
        """(h, L(0) - L(h)): the damped step of the model that keeps the hinge residuals' max(0, .)
        (`solver.active_set`), and its predicted decrease; without hinge rows near switching, `solve`
        and `model_decrease`.

        Raises:
            numpy.linalg.LinAlgError: a damped matrix is not positive definite (mu too small).
        """
        if self.hinge is None:
            h = self.solve(mu)
            return h, self.model_decrease(h)
        h = active_set_step(self, self.hinge, mu)
        return h, self.model_decrease(h) + self.hinge.correction(np.zeros_like(h)) - self.hinge.correction(h)

    def lagged(self, h: np.ndarray, g: np.ndarray, E: float) -> NormalEquations:
        """The normal equations after the step h with the same J^T J and the exact gradient there: a
        step that keeps the last Jacobian (`solver.gauss_newton`).

        Args:
            h: (n_free,) the step taken. g: (n_free,) J^T rho at the new point (half of dE / d xi,
                from the objective's own gradient). E: the objective there.
        Returns:
            NormalEquations whose quadratic model has the new gradient; the hinge rows' signed values
            moved by their linearization, g corrected so that the rows the band keeps on
            (`HingeRows.on`) enter the gradient with those values.
        """
        if self.hinge is None:
            return NormalEquations(self.ab, g, E, None, self.pairs, self._abf)
        hinge = self.hinge.moved(h)
        s = hinge.s
        g = g + hinge.P.T @ (s * (hinge.on.astype(float) - (s > 0)))
        return NormalEquations(self.ab, g, E, hinge, self.pairs, self._abf)

    def model_decrease(self, h: np.ndarray) -> float:
        """L(0) - L(h) of the Gauss-Newton model L(h) = |rho + J h|^2 = E + 2 h.g + h^T J^T J h."""
        return -(2.0 * h @ self.g + h @ self.matvec(h))


def secant_solve(h0, g: np.ndarray, pairs) -> np.ndarray:
    """H g by the two-loop recursion of limited-memory BFGS with the initial inverse h0 (a callable:
    v -> H0 v) and the secant pairs [(s, y), ...] oldest first, y . s > 0 (Nocedal & Wright, Numerical
    Optimization, 2nd ed., algorithm 7.4). H satisfies H y = s for the newest pair and agrees with H0
    on the directions no pair has seen: seeded with the Gauss-Newton (J^T J + mu D)^-1, it adds the
    curvature the residuals' second derivatives give (Madsen, Nielsen & Tingleff 2004, sec. 3.5, a
    hybrid of Levenberg-Marquardt and quasi-Newton for problems whose residuals stay large)."""
    q, alphas = np.array(g, float), []
    for s, y in reversed(pairs):
        a = (s @ q) / (y @ s)
        q -= a * y
        alphas.append(a)
    r = h0(q)
    for (s, y), a in zip(pairs, reversed(alphas)):
        r += s * (a - (y @ r) / (y @ s))
    return r


def term_residuals(objective, basis, Y, Y1, Y2):
    """[(term, c_j = lambda_j / s_j, Residual), ...] of the terms with a nonzero weight, on one shared
    `PathContext` (each engine's forward pass once).

    Raises:
        NoResidualError: a weighted term gives no residual form (names it).
    """
    ctx = PathContext(basis.t, Y, Y1, Y2)
    out = []
    for term, w, s in zip(objective.terms, objective.weights, objective.scales):
        if w == 0.0:
            continue
        res = term.residual(ctx)
        if res is None:
            raise NoResidualError(f"objective term {term.name!r} is not a sum of squares (no residual form)")
        out.append((term, w / s, res))
    return out


def normal_equations(objective, frames: FrameSet, local: LocalSpline, timings: dict | None = None) -> NormalEquations:
    """J^T J, J^T rho and |rho|^2 of `objective` at `frames` in the free coefficients xi of `local`.

    Args:
        objective: Objective whose weighted terms all give `Term.residual`. frames: FrameSet.
        local: `LocalSpline(frames, objective.basis(frames.times).t)`.
        timings: if a dict, CPU seconds (time.process_time) are added to its "residuals" (the terms'
            residuals and their engines' forward passes), "blocks" (the Jacobian blocks: the terms'
            groups, the site Jacobians), "gram" (J^T J per segment) and "band" (into the free
            coefficients, banded).
    Returns:
        NormalEquations.
    Raises:
        NoResidualError: a weighted term without a residual form.
    """
    basis = objective.basis(frames.times)
    Y, Y1, Y2 = basis.evaluate(frames.values, objective.needs)
    q = (np.full(len(basis.t), objective.h) if basis.weights is None else basis.weights)
    nq, m = local.nq, local.m
    # J^T J in the B-spline coefficients, banded: band[u, d] the block (u, u + d), d = 0..3 (a point of
    # segment s reads coefficients s..s+3); gc: J^T rho in the coefficients
    band, gc = np.zeros((m + 2, 4, nq, nq)), np.zeros((m + 2, nq))
    E = 0.0
    clock = _Clock(timings)
    site_rows = []  # site terms, summed site by site (`_add_sites`)
    hinge_parts = []  # their hinge columns (`solver.active_set`)
    term_hinges = []  # the hinge columns of other terms (`solver.terms.base.OneSided`)
    residuals = term_residuals(objective, basis, Y, Y1, Y2)
    clock("residuals")
    for _, c, res in residuals:
        w = np.sqrt(c * q)  # (n,) row weights
        rho = res.r * w[:, None]
        E += float((rho * rho).sum())
        if res.compact is None and res.blocks is None and res.sites is not None and supports(res.sites.engine):
            site_rows.append((res.sites, w, rho))
            if res.sites.signed is not None and res.sites.dv is None:
                hinge_parts.append((res.sites, w))
            cached_site_jacobians(res.sites.ctx, res.sites.engine, res.sites.result)
            clock("blocks")
            continue
        if res.one_sided is not None:
            term_hinges.append((res.one_sided, w))
        groups = res.groups()
        clock("blocks")
        for batch in _batches(groups):
            _add_batch(band, gc, local, w, rho, batch)
        clock("gram")
    _add_sites(band, gc, local, site_rows)
    clock("gram")
    Zs = local.Z
    A = _band_to_sparse(band, m, nq)
    H = (Zs.T @ (A @ Zs)).tocoo()
    g = Zs.T @ gc.ravel()
    lower = H.row >= H.col
    i, j, v = H.row[lower], H.col[lower], H.data[lower]
    b = int((i - j).max(initial=0))
    ab = np.zeros((b + 1, local.n_free))
    np.add.at(ab, (i - j, j), v)
    hinge = hinge_rows(local, hinge_parts, nq, term_hinges) if hinge_parts or term_hinges else None
    clock("band")
    return NormalEquations(ab, np.asarray(g), E, hinge)


class _Clock:
    """clock(name): adds the CPU time since the last call to timings[name] (a no-op without a dict)."""

    def __init__(self, timings):
        self.timings, self.t = timings, time.process_time()

    def __call__(self, name):
        if self.timings is not None:
            t = time.process_time()
            self.timings[name] = self.timings.get(name, 0.0) + t - self.t
            self.t = t


def _batches(groups):
    """`Residual.groups` in batches of the same shape (columns, components, orders) and disjoint
    components, each added in one pass (`_add_batch`): a term's per-joint groups (the covariant
    acceleration's 4 x 4 blocks of every quaternion) go together."""
    batches: dict[tuple, list] = {}
    out = []
    for g in groups:
        cols, comps, Js = g
        key = (len(cols), len(comps), tuple(J is not None for J in Js))
        b = batches.setdefault(key, [])
        if b and np.isin(comps, np.concatenate([x[1] for x in b])).any():
            out.append(b)
            b = batches[key] = []
        b.append(g)
    return out + [b for b in batches.values() if b]


def _add_batch(band, gc, local, w, rho, batch):
    """Add residual groups' J^T J and J^T rho (rows weighted by w (n,)) into the coefficient band `band`
    ((m+2, 4, nq, nq)) and `gc` ((m+2, nq)) (`_accumulate`). `batch`: groups (columns, comps, (J0, J1, J2)) of
    one shape with disjoint comps (`_batches`), J (n, m_g, c_g) or None. Only points where a group's
    Jacobian is nonzero are used, BLOCK_POINTS at a time (the rows' temporaries stay in cache: on a long
    clip they would be tens of MB)."""
    orders = [k for k in range(3) if batch[0][2][k] is not None]
    nonzero = np.zeros(len(w), bool)
    for k in orders:
        for g in batch:
            nonzero |= np.any(g[2][k] != 0, axis=(1, 2))
    act_all = np.flatnonzero(nonzero)
    comps = np.stack([g[1] for g in batch])
    nb, (mg, cs) = len(batch), batch[0][2][orders[0]].shape[1:]
    for lo in range(0, len(act_all), BLOCK_POINTS):
        act = act_all[lo:lo + BLOCK_POINTS]
        X = np.zeros((nb, len(act), mg, 4, cs))
        for k in orders:
            Jk = np.stack([g[2][k][act] for g in batch])  # (b, p, m_g, c_g)
            X += Jk[:, :, :, None, :] * (w[act, None] * local.vals[k][act])[None, :, None, :, None]
        X = X.reshape(nb, len(act), mg, 4 * cs)
        R = np.stack([rho[act][:, g[0]] for g in batch])  # (b, p, m_g)
        _accumulate(band, gc, local, act, X, np.einsum("bpma,bpm->bpa", X, R), comps)


def _add_sites(band, gc, local, site_rows):
    """Add the site terms' J^T J and J^T rho site by site: every residual row reading site k is
    c_r . (p, v) (`SiteRows`, c_r (6,) weighted), so their rows' J^T J over the site's components is
    M^T C M with C = sum_r c_r c_r^T (6 x 6 per point) and M the site's Jacobian in the segment's
    coefficients ((d p, d v) / d c: `solver.site_jacobian`), and J^T rho = M^T sum_r c_r rho_r. C is
    factored per point (C = L L^T, symmetric eigen-decomposition) into at most 6 rows L^T M: one
    product per site for all its terms instead of one per residual column."""
    by_engine: dict[int, list] = {}
    for rows, w, rho in site_rows:
        by_engine.setdefault(id(rows.engine), []).append((rows, w, rho))
    for parts in by_engine.values():
        first = parts[0][0]
        jac = cached_site_jacobians(first.ctx, first.engine, first.result)
        vel = any(rows.dv is not None for rows, _, _ in parts)
        for k, (comps, Jp, Jv) in enumerate(jac):
            coef, res = [], []
            for rows, w, rho in parts:
                cols = np.flatnonzero(rows.site == k)
                if not cols.size:
                    continue
                cp = np.zeros((len(w), len(cols), 6 if vel else 3))
                if rows.dp is not None:
                    cp[:, :, :3] = rows.dp[:, cols]
                if rows.dv is not None:
                    cp[:, :, 3:] = rows.dv[:, cols]
                coef.append(cp * w[:, None, None])
                res.append(rho[:, cols])
            if not coef:
                continue
            cr, rr = np.concatenate(coef, axis=1), np.concatenate(res, axis=1)
            act = np.flatnonzero(np.any(cr != 0, axis=(1, 2)))
            if not act.size:
                continue
            cr, rr = cr[act], rr[act]
            C = np.einsum("pri,prj->pij", cr, cr)
            b = np.einsum("pri,pr->pi", cr, rr)
            v0, v1 = local.vals[0][act], local.vals[1][act]  # (p, 4)
            Jpa = Jp[act]
            M = [Jpa[:, :, None, :] * v0[:, None, :, None]]  # (p, 3, 4, c): d p / d c
            if vel:
                M.append(Jv[act][:, :, None, :] * v0[:, None, :, None] + Jpa[:, :, None, :] * v1[:, None, :, None])
            M = np.concatenate(M, axis=1).reshape(len(act), C.shape[1], -1)  # (p, d, 4c)
            e, U = np.linalg.eigh(C)
            # C = LT^T LT with one row per nonzero eigenvalue (a point's rank is that of its terms' rows:
            # 1 for a surface's depth, 3-4 with a planted foot's height and sliding), points' rows stacked
            keep = (e > 1e-12 * e.max(initial=0.0)) | (e == e.max(axis=1, keepdims=True))
            pt, ev = np.nonzero(keep)
            X = np.einsum("ri,ria->ra", U[pt, :, ev] * np.sqrt(e[pt, ev])[:, None], M[pt])
            gx = np.zeros(X.shape)
            first = np.r_[True, pt[1:] != pt[:-1]] if len(pt) else np.zeros(0, bool)
            gx[first] = np.einsum("pi,pia->pa", b, M)[pt[first]]
            _accumulate(band, gc, local, act[pt], X[None, :, None, :], gx[None], np.asarray(comps)[None])


def _accumulate(band, gc, local, act, X, gx, comps):
    """band[u, d] += the blocks (u, u + d) of the sum over the points of X^T X, gc[u] += the sums of gx,
    for batches of disjoint component sets: act (p,) the points, X (b, p, r, 4 c) rows in the 4
    coefficients of each point's segment s (s..s+3) x c components comps (b, c), gx (b, p, 4 c).

    A segment's points are stacked into one product per chunk (chunks of at most the mean run's length:
    segments differ in length, and padding every run to the longest would multiply the work by their
    ratio, 2.5 on 127_33), the chunks summed per segment, and each segment's 4 x 4 coefficient blocks
    added into the band directly (the upper ones: J^T J is symmetric), one coefficient slot a at a time:
    for one a the targets u = s + a are distinct, so one indexed add per slot."""
    nb, p, mg, width = X.shape
    nq = local.nq
    seg = local.seg[act]
    starts = np.flatnonzero(np.r_[True, seg[1:] != seg[:-1]])  # the segments' runs of points
    counts = np.diff(np.r_[starts, p])
    s = seg[starts]
    size = max(1, int(np.ceil(counts.mean())))
    pos = np.arange(p) - np.repeat(starts, counts)
    key = np.repeat(np.cumsum(np.r_[0, np.ceil(counts[:-1] / size)]).astype(int), counts) + pos // size
    cstart = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])  # chunk starts (points)
    first = np.searchsorted(cstart, starts)  # each segment's first chunk
    Xp = np.zeros((nb, key[-1] + 1, size, mg, width))
    Xp[:, key, pos % size] = X
    Xp = Xp.reshape(nb, key[-1] + 1, -1, width)
    G = np.add.reduceat(np.matmul(Xp.transpose(0, 1, 3, 2), Xp), first, axis=1) if len(first) < key[-1] + 1 \
        else np.matmul(Xp.transpose(0, 1, 3, 2), Xp)
    cs = comps.shape[1]
    G = G.reshape(nb, len(s), 4, cs, 4, cs)
    gs = np.add.reduceat(gx, starts, axis=1).reshape(nb, len(s), 4, cs)
    flat, ci, cj = band.reshape(-1), comps[:, None, None, :, None], comps[:, None, None, None, :]
    for a in range(4):
        u = (s + a)[None, :, None, None, None]
        d = np.arange(4 - a)[None, None, :, None, None]
        idx = ((u * 4 + d) * nq + ci) * nq + cj  # (b, segments, 4 - a, c, c): distinct entries
        flat[idx.ravel()] += G[:, :, a, :, a:, :].transpose(0, 1, 3, 2, 4).ravel()
        gc[(s + a)[None, :, None], comps[:, None, :]] += gs[:, :, a]


def _band_to_sparse(band, m, nq):
    """The symmetric sparse ((m+2) nq)^2 matrix of the blocks band[u, d] (block (u, u+d) and its transpose)."""
    rows, cols, vals = [], [], []
    ii, jj = np.meshgrid(np.arange(nq), np.arange(nq), indexing="ij")
    for d in range(4):
        u = np.arange(m + 2 - d)
        B = band[u, d]  # (len(u), nq, nq)
        r = (u[:, None, None] * nq + ii).ravel()
        c = ((u + d)[:, None, None] * nq + jj).ravel()
        v = B.ravel()
        keep = v != 0
        rows.append(r[keep]), cols.append(c[keep]), vals.append(v[keep])
        if d:
            rows.append(c[keep]), cols.append(r[keep]), vals.append(v[keep])
    N = (m + 2) * nq
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(N, N))
