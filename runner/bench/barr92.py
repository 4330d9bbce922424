"""(a) Barr et al. 1992: discrete samples, hard unit-norm constraints (see runner/bench/baselines.py)."""
from __future__ import annotations

import time

import numpy as np
from scipy.interpolate import CubicSpline

from runner.bench.common import BaselineResult, check_inputs, dense_path, normalized_path_energy, run_slsqp


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
        times, q = check_inputs(times, quats)
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
    x, status, n = run_slsqp(pb, max_time_s, ftol, maxiter)
    U = pb.samples(x)
    cs = CubicSpline(pb.t, U, bc_type="natural")
    wall = time.perf_counter() - t0  # the continuous path is made; its energy and samples are a report
    E = normalized_path_energy(cs, pb.t)
    pt, pu, viol = dense_path(cs, pb.t, pb.times)
    return BaselineResult(
        path_times=pt, path_u=pu, wall_time_s=wall, n_evals=n, status=status, E=E,
        method="barr92", resolution=int(resolution), n_vars=x.size, n_constraints=pb.n_free,
        max_unit_violation=viol,
        extra={"sample_times": pb.t, "samples": U, "sample_norm_error": float(np.max(np.abs(
            np.linalg.norm(U, axis=1) - 1.0)))},
    )
