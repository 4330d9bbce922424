"""A Gauss-Newton preconditioner for a subproblem on a grid of frames: the curvature of D and of the stiff
constraints, banded in B-spline coefficients.

The subproblem's variables are the frames' free values x; the path at the quadrature points is the natural
cubic spline through the frames. That spline is a cubic B-spline on the clamped knot vector of the frame
times with m + 2 coefficients C, fixed by its m values at the frames and its two natural end conditions
(de Boor, A Practical Guide to Splines, 2001, ch. IX), and each point depends on only the four coefficients
of its knot interval. The Gauss-Newton Hessian of Phi (`solver.lagrangian`) in C,

    H_C = sum_i sum_a,b (b_i^a b_i^b^T) (x) sum_r,s M_i[r, a]^T G_i^rs M_i[s, b]     (a, b, r, s in 0, 1, 2)

is therefore block-banded with four blocks of nv a side: b_i^a (4,) the a-th derivative of the point's four
basis functions; G_i^rs (nv, nv) the curvature of Phi in the point's pose tangent, qvel and qacc (r, s = 0, 1,
2; D/D0: 2 w_i omega^4 P_i / D0 on the pose and 2 w_i M_i / D0 on qacc, `solver.change`; each constraint's
`Constraint.curvature` under the penalty's weights, below, in factored form: `solver.curvature`); and
M_i[r, a] the derivative of the path's r-th order tangent by the a-th time derivative of the frame
variables' change at the point (`_motion_maps`: identity on linear components; for a quaternion, through
the frames' spline p there, whose rotation by d moves the path by p [0, d/2], and `qvel`, `qacc` depend on
its value and derivatives alike).

The penalty of a pair, psi(c) = (rho/2)(w_p/T) max(0, lam/rho + c/tol)^2, has psi' = (w_p/T) s / tol and
psi'' = (w_p/T) rho / tol^2 where s = max(0, lam + rho c/tol) > 0; its Gauss-Newton curvature is
psi'' grad c grad c^T + psi' (c's own curvature, its Gauss-Newton part) (Nocedal & Wright, Numerical
Optimization, 2nd ed., sec. 17.4 and 10.3).

The frames fix C through H's values at the frame times and the end conditions: the frame values are
A C, A (m, m + 2) the basis at the frame times. The Hessian in the frame values is then the restriction of
H_C to the subspace where the end conditions hold (and a pinned frame value is 0), written as H_C plus
`STIFF` times their rows' squares: with H_C + STIFF E^T E = L L^T (LAPACK's banded Cholesky, O(m nv^3)),
x = S z with S = Sel A L^-T (Sel: the free components) gives S S^T -> the inverse of the restricted
Hessian as STIFF grows, so in z Phi's Gauss-Newton Hessian is about the identity, its stiff penalty
terms included. z has (m + 2) nv components, a few more than x; the extra ones move no frame value, and
L-BFGS, whose steps are combinations of gradients S^T g, never moves along them.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy.linalg.lapack import dtbtrs
from scipy.sparse import csr_matrix

from solver.curvature import Curvature, Outer
from solver.quaternion import conj, left_matrix, mul
from solver.spline_coefficients import SplineCoefficients

__all__ = ["GaussNewtonPreconditioner", "GridModel", "cached_preconditioner"]

#: [1] the end conditions' and pins' weight relative to the largest diagonal entry of H_C among the coefficients
#: each ties: 1e6 leaves them met to 1e-6 of the curvature's scale there while LAPACK's Cholesky stays
#: accurate (the condition number it adds is 1e6, against double precision's 1e16)
STIFF = 1e6


class GridModel:
    """What every Gauss-Newton preconditioner on one frame set shares: its `SplineCoefficients` and D/D0's
    block band (`_change_terms`), built once at the first path it is asked for, through the pose's and qacc's
    maps by the same order only ((0, 0), (2, 2)). That leaves out qacc's dependence on a quaternion's value
    and rate ((2, 0), (2, 1)), which is not small where a joint turns fast: on 35_17's clean, a step this
    model priced as a decrease raised D/D0 from 0.0098 to 0.80, and with those maps (built at each path) the
    model held along the same step. Preconditioned L-BFGS did not gain from them on the clean corpus (more
    CPU in all): L-BFGS needs the band only to make Phi's Hessian about the identity; a Gauss-Newton step
    taken as it is would need them.

    Args:
        basis: the frame set's SplineBasis at the points. al: AugmentedLagrangian (its points, D).
        quat_slots: (s, 4) the layout's quaternion slots.
    """

    def __init__(self, basis, al, quat_slots):
        self.basis, self.quat = basis, quat_slots
        self.coefs = SplineCoefficients(basis.knots, al.t)
        self.change = None

    def preconditioner(self, al, frames) -> GaussNewtonPreconditioner | None:
        """The `GaussNewtonPreconditioner` of al's Phi at `frames` (on this frame set) under its multipliers and
        rho; None where no pair acts or is within a tolerance of acting (Phi is then D/D0 there, whose
        curvature D's own preconditioner, `solver.lagrangian.Preconditioner`, already carries) or where the
        factorization fails (then D's preconditioner serves the subproblem)."""
        from solver.lagrangian import _variable_dofs
        from solver.manifold import FrameVariables

        var = FrameVariables(frames, self.quat)
        P = var.values(np.zeros(var.size))
        st = al.state(self.basis, P)
        terms = []
        for c, w, lam in zip(al.constraints, al.w, al.lam):
            ch = c.values(st) / c.tolerance
            s = np.maximum(0.0, lam + al.rho * ch)
            near = lam + al.rho * (ch + 1.0) > 0  # active, or within a tolerance of it
            terms += c.curvature(st, w * s / c.tolerance, w * al.rho / np.asarray(c.tolerance, float) ** 2 * near)
        if not terms:
            return None
        try:
            return GaussNewtonPreconditioner(var, self, al, st, terms, _variable_dofs(var, al.tmap))
        except np.linalg.LinAlgError:  # not positive definite beyond the ridge's reach (round-off): D's serves
            return None


def cached_preconditioner(cache: dict, basis, al, frames, quat_slots) -> GaussNewtonPreconditioner | None:
    """`GridModel.preconditioner` at `frames`, the frame set's GridModel kept in `cache` while its `basis` is
    the same object (a solve's subproblems on one frame set share it)."""
    if cache.get("basis") is not basis:
        cache.update(basis=basis, model=GridModel(basis, al, quat_slots))
    return cache["model"].preconditioner(al, frames)


class GaussNewtonPreconditioner:
    """x = S z (module docstring) at the current path of a subproblem, with the `Preconditioner`
    interface of `solver.lagrangian` (`size`, `apply`, `apply_transpose`).

    Args:
        variables: the subproblem's FrameVariables. model: the frame set's GridModel. al:
            AugmentedLagrangian (its D, constraints, multipliers, rho). st: the PathState at the frames.
            terms: the constraints' `Constraint.curvature` there under the penalty's weights.
            var_dofs: (frame (k,), dof (k,)) of each variable (`solver.lagrangian._variable_dofs`).
    Raises:
        numpy.linalg.LinAlgError: the band not positive definite beyond `RIDGE`'s reach (round-off;
            `GridModel.preconditioner` then leaves the subproblem with D's preconditioner).
    """

    def __init__(self, variables, model: GridModel, al, st, terms: list, var_dofs):
        self.coefs = coefs = model.coefs
        tm, basis = al.tmap, model.basis
        nv = self.nv = tm.nv
        P = variables.values(np.zeros(variables.size))
        M = _motion_maps(tm, st, basis.evaluate(P, (0, 1, 2)))
        if model.change is None:
            model.change = _assemble(coefs, _change_terms(al), {k: M[k] for k in ((0, 0), (2, 2))}, nv)
        Hb = model.change + _assemble(coefs, [t for t in terms if isinstance(t, Curvature)], M, nv)
        frames, dofs = var_dofs
        free = np.zeros((coefs.at_frames.shape[0], nv), bool)
        free[frames, dofs] = True
        _stiffen(Hb, coefs, free)
        self._scale, self.L = _factor(_lower_band(Hb))
        self._frames, self._dofs = frames, dofs
        self.size = coefs.size * nv
        self._U, self._f = _low_rank(self, al, basis, variables, P, [t for t in terms if isinstance(t, Outer)])

    def solve_lower(self, y: np.ndarray) -> np.ndarray:
        """L^-1 y (y (N,) or (N, r)) for H_C = L L^T, L = diag(d)^-1 L' with L' LAPACK's factor of the
        equilibrated diag(d) H_C diag(d) (`_factor`)."""
        out, _ = dtbtrs(self.L, y * (self._scale if y.ndim == 1 else self._scale[:, None]), uplo="L", trans="N")
        return out

    def solve_upper(self, z: np.ndarray) -> np.ndarray:
        """L^-T z."""
        out, _ = dtbtrs(self.L, z, uplo="L", trans="T")
        return out * self._scale

    def apply(self, z: np.ndarray) -> np.ndarray:
        """x = S z = Sel A L^-T F z."""
        if self._U is not None:
            z = z + self._U @ (self._f * (self._U.T @ z))
        X = self.coefs.at_frames @ self.solve_upper(z).reshape(-1, self.nv)
        return X[self._frames, self._dofs]

    def scatter(self, g: np.ndarray) -> np.ndarray:
        """A^T Sel^T g (N,): a gradient in x as one in the coefficients."""
        G = np.zeros((self.coefs.at_frames.shape[0], self.nv))
        G[self._frames, self._dofs] = g
        return (self.coefs.at_frames.T @ G).ravel()

    def apply_transpose(self, g: np.ndarray) -> np.ndarray:
        """S^T g = F L^-1 A^T Sel^T g (a gradient in x as one in z)."""
        y = self.solve_lower(self.scatter(g))
        if self._U is not None:
            y = y + self._U @ (self._f * (self._U.T @ y))
        return y


def _low_rank(pre, al, basis, variables, P: np.ndarray, outer: list):
    """(U (N, r), f (r,)) with F = I + U diag(f) U^T = (I + V V^T)^(-1/2), V's columns sqrt(d2_p) S^T grad_x c_p
    (S^T without F: L^-1 A^T Sel^T) of the pairs whose curvature couples many points (`solver.curvature.Outer`),
    or (None, None) without any: the symmetric inverse square root of an identity plus a low-rank term, from
    V = Q R and R R^T = W diag(lambda) W^T (U = Q W, f = (1 + lambda)^(-1/2) - 1; Golub & Van Loan, Matrix
    Computations, 4th ed., sec. 2.1.4 and 8.1). grad_x c_p is the constraint's own reverse pass, one for the
    pairs that share no point, each pair's part of the path's adjoint then pulled back apart."""
    cols, weights = [], []
    x0 = np.zeros(variables.size)
    for o in outer:
        for color in _colors(o):
            st = al.state(basis, P)
            g = np.zeros(len(o.d2))
            g[color] = 1.0
            o.constraint.pull(st, g)
            dY = st.pullback()
            for p in color:
                rows = np.zeros(len(dY[0]), bool)
                rows[o.points[o.pair == p]] = True
                G = basis.pullback(*(np.where(rows[:, None], d, 0.0) for d in dY))
                cols.append(pre.scatter(variables.pullback(x0, G)))
                weights.append(np.sqrt(o.d2[p]))
    if not cols:
        return None, None
    Q, R = np.linalg.qr(pre.solve_lower(np.stack(cols, axis=1)) * np.array(weights))  # one solve, every pair
    lam, W = np.linalg.eigh(R @ R.T)
    return Q @ W, 1.0 / np.sqrt(1.0 + np.maximum(lam, 0.0)) - 1.0


def _colors(o) -> list:
    """The live pairs of an `Outer` (d2 > 0) in groups that share no quadrature point (greedy, in order)."""
    groups, used = [], []
    for p in np.flatnonzero(o.d2 > 0):
        pts = set(o.points[o.pair == p].tolist())
        for grp, seen in zip(groups, used):
            if not pts & seen:
                grp.append(p)
                seen |= pts
                break
        else:
            groups.append([p])
            used.append(pts)
    return groups


def _change_terms(al) -> list:
    """D/D0's Hessian as `Curvature` terms: 2 w_i omega^4 P_i / D0 on the pose and 2 w_i M_i / D0 on qacc
    (`solver.change`)."""
    ch, nv = al.change, al.tmap.nv
    n = len(ch.ref.weights)
    w = ch.ref.weights * (2.0 / al.d0)
    P = ch.pose_metric
    pose = P if P.ndim == 3 else np.einsum("ni,ij->nij", P, np.eye(nv))
    eye = np.broadcast_to(np.eye(nv), (n, nv, nv))
    allp, alld = np.arange(n), np.arange(nv)
    return [Curvature(allp, alld, {0: eye}, (w * ch.omega ** 4)[:, None, None] * pose),
            Curvature(allp, alld, {2: eye}, w[:, None, None] * ch.mass)]


def _bmm(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A @ B over a leading batch: numpy's batched matmul for large matrices, a broadcast sum for small ones
    (matmul calls a kernel per matrix: for 3 x 3 blocks that costs ~10x the arithmetic)."""
    if A.shape[-1] * A.shape[-2] * B.shape[-1] > 4096:
        return np.matmul(A, B)
    return (A[..., :, :, None] * B[..., None, :, :]).sum(-2)


_PAIRS = [(ca, cb) for ca in range(4) for cb in range(ca + 1)]  # [indices] a knot interval's coefficient pairs, row >= column


def _assemble(coefs: SplineCoefficients, terms: list, M: dict, nv: int) -> np.ndarray:
    """(m + 2, 4, nv, nv) the lower block band of sum over `terms` (`Curvature`) of their curvature in the
    B-spline coefficients: each term's factors pulled back to the frame variables' orders through the motion
    maps M (`_motion_maps`: F'^a = sum_r F^r M[r, a]), then sum_i (b_i^a b_i^b^T) (x) F'^a_i^T K_i F'^b_i
    summed over the points of each knot interval that share a support. [c, d] is the block (c + d, c)."""
    Hb = np.zeros((coefs.size, 4, nv, nv))
    for t in terms:
        q = len(t.points)
        sup = np.broadcast_to(t.support, (q, np.shape(t.support)[-1]))
        kinds, sid = np.unique(sup, axis=0, return_inverse=True)
        order = np.lexsort((t.points, sid.ravel()))  # by support, then by point
        pts, sup, sid = t.points[order], sup[order], sid.ravel()[order]
        F = {}
        for r, f in t.factors.items():
            if r == "qpos":  # by the qpos components: through dY/dd = p [0, d/2] (`_motion_maps`)
                qs = np.broadcast_to(t.qpos_support, (q, np.shape(t.qpos_support)[-1]))[order]
                x = _bmm(f[order], M["qpos"][pts[:, None, None], qs[:, :, None], sup[:, None, :]])
                F[0] = F[0] + x if 0 in F else x
                continue
            for key, m in M.items():
                if key != "qpos" and key[0] == r:
                    a = key[1]
                    x = _bmm(f[order], m[pts[:, None, None], sup[:, :, None], sup[:, None, :]])
                    F[a] = F[a] + x if a in F else x
        keys = [(a, b) for a in F for b in F]
        KF = {b: _bmm(t.K[order], f) for b, f in F.items()}
        ns, nk = sup.shape[1], len(keys)
        Xf = np.stack([_bmm(F[a].transpose(0, 2, 1), KF[b]) for a, b in keys], axis=1).reshape(q * nk, ns * ns)
        span = coefs.span[pts]
        new = np.r_[True, (span[1:] != span[:-1]) | (sid[1:] != sid[:-1])]
        group, first = np.cumsum(new) - 1, np.flatnonzero(new)
        gk = np.repeat(group, nk)
        for ca, cb in _PAIRS:  # sum over each group's points and the orders, in one product
            w = np.stack([coefs.b[a][pts, ca] * coefs.b[b][pts, cb] for a, b in keys], axis=1).ravel()
            acc = (csr_matrix((w, (gk, np.arange(q * nk))), shape=(len(first), q * nk)) @ Xf).reshape(-1, ns, ns)
            gs = sup[first]
            Hb[(span[first] + cb)[:, None, None], ca - cb, gs[:, :, None], gs[:, None, :]] += acc
    return Hb


#: [rad] the rotation step of the motion maps' central differences (`_motion_maps`), on unit quaternions: their
#: truncation error is ~1e-14 relative (step squared), round-off ~1e-16 / 1e-7 = 1e-9 relative
MOTION_STEP = 1e-7


def _motion_maps(tm, st, Yd) -> dict:
    """{(r, s): (n, nv, nv)} the derivative of the path's r-th order tangent (0 the pose, 1 qvel, 2 qacc) at
    each point by the s-th time derivative of the frame variables' change: the pose's `_tangent_maps`, qvel's
    and qacc's by central differences of `TangentMap.motion`. A frame variable's rotation vector d moves its
    frame's quaternion by p [0, d/2], so a change d(t) of the spline p(t) moves the path's r-th derivative by
    d^r/dt^r (p [0, d/2]) (Leibniz: p^(r-j) [0, d^(j)/2] times binomial(r, j)), whose qvel and qacc
    (PathMotion) depend on the quaternion's value and derivatives alike; linear components map one to one.

    Args:
        tm: TangentMap. st: the PathState at the points. Yd: (Y, Y', Y'') each (n, nq), the frames' spline.
    """
    n = len(st.Y)
    out = {(0, 0): _tangent_maps(tm, st.Y, Yd[0]), "qpos": _qpos_map(tm, Yd[0])}
    eye = np.zeros((n, tm.nv, tm.nv))
    eye[:, tm.lin_v, tm.lin_v] = 1.0
    for r, s in ((1, 0), (1, 1), (2, 0), (2, 1), (2, 2)):
        out[(r, s)] = eye.copy() if r == s else np.zeros((n, tm.nv, tm.nv))
    if not len(tm.quat_q):
        return out
    p = [y[:, tm.quat_q] for y in Yd]  # (n, k, 4) each: p, p', p''
    Ys = [st.Y, st.Y1, st.Y2]
    binom = ((1,), (1, 1), (1, 2, 1))
    for axis in range(3):
        for s in range(3):  # d^(s) = e_axis, the other derivatives 0: the path's r-th derivative moves by
            moved = []      # binomial(r, s) p^(r-s) [0, e/2] for r >= s
            for sign in (1.0, -1.0):
                Y = [y.copy() for y in Ys]
                for r in range(s, 3):  # p^(r-s) [0, e_axis / 2]
                    Y[r][:, tm.quat_q] += sign * MOTION_STEP * binom[r][s] * 0.5 * left_matrix(p[r - s])[..., 1 + axis]
                mo = tm.motion(*Y)
                moved.append((mo.qvel, mo.qacc))
            for r in (1, 2):
                if r < s:
                    continue
                dv = (moved[0][r - 1] - moved[1][r - 1]) / (2.0 * MOTION_STEP)  # (n, nv)
                for vv in tm.quat_v:
                    out[(r, s)][:, vv, vv[axis]] = dv[:, vv]
    return out


def _qpos_map(tm, Yd: np.ndarray) -> np.ndarray:
    """(n, nq, nv) dY/dd at each point: 1 for a linear component, p [0, d/2] = (1/2) L(p)[:, 1:] d for a
    quaternion slot whose frames' spline is p there."""
    out = np.zeros((len(Yd), tm.nq, tm.nv))
    out[:, tm.lin_q, tm.lin_v] = 1.0
    for qq, vv in zip(tm.quat_q, tm.quat_v):
        out[:, qq[:, None], vv[None, :]] = 0.5 * left_matrix(Yd[:, qq])[:, :, 1:]
    return out


def _tangent_maps(tm, Y: np.ndarray, Yd: np.ndarray) -> np.ndarray:
    """(n, nv, nv) d(path tangent)/d(frame variable) per point, Y the path's qpos and Yd the frames' spline's
    at the points: the vector part of conj(Q) p [0, d], L(r)[1:, 1:] d with r = conj(Q) p, Q and p the unit
    quaternions there (the identity on linear components)."""
    T = np.zeros((len(Y), tm.nv, tm.nv))
    T[:, tm.lin_v, tm.lin_v] = 1.0
    for qq, vv in zip(tm.quat_q, tm.quat_v):
        Q = Y[:, qq] / np.linalg.norm(Y[:, qq], axis=1, keepdims=True)
        p = Yd[:, qq] / np.maximum(np.linalg.norm(Yd[:, qq], axis=1, keepdims=True), 1e-300)
        T[:, vv[:, None], vv[None, :]] = left_matrix(mul(conj(Q), p))[:, 1:, 1:]
    return T


def _stiffen(Hb: np.ndarray, coefs: SplineCoefficients, free: np.ndarray) -> None:
    """Add STIFF times the squares of the natural end conditions' rows (every dof) and of each pinned
    frame value's row, each scaled to unit length, to Hb, in place."""
    nv = Hb.shape[2]
    diag = np.einsum("cii->ci", Hb[:, 0])  # (m + 2, nv) a view
    rows = [(coefs.ends[e], np.ones(nv, bool)) for e in range(2)]
    A = coefs.at_frames
    rows += [(A[k].toarray().ravel(), ~free[k]) for k in np.flatnonzero(~free.all(axis=1))]
    for a, mask in rows:
        a = a / np.linalg.norm(a)
        nz = np.flatnonzero(a)
        d = np.flatnonzero(mask)
        beta = STIFF * diag[nz][:, d].max(axis=0)  # the stiffness of the coefficients it ties, per dof
        for i in nz:
            for j in nz:
                if i >= j and i - j < 4:
                    Hb[j, i - j, d, d] += beta * a[i] * a[j]


def _factor(ab: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(d (N,), L) with d_i^-1 d_j^-1 H_ij = (L L^T)_ij: LAPACK's banded Cholesky of H (lower band storage ab) scaled
    to a unit diagonal first (Jacobi equilibration: the penalty's curvature and D's differ by orders of magnitude
    between the degrees of freedom; Higham, Accuracy and Stability of Numerical Algorithms, 2nd ed., sec. 10.1);
    where that fails (H is positive semidefinite: a failure is round-off), with RIDGE of that diagonal added, raised
    tenfold until it succeeds. Not a ridge from the start: equilibrated, the band's least curvature is far below
    RIDGE where STIFF's rows set the scale (a 40-frame clean at 120 fps: with it, S S^T fell short of the Hessian's
    inverse 1000-fold along the slowest displacements; without, the two agreed within 0.1 %)."""
    d = 1.0 / np.sqrt(np.maximum(ab[0], 1e-300))
    u = ab.shape[0]
    scaled = ab.copy()
    for k in range(u):
        scaled[k, : ab.shape[1] - k] *= d[k:] * d[: ab.shape[1] - k]
    ridge = 0.0
    while True:
        trial = scaled.copy()
        trial[0] += ridge
        try:
            return d, scipy.linalg.cholesky_banded(trial, lower=True)
        except np.linalg.LinAlgError:
            ridge = RIDGE if ridge == 0.0 else 10.0 * ridge
            if ridge > 1.0:
                raise


#: [1] the ridge added to the equilibrated H_C's unit diagonal where its Cholesky fails: 1e-10, above the round-off of a
#: positive semidefinite matrix's Cholesky (~n eps = 1e-12 for n ~ 1e4)
RIDGE = 1e-10


def _lower_band(Hb: np.ndarray) -> np.ndarray:
    """LAPACK's lower band storage ab[i - j, j] = H[i, j] (4 nv rows) of the block band Hb."""
    nc, _, nv, _ = Hb.shape
    N = nc * nv
    ab = np.zeros((4 * nv, N))
    p, q = np.meshgrid(np.arange(nv), np.arange(nv), indexing="ij")
    for d in range(4):
        keep = (p >= q) if d == 0 else np.ones((nv, nv), bool)
        pp, qq = p[keep], q[keep]
        c = np.arange(nc - d)
        ab[(d * nv + pp - qq)[None, :], c[:, None] * nv + qq[None, :]] = Hb[: nc - d, d][:, pp, qq]
    return ab
