"""The two earlier methods the orientation benchmark compares against (paper sec. 3 and sec. 4).

Problem (paper sec. 3): keyframe times t_0..t_{K-1} [s] and unit quaternions (K, 4) (w x y z); find an
orientation path through them minimizing E = integral |covariant acceleration|^2 dt. Accuracy of any
method is measured on its *continuous, normalized* path u(t) = q(t)/|q(t)|:

    E(u) = integral_{t_0}^{t_{K-1}} |u'' - u (u''.u)|^2 dt                                   [1/s^3]

and the relative gap (E - E*)/E* against the exact optimum E* (a natural Riemannian cubic spline on
S^3, computed independently in runner/bench/sphere_reference/).

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
deterministic. Nothing here is shared with the method of solver/ (only the hemisphere alignment).
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from runner.bench.barr92 import BarrProblem, barr92_discrete
from runner.bench.bspline import BSplineProblem, bspline_coefficients
from runner.bench.common import BaselineResult, normalized_path_energy

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
        times, quats: the keyframes; E_star: the exact optimum [1/s^3] (runner/bench/sphere_reference/).
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
