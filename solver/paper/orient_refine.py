"""`orient(tol=...)`: the orientation's refinement strategy for `solve`'s loop (`GapToOptimum`): optimize
-> estimate the gap -> refine until the estimated relative gap (E - E*)/E*
(`solver.paper.error_estimate.estimate_gap`) is at most the tolerance (docs/orient.md "Accuracy on request: tol and the gap estimate"),
and the measures of an orientation path it uses (covariant energy by Gauss quadrature, max |1 - |q||)."""
from __future__ import annotations

import numpy as np

from solver.constraints.unit import UNIT_LIMIT
from solver.frames import FrameSet
from solver.lagrangian import GAMMA
from solver.layout import StateLayout
from solver.objective import Objective
from solver.optimize import OptimizeResult
from solver.paper.error_estimate import estimate_gap, optimization_gap
from solver.paper.refinement import Step, ToTolerance
from solver.quadrature import GAUSS_POINTS, gauss_nodes, gauss_times
from solver.spline import interpolate_segments
from solver.terms import NormalizedCovariantAcceleration

_SINGLE = StateLayout.single_quaternion()  # one orientation: qpos = q (4,)

#: [1] The estimate is a median-calibrated guess (true/estimated 0.4-3.6 on the tuning sets, 90% within
#: 0.7-1.6); a round is accepted when the estimate is at most tol / TOL_SAFETY, so that the true gap is
#: at most tol on all tuning sets (docs/orient.md, "Accuracy on request").
TOL_SAFETY = 2.0


#: The unit term f1 = (1 - q.q)^2 is a quadratic penalty on |q| = 1. When a round meets the tolerance
#: with max |1 - |q|| above the figure's own limit on it (`solver.constraints.unit.UNIT_LIMIT`, 3 %: a
#: 3 % change of speed within a segment once normalized), the penalty's weight grows by the method of
#: multipliers' factor (`solver.lagrangian.GAMMA`, 10; the penalty method of Nocedal & Wright,
#: Numerical Optimization, 2006, Framework 17.1) and the same frames are optimized again, for as long as
#: that lowers the drift. The normalized form's f2 does not see |q|, so this does not move its
#: exact-unit optimum.
DRIFT_LIMIT, DRIFT_BOOST = UNIT_LIMIT, GAMMA


class GapToOptimum(ToTolerance):
    """`solve`'s refinement strategy for `orient`'s tol: the loop of `solve`'s refine "tol"
    (`ToTolerance`: optimize -> estimate -> add a frame at the midpoint of every segment whose share of
    the estimate is within a factor of four of the largest, `adaptive_times`) with the estimated gap to
    the exact optimum as its estimate: `estimate_gap` plus the optimizer's stationarity gap
    (`_stationarity`) and the quadrature discrepancy (`quadrature_discrepancy`), accepted at
    tol / TOL_SAFETY.

    A round whose optimizer stopped short (a stall on its relative-decrease test) is not accepted: its
    stationarity gap counts in the estimate, and the next round optimizes every frame again. A round
    that is accepted with max |1 - |q|| above DRIFT_LIMIT has the unit weight (the objective's first)
    multiplied by DRIFT_BOOST and the same frames optimized again ("boost"), while that lowers the drift.

    Args:
        tol: the requested estimated gap (> 0). options: the SolveOptions of the solve (per_round,
            max_frames: default TOL_FRAMES_PER_INTERVAL per keyframe interval, precondition,
            radial_weight, quat_slots).
    Attributes:
        estimates, converged, final_estimate: `Refinement`'s. boosts: unit-weight boosts made.
        measures: {"frames", "energy", "drift"} of the last round (`covariant_energy`,
            `max_norm_deviation`), else {}.
    """

    what = "estimated gap"

    def __init__(self, tol: float, options):
        super().__init__(tol, options.per_round, options.max_frames, "decrease")
        self.options, self.measures = options, {}
        self.accept_at, self.bound = tol / TOL_SAFETY, f"tol {tol:g} / {TOL_SAFETY:g}"
        self.boosts, self._drift_before = 0, float("inf")

    def after_round(self, objective, frames, result, index, progress):
        step = super().after_round(objective, frames, result, index, progress)
        drift = self.measures["drift"]
        if self.converged and drift > DRIFT_LIMIT and drift < self._drift_before:
            # |q| leaves its limit: raise the unit term's penalty and optimize the same frames again, for
            # as long as that lowers the drift
            self.converged, self._drift_before = False, drift
            self.boosts += 1
            objective.weights[0] *= DRIFT_BOOST
            return Step("boost")
        return step

    def estimate(self, objective, frames, result):
        """The estimated gap and each segment's share of it (what ranks the segments to refine): the
        segment's GAP_FACTOR D_c / E (`estimate_gap`) plus its share of the quadrature discrepancy,
        |E_8,c - E_q,c| / E_8 (`segment_energies` by 8 points and by the objective's Gauss points), so
        that a segment whose integral the optimizer's rule gets wrong is refined too."""
        ev = objective.evaluate(frames.times, frames.values, grad=False)
        est, D = estimate_gap(objective, frames, ev.E)
        E8c = segment_energies(frames.times, frames.values)
        E8 = float(E8c.sum())
        shares = est * D / D.sum() if D.sum() > 0 else np.zeros_like(D)
        if objective.quadrature == "gauss" and E8 > 0:
            shares = shares + np.abs(E8c - segment_energies(frames.times, frames.values, objective.points)) / E8
        est += _discrepancy(ev.integrals, E8) + _stationarity(result, ev.E, objective, frames, self.options)
        self.measures = {"frames": frames, "energy": E8, "drift": max_norm_deviation(frames.times, frames.values)}
        return est, shares


