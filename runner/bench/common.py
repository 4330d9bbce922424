"""Shared pieces of the benchmarks: of the baselines (runner/bench/barr92.py, runner/bench/bspline.py) the result,
the input check, the normalized path energy and the time-limited SLSQP driver; and a call's median time."""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize
from threadpoolctl import threadpool_limits

from solver.quaternion import align_hemispheres


@dataclass
class BaselineResult:
    """Result of one baseline run.

    Attributes:
        path_times: (n,) increasing sample times [s], covering [t_0, t_{K-1}], including every keyframe
            time and every knot/sample time of the method's continuous path.
        path_u: (n, 4) the method's continuous path, normalized (unit quaternions, w x y z), at path_times.
        wall_time_s: wall time of setup, optimization and the continuous path's construction [s]; the
            report on it (E, the dense samples and their unit violation) is not timed, as `orient`'s
            summary is not (`OrientResult.energy`).
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


def median_time(fn: Callable, repeat: int, clock: Callable[[], float] = time.perf_counter) -> tuple:
    """(the last result of fn(), the median [s] of `repeat` calls' times by `clock`: wall by default,
    `time.process_time` for this process's CPU)."""
    times, out = [], None
    for _ in range(max(1, repeat)):
        t0 = clock()
        out = fn()
        times.append(clock() - t0)
    return out, float(np.median(times))


def check_inputs(times, quats):
    """Keyframe times (K,) [s] and unit, hemisphere-aligned quaternions (K, 4); ValueError for other
    shapes, or times that are not finite and strictly increasing."""
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


def dense_path(q_of_t: Callable, breaks: np.ndarray, times: np.ndarray, min_per_interval: int = 400):
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


class TimeUp(Exception):
    """Raised inside an SLSQP callback when the wall-time limit is reached."""


def run_slsqp(problem, max_time_s: float, ftol: float, maxiter: int):
    """SLSQP with a wall-time limit; returns (x, status, n_evals)."""
    t_start = time.perf_counter()
    state = {"n": 0, "x_acc": problem.x0.copy()}

    def fun(x):
        if time.perf_counter() - t_start > max_time_s:
            raise TimeUp
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
    except TimeUp:
        return state["x_acc"], "time_limit", state["n"]
    status = "converged" if res.success else f"failed: {res.message}"
    return res.x, status, state["n"]
