"""The two earlier methods the orientation benchmark compares against (paper sec. 3 and sec. 4).

Problem (paper sec. 3): keyframe times t_0..t_{K-1} [s] and unit quaternions (K, 4) (w x y z); find an
orientation path through them minimizing E = integral |covariant acceleration|^2 dt. Accuracy of any
method is measured on its *continuous, normalized* path u(t) = q(t)/|q(t)|:

    E(u) = integral_{t_0}^{t_{K-1}} |u'' - u (u''.u)|^2 dt                                   [1/s^3]

and the relative gap (E - E*)/E* against the exact optimum E* (a natural Riemannian cubic spline on
S^3, computed independently in tests/sphere_reference.py).

(a) `barr92_discrete` - Barr, Currin, Gabriel & Hughes 1992 ("Smooth interpolation of orientations
    with angular velocity constraints using quaternions", SIGGRAPH '92): the unknowns are quaternions
    at m samples inside every keyframe interval; objective = sum of squared finite-difference covariant
    accelerations (three-point second differences with their radial part removed) times dt; hard
    unit-norm equality constraints at every sample; a constrained optimizer (SLSQP with analytic
    gradients). The continuous path is afterwards a natural cubic spline in R^4 through all the samples,
    normalized - this post-interpolation is part of the method's error (paper sec. 3: "subsequent
    interpolation between these points ... would violate the unitariness").
(b) `bspline_coefficients` - Cohen 1992 style ("Interactive spacetime control for animation",
    SIGGRAPH '92), the alternative the paper argues against (sec. 4, "VARIABLE POINTS"): the unknowns are
    the coefficients of a cubic B-spline in R^4; objective = the paper's eq. 9 with a plain weight,
    lambda (1 - q.q)^2 + |q'' - q (q''.q)/(q.q)|^2, integrated by quadrature; the keyframes are linear
    equality constraints on the coefficients; SLSQP.

Both use analytic gradients (checked against finite differences in tests/test_baselines.py), stop on
SLSQP's `ftol` on the objective scaled to 1 at the start, obey a wall-time limit, and are
deterministic. Nothing here is shared with solver/.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from threadpoolctl import threadpool_limits
from scipy.interpolate import BSpline, CubicSpline
from scipy.optimize import minimize

from solver.quaternion import align_hemispheres

__all__ = [
    "BaselineResult",
    "BarrProblem",
    "BSplineProblem",
    "barr92_discrete",
    "bspline_coefficients",
    "baseline_time_to_gap",
    "normalized_path_energy",
    "METHODS",
]


@dataclass
class BaselineResult:
    """Result of one baseline run.

    Attributes:
        path_times: (n,) increasing sample times [s], covering [t_0, t_{K-1}], including every keyframe
            time and every knot/sample time of the method's continuous path.
        path_u: (n, 4) the method's continuous path, normalized (unit quaternions, w x y z), at path_times.
        wall_time_s: wall time of the optimization, setup and path evaluation included [s].
        n_evals: objective (+gradient) evaluations.
        status: "converged" (SLSQP's ftol reached), "time_limit" (stopped at max_time_s; the last
            accepted iterate is returned - SLSQP's early iterates on the larger Barr problems are far
            from the optimum: m = 16 stopped after ~13 s had gap ~2e3), or "failed: <SLSQP message>"
            (last iterate returned).
        E: energy integral |cov. acc.|^2 dt of the normalized continuous path [1/s^3], by Gauss-Legendre
            quadrature (8 nodes per polynomial piece) of the analytic expression - accurate to ~1e-12
            relative.
        method: "barr92" or "bspline".
        resolution: the resolution parameter used.
        n_vars, n_constraints: optimization problem size.
        max_unit_violation: max | |q| - 1 | over the path before normalization (0 up to rounding at
            keyframes; for Barr's method, between samples).
    """

    path_times: np.ndarray
    path_u: np.ndarray
    wall_time_s: float
    n_evals: int
    status: str
    E: float = float("nan")
    method: str = ""
    resolution: int = 0
    n_vars: int = 0
    n_constraints: int = 0
    max_unit_violation: float = float("nan")
    extra: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------------------------------
# helpers


def _check(times, quats):
    times = np.asarray(times, dtype=float)
    quats = np.asarray(quats, dtype=float)
    if times.ndim != 1 or len(times) < 2 or quats.shape != (len(times), 4):
        raise ValueError(f"need times (K,) with K >= 2 and quats (K, 4); got {times.shape}, {quats.shape}")
    if np.any(np.diff(times) <= 0) or not np.all(np.isfinite(times)):
        raise ValueError("keyframe times must be finite and strictly increasing")
    return times, align_hemispheres(quats / np.linalg.norm(quats, axis=1, keepdims=True))


def normalized_path_energy(q_of_t: Callable, breaks: np.ndarray, n_gauss: int = 8) -> float:
    """E of the normalized path u = q/|q| for a piecewise-polynomial q(t) in R^4.

    The covariant acceleration of u is, with n = q.q and P = I - q q^T / n,
        u'' - u (u''.u) = (P q'' - 2 (q.q')/n P q') / sqrt(n)
    (write q = rho u: P q' = rho u', P q'' = 2 rho' u' + rho (u'')_tan, (q.q')/n = rho'/rho).
    Integrated with n_gauss-point Gauss-Legendre on every polynomial piece.

    Args:
        q_of_t: callable (t (n,), nu) -> (n, 4) nu-th derivative of q (CubicSpline / BSpline style).
        breaks: (b,) the piece boundaries [s] (knots), increasing.
    Returns:
        E [1/s^3].
    """
    xg, wg = np.polynomial.legendre.leggauss(n_gauss)
    b = np.asarray(breaks, dtype=float)
    half = 0.5 * np.diff(b)
    mid = 0.5 * (b[1:] + b[:-1])
    t = (mid[:, None] + half[:, None] * xg[None, :]).ravel()
    w = (half[:, None] * wg[None, :]).ravel()
    q, q1, q2 = q_of_t(t, 0), q_of_t(t, 1), q_of_t(t, 2)
    n = np.sum(q * q, axis=1)

    def P(v):
        return v - q * (np.sum(v * q, axis=1) / n)[:, None]

    acc = (P(q2) - 2.0 * (np.sum(q * q1, axis=1) / n)[:, None] * P(q1)) / np.sqrt(n)[:, None]
    return float(np.sum(w * np.sum(acc * acc, axis=1)))


def _dense_path(q_of_t: Callable, breaks: np.ndarray, times: np.ndarray, min_per_interval: int = 400):
    """Sample times including every break (and keyframe), and u = q/|q| there; max | |q| - 1 |."""
    pieces = []
    for a, b in zip(times[:-1], times[1:]):
        inner = breaks[(breaks > a) & (breaks < b)]
        kb = np.concatenate([[a], inner, [b]])
        per = max(4, math.ceil(min_per_interval / (len(kb) - 1)))
        for c, d in zip(kb[:-1], kb[1:]):
            pieces.append(np.linspace(c, d, per + 1)[:-1])
    t = np.concatenate(pieces + [times[-1:]])
    q = q_of_t(t, 0)
    nq = np.linalg.norm(q, axis=1)
    return t, q / nq[:, None], float(np.max(np.abs(nq - 1.0)))


class _TimeUp(Exception):
    pass


def _run_slsqp(problem, max_time_s: float, ftol: float, maxiter: int):
    """SLSQP with a wall-time limit; returns (x, status, n_evals)."""
    t_start = time.perf_counter()
    state = {"n": 0, "x_acc": problem.x0.copy()}

    def fun(x):
        if time.perf_counter() - t_start > max_time_s:
            raise _TimeUp
        state["n"] += 1
        f, g = problem.objective(x)
        return f / problem.scale, g / problem.scale

    def cb(xk):
        state["x_acc"] = np.array(xk, copy=True)

    cons = [{"type": "eq", "fun": problem.constraint, "jac": problem.constraint_jac}]
    try:
        with threadpool_limits(1):  # small dense products: threads only add contention
            res = minimize(
                fun, problem.x0, jac=True, method="SLSQP", constraints=cons, callback=cb,
                options={"ftol": ftol, "maxiter": maxiter},
            )
    except _TimeUp:
        return state["x_acc"], "time_limit", state["n"]
    status = "converged" if res.success else f"failed: {res.message}"
    return res.x, status, state["n"]


# ----------------------------------------------------------------------------------------------------
# (a) Barr et al. 1992: discrete samples, hard unit-norm constraints


class BarrProblem:
    """Barr et al. 1992 discrete problem with m free samples per keyframe interval.

    Grid: in interval j, points t_j + k h_j, k = 0..m+1, h_j = (t_{j+1} - t_j)/(m+1); keyframes fixed.
    Unknowns x: the free samples' quaternions, (n_free * 4,) flattened (row = sample).
    Objective F = sum over interior grid points g of w_g |d_g - u_g (d_g.u_g)/(u_g.u_g)|^2, with d_g the
    three-point second difference (non-uniform at keyframes: d = 2[(u+ - u)/h+ - (u - u-)/h-]/(h- + h+))
    and w_g = (h- + h+)/2 [s]: the trapezoid rule for the integral of the squared covariant acceleration
    (the end points, where the natural optimum has zero covariant acceleration, are left out).
    Constraints: u.u - 1 = 0 at every free sample (hard, one per sample).
    """

    def __init__(self, times: np.ndarray, quats: np.ndarray, m: int):
        times, q = _check(times, quats)
        if m < 1:
            raise ValueError("Barr's method needs m >= 1 samples per keyframe interval")
        self.times, self.q, self.m = times, q, int(m)
        K = len(times)
        self.t = np.concatenate(
            [np.linspace(times[j], times[j + 1], m + 2)[:-1] for j in range(K - 1)] + [times[-1:]]
        )
        M = len(self.t)
        self.fixed_idx = np.arange(0, M, m + 1)
        self.free_idx = np.setdiff1d(np.arange(M), self.fixed_idx)
        g = np.arange(1, M - 1)
        h1, h2 = self.t[g] - self.t[g - 1], self.t[g + 1] - self.t[g]
        self.g = g
        self.al = 2.0 / (h1 * (h1 + h2))
        self.ga = 2.0 / (h2 * (h1 + h2))
        self.be = -(self.al + self.ga)
        self.w = 0.5 * (h1 + h2)
        # start: the normalized natural cubic spline through the keyframes (unit, so feasible)
        u0 = CubicSpline(times, q, bc_type="natural")(self.t)
        u0 /= np.linalg.norm(u0, axis=1, keepdims=True)
        self.x0 = u0[self.free_idx].ravel()
        self.scale = max(self.objective(self.x0)[0], 1e-12)

    @property
    def n_free(self) -> int:
        return len(self.free_idx)

    def samples(self, x: np.ndarray) -> np.ndarray:
        """(M, 4) all grid quaternions (keyframes + free samples) for unknowns x."""
        U = np.empty((len(self.t), 4))
        U[self.fixed_idx] = self.q
        U[self.free_idx] = np.asarray(x).reshape(-1, 4)
        return U

    def objective(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """(F, dF/dx); F in [1/s^3]."""
        U = self.samples(x)
        g = self.g
        d = self.al[:, None] * U[g - 1] + self.be[:, None] * U[g] + self.ga[:, None] * U[g + 1]
        u = U[g]
        c = np.sum(d * u, axis=1) / np.sum(u * u, axis=1)
        p = d - c[:, None] * u
        F = float(np.sum(self.w * np.sum(p * p, axis=1)))
        # f = |d|^2 - (d.u)^2/(u.u):  df/dd = 2p,  df/du (explicit) = -2 c p
        gp = 2.0 * self.w[:, None] * p
        G = np.zeros_like(U)
        np.add.at(G, g - 1, self.al[:, None] * gp)
        np.add.at(G, g + 1, self.ga[:, None] * gp)
        G[g] += self.be[:, None] * gp - c[:, None] * gp
        return F, G[self.free_idx].ravel()

    def constraint(self, x: np.ndarray) -> np.ndarray:
        X = np.asarray(x).reshape(-1, 4)
        return np.sum(X * X, axis=1) - 1.0

    def constraint_jac(self, x: np.ndarray) -> np.ndarray:
        X = np.asarray(x).reshape(-1, 4)
        n = len(X)
        J = np.zeros((n, 4 * n))
        rows = np.repeat(np.arange(n), 4)
        J[rows, np.arange(4 * n)] = 2.0 * X.ravel()
        return J


def barr92_discrete(
    times: np.ndarray,
    quats: np.ndarray,
    resolution: int,
    max_time_s: float = 60.0,
    ftol: float = 1e-10,
    maxiter: int = 100000,
) -> BaselineResult:
    """Barr et al. 1992 discrete method: `resolution` = m free samples per keyframe interval.

    See `BarrProblem` for the objective and constraints. Solved with SLSQP (analytic gradients of
    objective and constraints), objective scaled to 1 at the start, stopping on `ftol`. The continuous
    path: natural cubic spline in R^4 through all samples (keyframes included) at their times,
    normalized; `E` is that path's energy.

    Args:
        times: (K,) keyframe times [s]; quats: (K, 4) keyframe quaternions (w x y z).
        resolution: m >= 1 samples per keyframe interval (unknowns: 4 m (K-1)).
        max_time_s: wall-time limit for the optimization [s].
    Returns:
        BaselineResult.
    """
    t0 = time.perf_counter()
    pb = BarrProblem(times, quats, resolution)
    x, status, n = _run_slsqp(pb, max_time_s, ftol, maxiter)
    U = pb.samples(x)
    cs = CubicSpline(pb.t, U, bc_type="natural")
    E = normalized_path_energy(cs, pb.t)
    pt, pu, viol = _dense_path(cs, pb.t, pb.times)
    return BaselineResult(
        path_times=pt, path_u=pu, wall_time_s=time.perf_counter() - t0, n_evals=n, status=status, E=E,
        method="barr92", resolution=int(resolution), n_vars=x.size, n_constraints=pb.n_free,
        max_unit_violation=viol,
        extra={"sample_times": pb.t, "samples": U, "sample_norm_error": float(np.max(np.abs(
            np.linalg.norm(U, axis=1) - 1.0)))},
    )


# ----------------------------------------------------------------------------------------------------
# (b) Cohen 1992 style: B-spline coefficients, keyframes as linear equality constraints


class BSplineProblem:
    """Cubic B-spline in R^4 with keyframe equality constraints (paper sec. 4's alternative).

    Knots: in every keyframe interval `r` uniform spans (so the keyframe times are knots), clamped ends:
    n_coef = (K-1) r + 3. Unknowns x = the coefficient matrix C (n_coef, 4), flattened row-major.
    Objective (paper eq. 9 with a plain weight lambda):
        F = integral lambda (1 - q.q)^2 + |q'' - q (q''.q)/(q.q)|^2 dt,
    by the same n_quad-point Gauss-Legendre rule in every (uniform) span. Design matrices from
    `scipy.interpolate.BSpline.design_matrix` (values) and `BSpline(knots, I, 3).derivative(2)`.
    Constraints: B(t_i) C = q_i for every keyframe (4K linear equalities).
    """

    def __init__(self, times: np.ndarray, quats: np.ndarray, r: int, lam: float = 1e4, n_quad: int = 5):
        times, q = _check(times, quats)
        if r < 1:
            raise ValueError("need r >= 1 spans per keyframe interval")
        self.times, self.q, self.r, self.lam = times, q, int(r), float(lam)
        K = len(times)
        self.breaks = np.concatenate(
            [np.linspace(times[j], times[j + 1], r + 1)[:-1] for j in range(K - 1)] + [times[-1:]]
        )
        k = 3
        self.knots = np.concatenate([[times[0]] * k, self.breaks, [times[-1]] * k])
        self.n_coef = len(self.knots) - k - 1
        xg, wg = np.polynomial.legendre.leggauss(n_quad)
        b = self.breaks
        half, mid = 0.5 * np.diff(b), 0.5 * (b[1:] + b[:-1])
        self.tq = (mid[:, None] + half[:, None] * xg[None, :]).ravel()
        self.wq = (half[:, None] * wg[None, :]).ravel()
        self.B0 = BSpline.design_matrix(self.tq, self.knots, k).tocsr()
        from scipy.sparse import csr_matrix, kron, identity

        eye = np.eye(self.n_coef)
        self.B2 = csr_matrix(BSpline(self.knots, eye, k).derivative(2)(self.tq))
        Bk = BSpline.design_matrix(times, self.knots, k).tocsr()
        self.A_eq = kron(Bk, identity(4)).toarray()
        self.b_eq = q.ravel()
        # start: the natural cubic spline in R^4 through the keyframes - it lies in this spline space
        # (its knots are the keyframe times), so the start is feasible
        cs = CubicSpline(times, q, bc_type="natural")
        tg = np.linspace(times[0], times[-1], 4 * self.n_coef)
        Bg = BSpline.design_matrix(tg, self.knots, k).toarray()
        C0 = np.linalg.lstsq(Bg, cs(tg), rcond=None)[0]
        self.x0 = C0.ravel()
        self.scale = max(self.objective(self.x0)[0], 1e-12)

    def spline(self, x: np.ndarray) -> BSpline:
        return BSpline(self.knots, np.asarray(x).reshape(self.n_coef, 4), 3)

    def objective(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """(F, dF/dx); F in [1/s^3] (lambda in [1/s^4])."""
        C = np.asarray(x).reshape(self.n_coef, 4)
        Y = self.B0 @ C
        A = self.B2 @ C
        n = np.sum(Y * Y, axis=1)
        ay = np.sum(A * Y, axis=1)
        c = ay / n
        one = 1.0 - n
        f = self.lam * one**2 + np.sum(A * A, axis=1) - ay * c
        F = float(np.sum(self.wq * f))
        # d f / d Y = -4 lam (1 - n) Y - 2 c A + 2 c^2 Y ;  d f / d A = 2 A - 2 c Y
        gY = (-4.0 * self.lam * one + 2.0 * c**2)[:, None] * Y - 2.0 * c[:, None] * A
        gA = 2.0 * A - 2.0 * c[:, None] * Y
        G = self.B0.T @ (self.wq[:, None] * gY) + self.B2.T @ (self.wq[:, None] * gA)
        return F, np.asarray(G).ravel()

    def constraint(self, x: np.ndarray) -> np.ndarray:
        return self.A_eq @ x - self.b_eq

    def constraint_jac(self, x: np.ndarray) -> np.ndarray:
        return self.A_eq


def bspline_coefficients(
    times: np.ndarray,
    quats: np.ndarray,
    resolution: int,
    max_time_s: float = 60.0,
    lam: float = 1e4,
    ftol: float = 1e-10,
    maxiter: int = 100000,
) -> BaselineResult:
    """Cohen 1992 style: optimize cubic B-spline coefficients, keyframes as equality constraints.

    See `BSplineProblem`. SLSQP with analytic gradients, objective scaled to 1 at the start, stopping on
    `ftol`. The path is the B-spline q(t) normalized; `E` its energy.

    Args:
        times: (K,) keyframe times [s]; quats: (K, 4) keyframe quaternions (w x y z).
        resolution: r >= 1 uniform knot spans per keyframe interval (unknowns: 4 ((K-1) r + 3)).
        max_time_s: wall-time limit for the optimization [s].
        lam: weight lambda of the unit-norm penalty (eq. 9) [1/s^4]. With finite lambda the spline
            dips below unit length between keyframes (by ~|cov. acc.|^2 / (4 lambda); measured max
            | |q| - 1 | at r = 8: 5.7/lambda on large_nonuniform, 0.6/lambda on the moderate set; the paper
            reports < 0.2%), which biases the normalized path: a floor on the gap that resolution does
            not remove (large_nonuniform: ~4e-4 at lambda = 1e3, gap then *grows* with r; < 1e-5 at
            the default 1e4). Much larger lambda makes the problem stiff for SLSQP (lambda = 1e5, r = 4:
            gap 1.8e-3 vs 2.5e-4 at 1e4).
    Returns:
        BaselineResult.
    """
    t0 = time.perf_counter()
    pb = BSplineProblem(times, quats, resolution, lam=lam)
    x, status, n = _run_slsqp(pb, max_time_s, ftol, maxiter)
    spl = pb.spline(x)
    E = normalized_path_energy(spl, pb.breaks)
    pt, pu, viol = _dense_path(spl, pb.breaks, pb.times)
    return BaselineResult(
        path_times=pt, path_u=pu, wall_time_s=time.perf_counter() - t0, n_evals=n, status=status, E=E,
        method="bspline", resolution=int(resolution), n_vars=x.size, n_constraints=len(pb.b_eq),
        max_unit_violation=viol,
        extra={"keyframe_error": float(np.max(np.abs(pb.constraint(x)))), "lam": pb.lam},
    )


METHODS: dict[str, Callable[..., BaselineResult]] = {
    "barr92": barr92_discrete,
    "bspline": bspline_coefficients,
}

_LADDER = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128)


def baseline_time_to_gap(
    method: str | Callable[..., BaselineResult],
    times: np.ndarray,
    quats: np.ndarray,
    E_star: float,
    gaps: tuple = (1e-2, 1e-3, 1e-4),
    max_time_s: float = 60.0,
    resolutions: tuple = _LADDER,
    log: list | None = None,
) -> dict:
    """Increase a baseline's resolution until each gap level is reached or the time budget is spent.

    Runs `method` at resolutions 1, 2, 3, 4, 6, 8, 12, ... in turn (each run gets the remaining budget as
    its own time limit) and stops when every gap level is reached, the budget is spent, or the gap has
    not improved for two consecutive resolutions (e.g. the lambda floor of the B-spline method).

    Args:
        method: "barr92", "bspline", or a callable (times, quats, resolution, max_time_s) -> BaselineResult.
        times, quats: the keyframes; E_star: the exact optimum [1/s^3] (tests/sphere_reference.py).
        gaps: relative-gap levels (E - E*)/E*.
        max_time_s: total wall-time budget [s].
        log: if a list is given, one dict per run is appended (resolution, gap, wall_time_s, status).
    Returns:
        {gap: (wall_time_s, resolution, achieved_gap)} where wall_time_s is the wall time of the single
        run at the smallest resolution that reached the gap (the time a user who knew that resolution
        would spend), or {gap: (None, resolution, best_gap)} with the best gap found within the budget.
    """
    fn = METHODS[method] if isinstance(method, str) else method
    t_start = time.perf_counter()
    out: dict = {}
    best = (None, None, math.inf)  # (time, res, gap)
    stall = 0
    for res in resolutions:
        remaining = max_time_s - (time.perf_counter() - t_start)
        if remaining <= 0:
            break
        r = fn(times, quats, res, max_time_s=remaining)
        gap = (r.E - E_star) / E_star
        if log is not None:
            log.append({"resolution": res, "gap": gap, "wall_time_s": r.wall_time_s, "status": r.status,
                        "E": r.E, "n_evals": r.n_evals})
        if r.status == "time_limit":
            # not a finished run: count it only as "best gap within the budget"
            if gap < best[2]:
                best = (None, res, gap)
            break
        for g in gaps:
            if g not in out and gap <= g:
                out[g] = (r.wall_time_s, res, gap)
        if gap < best[2] * (1 - 1e-3):
            stall = 0
        else:
            stall += 1
        if gap < best[2]:
            best = (r.wall_time_s, res, gap)
        if all(g in out for g in gaps) or stall >= 2:
            break
    for g in gaps:
        if g not in out:
            out[g] = (None, best[1], best[2])
    return out