def _stationarity(result: OptimizeResult, E: float, obj: Objective, frames: FrameSet, opts) -> float:
    """`optimization_gap` of the round's result, 0.5 |g_z|^2 / E: from the gradient in z the optimizer
    evaluated at its best iterate (`OptimizeResult.grad`), or, where there is none in z (no
    preconditioner, or the plain-variable retry of `solver.paper.backend.nlopt_backend`), by
    `optimization_gap`. The optimizer's z stretches the radial directions of the frames at the round's
    *start* (`radial_weight`), where `optimization_gap` takes them at its end; the frames turn little in
    a round, and this saves an evaluation with a gradient and a preconditioner."""
    g = result.grad
    if opts.precondition and g is not None and g.size == frames.n_free:
        return float(0.5 * (g @ g) / E) if E > 0 else 0.0
    return optimization_gap(obj, frames, opts.radial_weight, opts.quat_slots)


def quadrature_discrepancy(sol, E8: float) -> float:
    """|E_8 - E_q| / E_8: the covariant energy E8 of the solution's path by 8 Gauss points per segment
    (`covariant_energy`) against the objective's own quadrature (`points`, default 4), from a `Solution`'s
    `integrals_final`. The optimizer minimizes the latter and may exploit its error (a path that is
    smoother at the nodes than between them), which the predicted decreases, computed with the same
    quadrature, cannot see. Usually ~1e-6; found 1.6e-3 on a generated set with 125-130 degree steps
    0.2-0.3 s apart (docs/orient.md "Accuracy on request: tol and the gap estimate")."""
    return _discrepancy(sol.integrals_final, E8)


def _discrepancy(integrals: dict, E8: float) -> float:
    """`quadrature_discrepancy` from the term integrals {name: integral} of the path."""
    Eq = integrals.get("covariant_normalized")
    if Eq is None:
        return 0.0
    return abs(E8 - Eq) / E8 if E8 > 0 else 0.0


def unit_rows(values: np.ndarray) -> np.ndarray:
    """Starting values of the first variable frames: the plain spline's values put back on the unit
    sphere. Between keyframes theta apart the spline dips by ~theta^2/8; the spline through the
    projected values is nearer the optimum (L-BFGS needs 10-25% fewer evaluations, docs/orient.md "Defaults, and what they deliver")."""
    return values / np.linalg.norm(values, axis=1, keepdims=True)


def covariant_energy(frame_times: np.ndarray, frames: np.ndarray, points: int = 2 * GAUSS_POINTS) -> float:
    """integral |covariant acceleration of u = q/|q||^2 dt of the spline through frames [1/s^3].

    Gauss-Legendre with `points` nodes on every spline segment (the integrand is smooth inside a
    segment, so this converges fast: ~1e-10 relative with 8 points on the test sets). Default: twice
    the objective's default order (GAUSS_POINTS), the check of that rule's error.

    Args:
        frame_times: (m,) [s]. frames: (m, 4) quaternions.
    """
    return float(segment_energies(frame_times, frames, points).sum())


def segment_energies(frame_times: np.ndarray, frames: np.ndarray, points: int = 2 * GAUSS_POINTS) -> np.ndarray:
    """`covariant_energy` segment by segment: (m-1,) [1/s^3], Gauss-Legendre with `points` nodes each."""
    ft = np.asarray(frame_times, float)
    t, wt = gauss_times(ft, points)
    Y, Y1, Y2 = interpolate_segments(ft, frames, gauss_nodes(points)[0], (0, 1, 2))
    f = NormalizedCovariantAcceleration(_SINGLE.quat_slots).evaluate(t, Y, Y1, Y2, grad=False).f
    return (wt * f).reshape(len(ft) - 1, points).sum(axis=1)


def max_norm_deviation(frame_times: np.ndarray, frames: np.ndarray) -> float:
    """max |1 - |q(t)|| over the natural cubic spline through frames (m, 4), exactly.

    On a segment q is a cubic in tau in [0, 1], so |q|^2 is a degree-6 polynomial; |1 - |q|| is monotone in
    |q|^2 on either side of 1, so its maximum is at an end or at a real root in [0, 1] of d|q|^2/dtau
    (degree 5, `numpy.roots`; a complex root's real part in [0, 1] is a point of the segment too, so taking every
    root's keeps the true extremes and adds only points on the path). The cubics come from the spline's values
    at four nodes (exact for a cubic).

    Returns:
        the largest deviation [1] (0 for a path of unit quaternions)."""
    nodes = np.linspace(0.0, 1.0, 4)
    q = interpolate_segments(frame_times, frames, nodes).reshape(-1, 4, 4)      # (segment, node, component)
    coefs = np.einsum("ij,sjc->sci", np.linalg.inv(np.vander(nodes, 4)), q)     # (segment, component, 4), highest first
    worst = 0.0
    for seg in coefs:
        r2 = sum(np.polymul(c, c) for c in seg)                                    # |q|^2, degree 6
        roots = np.roots(np.polyder(r2)) if np.any(r2[:-1]) else np.empty(0)
        tau = np.r_[0.0, 1.0, np.clip(roots.real, 0.0, 1.0)]
        worst = max(worst, float(np.abs(1.0 - np.sqrt(np.maximum(np.polyval(r2, tau), 0.0))).max()))
    return worst
