"""`orient(tol=...)`: the orientation's refinement strategy for `solve`'s loop (`GapToOptimum`): optimize
-> estimate the gap -> refine until the estimated relative gap (E - E*)/E*
(`solver.error_estimate.estimate_gap`) is at most the tolerance (docs/orient.md "Accuracy on request: tol and the gap estimate"),
and the measures of an orientation path it uses (covariant energy by Gauss quadrature, max |1 - |q||)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from solver.error_estimate import GAP_FACTOR, estimate_gap, optimization_gap
from solver.frames import FrameSet
from solver.layout import StateLayout
from solver.objective import Objective
from solver.optimize import OptimizeResult, Status
from solver.quadrature import gauss_nodes, gauss_times
from solver.refinement import TOL_FRAMES_PER_INTERVAL, Refinement, Step
from solver.spline import interpolate_segments
from solver.subdivide import predicted_times
from solver.terms import NormalizedCovariantAcceleration

_SINGLE = StateLayout.single_quaternion()  # one orientation: qpos = q (4,)

#: The estimate is a median-calibrated guess (true/estimated 0.4-3.6 on the tuning sets, 90% within
#: 0.7-1.6); a round is accepted when the estimate is at most tol / TOL_SAFETY, so that the true gap is
#: at most tol on all tuning sets (docs/orient.md, "Accuracy on request").
TOL_SAFETY = 2.0

#: With a tolerance, where to put frames (`solver.subdivide.predicted_times`): every segment c is cut so
#: that its share GAP_FACTOR D_c / E of the estimate, assumed to fall as the segment length to the power
#: PREDICT_RATE, brings the estimate to tol / TOL_SAFETY / PREDICT_MARGIN with the fewest frames. The
#: first placement is made before any optimization, from the estimate on the starting path (one frame
#: per keyframe interval, on the unit sphere): its shares put the frames where the optimized path will
#: need them, so one optimization round usually meets the tolerance (rather than several rounds of
#: midpoint frames, each re-optimized and re-estimated). Chosen on tuning seeds 0-49 (docs/orient.md, "Accuracy on
#: request"): rate 4 and margin 2 met tol = 1e-4 in one round on 39 of 50 sets (rate 5: fewer frames but
#: a second round on half the sets; margins 1.5-3 took the same time), the estimate accepted in the first
#: round within 0.59-1.53x of the true gap.
PREDICT_RATE = 4.0
PREDICT_MARGIN = 2.0
#: ... at most this many pieces per segment in one round.
PREDICT_MAX_SPLIT = 8

#: The share of tol the optimizer's own error may take: each round's optimizer stops at ftol_rel =
#: max(the options' ftol_rel, OPTIMIZER_SHARE * tol) (on the tuning seeds 0-49: evaluations to the
#: default tolerance 32 -> 12 in median, to 1e-4 26 -> 19), and a round that would be accepted is
#: checked against the same share: a relative-decrease test can stop L-BFGS on a stall far from the
#: optimum (seen once at 3e-5: true gap 1.6e-3 at an estimate of 1.1e-4), so where `optimization_gap`
#: (the relative decrease a Newton step would still make) is above OPTIMIZER_SHARE * tol the frames are
#: optimized again at the options' own ftol_rel (at most POLISHES times for the same frames and
#: weights), and the check is added to the estimate. On the tuning seeds the check was at most 0.013 x
#: tol on converged rounds (default tolerance); on the stalled round, 0.1 x tol. (The count was once for
#: the whole loop: on acceptance seed 1028 the unit weight, boosted 1000x, left stalls the spent count
#: could not polish.)
OPTIMIZER_SHARE = 0.03
POLISHES = 2

#: With a tolerance: when a round reaches it but the path has max |1 - |q|| above DRIFT_LIMIT, the unit
#: term's weight is multiplied by DRIFT_BOOST and the same frames are optimized again, and refined on if
#: the estimate asks for it (at most DRIFT_BOOSTS times). The normalized form's f2 does not see |q|, so the weight does not move its exact-unit optimum;
#: the light default weight lets |q| drift up to 36% on random sets with few frames.
DRIFT_LIMIT = 0.08
DRIFT_BOOST = 10.0
DRIFT_BOOSTS = 3



class GapToOptimum(Refinement):
    """`solve`'s refinement strategy for `orient`'s tol: rounds of optimize -> estimate -> refine until the
    estimated gap is at most tol / TOL_SAFETY.

    Each round stops the optimizer at ftol_rel OPTIMIZER_SHARE * tol (or the options' if larger). Frames
    are added by `predicted_times` on the predicted decreases the estimate computed: once before the
    first round (`first_frames`, from the estimate on the starting path), then after every round whose
    estimate is above tol / TOL_SAFETY. Where a round would be accepted, the estimate adds the
    quadrature discrepancy and the optimizer's stationarity gap; a stationarity gap above OPTIMIZER_SHARE *
    tol has the same frames optimized again at the options' own ftol_rel ("polish", at most POLISHES
    times per frames and weights), and a path with max |1 - |q|| above DRIFT_LIMIT has the unit term's
    weight (the objective's first) multiplied by DRIFT_BOOST and the same frames optimized again
    ("boost", at most DRIFT_BOOSTS times).

    Args:
        tol: the requested estimated gap (> 0). options: the SolveOptions of the solve (ftol_rel,
            per_round, max_frames: default TOL_FRAMES_PER_INTERVAL per keyframe interval,
            precondition, radial_weight, quat_slots).
    Attributes:
        estimates, converged, final_estimate: `Refinement`'s. boosts: unit-weight boosts made.
        measures: {"frames", "energy", "drift"} of the last round that computed them
            (`covariant_energy`, `max_norm_deviation`), else {}.
    """

    converged = False

    def __init__(self, tol: float, options):
        super().__init__()
        self.tol, self.options = tol, options
        self.boosts, self.measures = 0, {}
        self._polishes, self._strict = 0, False
        self._target = tol / TOL_SAFETY / PREDICT_MARGIN
        self._budget = options.max_frames
        self._per_round = options.per_round

    def first_frames(self, objective, frames):
        """Add frames where the estimate on the starting path asks for them (the optimized path will
        need them there)."""
        if not self._budget:
            self._budget = TOL_FRAMES_PER_INTERVAL * (int(frames.is_keyframe.sum()) - 1)
        E = objective.evaluate(frames.times, frames.values, grad=False).E
        _, D = estimate_gap(objective, frames, E)
        room = min(self._budget - frames.n_variable, self._per_round or self._budget)
        return frames.with_variable_frames(_place(D, E, frames, self._target, room))

    def round_options(self, options):
        ftol = options.ftol_rel if self._strict else max(options.ftol_rel, OPTIMIZER_SHARE * self.tol)
        self._strict = False
        return replace(options, ftol_rel=ftol)

    def after_round(self, objective, frames, result, index, progress):
        ev = objective.evaluate(frames.times, frames.values, grad=False)
        est, D = estimate_gap(objective, frames, ev.E)
        if est <= self.tol / TOL_SAFETY:  # only where it may stop: ~1e-6 usually, and it costs an evaluation
            E8 = covariant_energy(frames.times, frames.values)
            opt = _stationarity(result, ev.E, objective, frames, self.options)
            est += _discrepancy(ev.integrals, E8) + opt
            self.measures = {"frames": frames, "energy": E8, "drift": max_norm_deviation(frames.times, frames.values)}
            if opt > OPTIMIZER_SHARE * self.tol and self._polishes < POLISHES:
                # the optimizer stopped short (a stall on its relative-decrease test): same frames again,
                # at the options' own ftol_rel
                self._record(est)
                self._polishes += 1
                self._strict = True
                return Step("polish")
        self._record(est)
        if est <= self.tol / TOL_SAFETY:
            return self._accept(objective, est)
        room = self._budget - frames.n_variable
        if room <= 0:
            return Step("stop", message=f"frame budget of {self._budget} variable frames reached at estimated gap "
                                        f"{est:.2g} (tol {self.tol:g})")
        new = _place(D, ev.E, frames, self._target, min(room, self._per_round or self._budget))
        if new.size == 0:
            return Step("stop", message=f"no segment to refine at estimated gap {est:.2g} (tol {self.tol:g})")
        self._polishes = 0
        return Step("refine", new)

    def _record(self, est: float) -> None:
        self.estimates.append(est)
        self.final_estimate = est

    def _accept(self, objective, est: float) -> Step:
        """The estimate is within tol: stop, unless |q| drifts (then stiffen the unit term and optimize the
        same frames again; early rounds are not checked: there the drift is mostly the spline's dip
        between frames far apart, ~theta^2/8, which only more frames remove)."""
        if self.boosts < DRIFT_BOOSTS and self.measures["drift"] > DRIFT_LIMIT:
            self.boosts += 1
            objective.weights[0] *= DRIFT_BOOST
            self._polishes = 0  # a new objective: its optimizations may stall afresh
            return Step("boost")
        self.converged = True
        return Step("stop", message=f"estimated gap {est:.2g} <= tol {self.tol:g} / {TOL_SAFETY:g}")

    def final_message(self, status, message):
        if status is Status.MAX_TIME and self.options.max_time_s:
            return f"time limit of {self.options.max_time_s:g} s reached" + (
                f" at estimated gap {self.estimates[-1]:.2g} (tol {self.tol:g})" if self.estimates else "")
        return message


def _stationarity(result: OptimizeResult, E: float, obj: Objective, frames: FrameSet, opts) -> float:
    """`optimization_gap` of the round's result, 0.5 |g_z|^2 / E: from the gradient in z the optimizer
    evaluated at its best iterate (`OptimizeResult.grad`), or, where there is none in z (no
    preconditioner, or the plain-variable retry of `solver.backend.nlopt_backend`), by
    `optimization_gap`. The optimizer's z stretches the radial directions of the frames at the round's
    *start* (`radial_weight`), where `optimization_gap` takes them at its end; the frames turn little in
    a round, and this saves an evaluation with a gradient and a preconditioner (~5% of a tol=1e-4 call)."""
    g = result.grad
    if opts.precondition and g is not None and g.size == frames.n_free:
        return float(0.5 * (g @ g) / E) if E > 0 else 0.0
    return optimization_gap(obj, frames, opts.radial_weight, opts.quat_slots)


def _place(D: np.ndarray, E: float, frames: FrameSet, target: float, budget: int) -> np.ndarray:
    """New frame times for the estimate's shares GAP_FACTOR D / E to reach `target` (`predicted_times`)."""
    if not E > 0:
        return np.zeros(0)
    return predicted_times(GAP_FACTOR * D / E, frames, target, budget, PREDICT_RATE, PREDICT_MAX_SPLIT)


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


def covariant_energy(frame_times: np.ndarray, frames: np.ndarray, points: int = 8) -> float:
    """integral |covariant acceleration of u = q/|q||^2 dt of the spline through frames [1/s^3].

    Gauss-Legendre with `points` nodes on every spline segment (the integrand is smooth inside a
    segment, so this converges fast: ~1e-10 relative with 8 points on the test sets).

    Args:
        frame_times: (m,) [s]. frames: (m, 4) quaternions.
    """
    ft = np.asarray(frame_times, float)
    t, wt = gauss_times(ft, points)
    Y, Y1, Y2 = interpolate_segments(ft, frames, gauss_nodes(points)[0], (0, 1, 2))
    f = NormalizedCovariantAcceleration(_SINGLE.quat_slots).evaluate(t, Y, Y1, Y2, grad=False).f
    return float(wt @ f)


def max_norm_deviation(frame_times: np.ndarray, frames: np.ndarray, per_segment: int = 64) -> float:
    """max |1 - |q(t)|| over the spline through frames (`per_segment` samples per segment, ends included:
    64, a sample every 1.6 % of a segment, where |q(t)| of a cubic varies smoothly; it is compared with
    DRIFT_LIMIT, 8 %, so locating its peak to a fraction of a percent is enough)."""
    q = interpolate_segments(frame_times, frames, np.arange(per_segment) / per_segment)
    r2 = np.einsum("ni,ni->n", q, q)  # |q|^2; the last frame is the path's end
    last = np.asarray(frames, float)[-1]
    return float(max(np.abs(1.0 - np.sqrt(r2)).max(), abs(1.0 - np.sqrt(last @ last))))
