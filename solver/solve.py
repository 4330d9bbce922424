"""The algorithm of the paper's figure 5, end to end: frames -> optimize -> subdivide -> optimize ...

1. the plain spline through the keyframes (partial keyframes' free components filled);
2. optional renormalization of the terms on it (eq. 7);
3. variable frames: where a term's integrand changes character (a contact's touch-down and lift-off,
   `Objective.knot_times`), then none, n per segment (global) or where the weak-form Euler-Lagrange
   score is largest (adaptive), valued on the current path;
4. nlopt moves the free components; keyframes hold exactly at every iterate;
5. repeat 3-4 until the frame budget, the round limit or the time limit; or, with a tolerance
   (`SolveOptions.tol`), until the decrease of E that refinement still predicts, relative to E
   (`refinement_estimate`), is at most tol.
"""
from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from solver.errors import InputError
from solver.frames import FrameSet
from solver.metrics import sample_times
from solver.objective import NonFiniteError, Objective
from solver.optimize import ALGORITHMS, OptimizeResult, Status
from solver.round import optimize_round
from solver.subdivide import adaptive_times, global_times, knot_hint_times, predicted_decreases, weak_form_scores

SUBDIVISIONS = ("none", "global", "adaptive")
STALL_FRACTION = 0.5  # penalty continuation: a boost must at least halve a violation (`SolveOptions.limits`)
LIMIT_CHECK_RATE = 4000.0  # [1/s] samples per second at which `limits` are checked
SCORES = ("gradient", "decrease")
#: With a tolerance and no `max_frames`: the frame budget, per keyframe interval.
TOL_FRAMES_PER_INTERVAL = 10
#: [s] `SolveOptions.term_knots`: a hinted frame closer than this to another frame is left out (30 ms:
#: under four frames at motion capture's 120 Hz; contact times are only that accurate).
KNOT_MIN_GAP = 0.03


def refinement_estimate(objective: Objective, frames: FrameSet, E: float | None = None) -> tuple[float, np.ndarray]:
    """The decrease of E still available from refinement, relative to E: sum_c D_c / E, with D_c the
    predicted decrease from a frame inserted at the midpoint of segment c and moved to its best place
    (`predicted_decreases`, what adaptive subdivision ranks segments by). A first-order prediction of
    what halving every segment would buy (each frame moved alone, the others held); 0 where the path
    is optimal for its frames and no frame could lower E.

    Returns:
        (estimate, D): D (m-1,) the predicted decreases [units of E].
    """
    D = predicted_decreases(objective, frames)
    if E is None:
        E = objective.evaluate(frames.times, frames.values, grad=False).E
    return (float(D.sum() / E) if E > 0 else 0.0), D


@dataclass(frozen=True)
class SolveOptions:
    """How to optimize.

    Attributes:
        subdivision: "none" (only the frames given), "global" (`per_segment` frames in every segment,
            once) or "adaptive" (rounds of weak-form Euler-Lagrange subdivision).
        term_knots: with "global" or "adaptive", first place variable frames where a term says its
            integrand changes character (`Objective.knot_times`: the contacts' touch-downs and
            lift-offs), at least KNOT_MIN_GAP from other frames; `per_segment` then splits every
            segment of that set. Without contact terms there are none. On run-and-step with its
            contacts (penetration weight 1) this took the solve from 1633 to 485 evaluations (README
            "Feet that plant").
        per_segment: variable frames per segment (of the keyframes and the term knots) for "global",
            and to start "adaptive" with.
        rounds: adaptive rounds (each adds frames, then re-optimizes).
        per_round: at most this many frames per adaptive round (0 = one per segment).
        max_frames: cap on variable frames in total (0 = none).
        renormalize: divide each term by its value on the plain spline (eq. 7).
        algorithm, ftol_rel, max_evals (per round), max_time_s (whole solve): optimizer settings.
        score: what ranks segments for adaptive subdivision: "gradient" (|dE/dP| of a midpoint frame,
            `weak_form_scores`) or "decrease" (the decrease of E that frame predicts,
            `predicted_decreases`; does not favour short segments).
        precondition: optimize in the variables z = R (x - x0), R^T R = the Hessian of
            integral |Y''|^2 dt over the free components (an upper Cholesky factor from W2, once per
            round): for acceleration-dominated objectives this removes most of the ill-conditioning
            of frame values (the Hessian of a spline's bending energy grows like 1/h^3) and L-BFGS
            needs 2-3x fewer evaluations. Iterates and results are the same kind of path.
        radial_weight, quat_slots: with `precondition`, the curvature the preconditioner assumes along
            the radial direction of each quaternion (qpos indices `quat_slots`, (s, 4)) of a free frame,
            relative to the other directions (1: all alike). An objective that depends on q/|q| (the
            normalized covariant acceleration) has little radial curvature (its unit term's): there
            0.1 saves 25-40% of the evaluations on the orientation test sets (`solver.orient`,
            docs/orient.md). "auto": from the curvatures the objective's terms declare, on the slots
            the unit term acts on (`solver.precondition.auto_radial_weight`; `quat_slots` unused):
            the figure's default (`default_options`), where the unit term makes the radial directions
            stiff (about 20x the acceleration metric) and a weight of 1 leaves L-BFGS with a
            condition number of ~1e4 and an evaluation count that grows with the clip's length.
        tol: with adaptive subdivision, > 0: rounds until the decrease of E refinement still predicts,
            relative to E (`refinement_estimate`, after each round's optimization and penalty
            continuation), is at most tol, instead of a fixed number of `rounds`; or until `max_frames`
            (default TOL_FRAMES_PER_INTERVAL per keyframe interval) or `max_time_s` runs out
            (`Solution.converged_to_tol` False, the message says which and gives the estimate).
            0: `rounds` rounds.
        limits: ((term name, tolerance), ...): penalty continuation. After a round, a term whose
            `violation` on the path (sampled at LIMIT_CHECK_RATE, in the term's own units, e.g. metres of
            penetration) exceeds its tolerance has its weight multiplied by `boost` and the round is
            optimized again, at most `max_boosts` times in a solve: the quadratic-penalty method's
            schedule (Nocedal & Wright, Numerical Optimization, sec. 17.1), which drives a soft
            constraint's violation to a stated bound without a constrained optimizer. A quadratic
            penalty's violation falls about as 1/weight; a term whose violation a boost did not cut
            below STALL_FRACTION of what it was is not boosted again (the keyframes make the bound
            unreachable there: 127_33 keyed every 0.33 s took four boosts and 1550 evaluations while
            its clearance violation grew from 68 to 112 mm); `Solution.stalled` lists them.
    """

    subdivision: str = "adaptive"
    term_knots: bool = True
    per_segment: int = 1
    rounds: int = 2
    per_round: int = 0
    max_frames: int = 0
    renormalize: bool = True
    algorithm: str = "lbfgs"
    ftol_rel: float = 1e-7
    max_evals: int = 0
    max_time_s: float = 0.0
    score: str = "decrease"
    precondition: bool = False
    radial_weight: float | str = 1.0
    quat_slots: tuple = ()
    limits: tuple = ()
    boost: float = 10.0
    max_boosts: int = 4
    tol: float = 0.0

    def __post_init__(self):
        if self.subdivision not in SUBDIVISIONS:
            raise InputError(f"unknown subdivision {self.subdivision!r}; choose one of: {', '.join(SUBDIVISIONS)}")
        if self.score not in SCORES:
            raise InputError(f"unknown subdivision score {self.score!r}; choose one of: {', '.join(SCORES)}")
        for name in ("per_segment", "rounds", "per_round", "max_frames", "max_evals", "max_boosts"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 0:
                raise InputError(f"{name} must be a whole number >= 0, got {v!r}")
        if self.algorithm not in ALGORITHMS:
            raise InputError(f"unknown algorithm {self.algorithm!r}; choose one of: {', '.join(ALGORITHMS)}")
        if not self.ftol_rel >= 0:
            raise InputError(f"ftol_rel must be >= 0, got {self.ftol_rel}")
        if self.radial_weight != "auto" and not (isinstance(self.radial_weight, (int, float, np.number))
                                                 and self.radial_weight > 0):
            raise InputError(f"radial_weight must be a number > 0 or 'auto', got {self.radial_weight!r}")
        if any(len(slot) != 4 for slot in self.quat_slots):
            raise InputError(f"quat_slots must be groups of 4 qpos indices, got {self.quat_slots!r}")
        if not self.boost >= 1:
            raise InputError(f"boost must be >= 1, got {self.boost}")
        for lim in self.limits:
            if len(lim) != 2 or not lim[1] >= 0:
                raise InputError(f"limits must be (term name, tolerance >= 0) pairs, got {lim!r}")
        if not self.max_time_s >= 0:
            raise InputError(f"max_time_s must be >= 0, got {self.max_time_s}")
        if not (self.tol >= 0 and np.isfinite(self.tol)):
            raise InputError(f"tol must be a number >= 0, got {self.tol!r}")


@dataclass(frozen=True)
class Round:
    """One optimization round: the frames it started with and the optimizer's result (read-only).

    Attributes:
        n_frames, n_variable: frames the round optimized, and how many of them are variable frames.
        result: the optimizer's OptimizeResult.
        scores: (n_frames_before - 1,) the subdivision scores (`SolveOptions.score`) that chose this
            round's new frames, on the previous round's segments; None for the first round and after a
            penalty boost.
        times: (n_frames,) the frame times this round optimized [s].
    """

    n_frames: int
    n_variable: int
    result: OptimizeResult
    scores: np.ndarray | None = None
    times: np.ndarray | None = None


@dataclass(frozen=True)
class Solution:
    """The result of `solve` (read-only: a frozen dataclass whose arrays are not writeable).

    Attributes:
        frames: optimized FrameSet (the path is the natural cubic spline through it), (m, nq) values.
        initial: the plain spline's FrameSet (a read-only copy of `solve`'s `initial`).
        rounds: (Round, ...) per-round results.
        status: Status of the last round (INTERRUPTED etc. end the solve early).
        message: why it ended.
        E_initial, E_final: objective on the plain spline and on the result, both under the final
            weights (penalty continuation raises some) and the renormalization scales.
        integrals_initial, integrals_final: {term: integral of f_j dt} on each (unweighted).
        scales: {term: renormalization divisor} (eq. 7; 1 without renormalization).
        trace: (N,) best objective after each evaluation, all rounds concatenated.
        wall_time_s: [s], optimization and subdivision (excludes building the terms).
        n_evals: objective evaluations in all rounds.
        weights: {term: lambda_j} at the end: the objective's weights after penalty continuation
            (`SolveOptions.limits`); the caller's Objective keeps its own.
        objective: the working copy of the objective the last round optimized (final weights and
            scales, terms prepared on the result): for scores or evaluations on the result under the
            objective that produced it. `solve` never changes the caller's Objective.
        refinement_estimates: with adaptive subdivision, `refinement_estimate` after each round that
            computed it (every round but the last without a tolerance; every round with one).
        converged_to_tol: with a tolerance, whether the estimate reached it; None without one.
        stalled: {term: violation} of the terms penalty continuation gave up on (a boost did not halve
            the violation; `SolveOptions.limits`), in the term's `violation` units.
    """

    frames: FrameSet
    initial: FrameSet
    rounds: tuple[Round, ...]
    status: Status
    message: str
    E_initial: float
    E_final: float
    integrals_initial: dict
    integrals_final: dict
    scales: dict
    trace: np.ndarray
    wall_time_s: float
    n_evals: int = field(default=0)
    weights: dict = field(default_factory=dict)
    objective: Objective | None = field(default=None, repr=False, compare=False)
    refinement_estimates: tuple = ()
    converged_to_tol: bool | None = None
    final_estimate: float = float("nan")
    stalled: dict = field(default_factory=dict)

    @cached_property
    def refinement_estimate(self) -> float:
        """`refinement_estimate` of the result (relative to E_final): the last round's with a
        tolerance, else computed when first read (three gradient evaluations with a frame in every
        segment); NaN without the objective."""
        if np.isfinite(self.final_estimate):
            return self.final_estimate
        if self.objective is None:
            return float("nan")
        return refinement_estimate(self.objective, self.frames, self.E_final)[0]


def solve(
    objective: Objective,
    initial: FrameSet,
    options: SolveOptions = SolveOptions(),
    *,
    should_stop: Callable[[], bool] | None = None,
    progress: Callable[[str, dict], None] | None = None,
    project: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Solution:
    """Optimize the variable frames (and partial keyframes' free components) of a frame set.

    Args:
        objective: the weighted terms on the keyframe interval.
        initial: the plain spline's frames (`FrameSet.from_keyframes`); may already hold variable frames.
        options: SolveOptions.
        should_stop: polled during optimization (Ctrl-C handler); True ends the solve, keeping the
            best path so far (it meets every keyframe).
        progress: progress(event, info) for "round" (start of a round), "eval" (each evaluation),
            "boost" ({"terms": {name: violation}, "boosts": n}), "stalled" ({"terms": {name:
            violation}}: not boosted again) and "estimate" (after a round: the refinement estimate).
        project: maps the values (r, nq) of the variable frames placed on the plain spline before the
            first round (`per_segment`) to the values to start from (e.g. `solver.orient` puts the
            quaternions back on the unit sphere); frames inserted by adaptive rounds keep the path's
            values (the path is then unchanged by the insertion).
    Returns:
        Solution.
    Raises:
        InputError: `initial` is not a FrameSet or `options` not SolveOptions; the objective's interval
            is not the frames' [first, last] time; the objective cannot be evaluated on the frames
            (their nq does not fit the objective's model).
        NonFiniteError: the objective is NaN or infinite on the initial path (nothing to keep).

    `objective` is not changed: renormalization (eq. 7) and penalty continuation act on a copy
    (`Solution.objective`), so solving twice with the same inputs gives the same result. The copy
    shares the terms, whose per-round state (`Term.prepare`) `solve` sets afresh from `initial`.
    """
    objective = _working_copy(objective)
    ev_check = _check_inputs(objective, initial, options)
    t_start = time.perf_counter()
    objective.prepare(initial.times, initial.values)  # terms' per-round state from the plain spline
    if options.renormalize:
        scales = objective.renormalize(initial.times, initial.values)
    else:
        scales = dict(zip(objective.names, objective.scales.tolist()))
    if options.renormalize or objective.keeps_state:
        ev0 = objective.evaluate(initial.times, initial.values, grad=False)
    else:  # nothing changed the objective since the input check evaluated it on the same frames
        ev0 = ev_check
    frames = initial
    if options.subdivision in ("global", "adaptive") and options.term_knots:
        # frames where a term's integrand changes character (contacts' touch-down and lift-off),
        # valued on the plain spline (the path is unchanged), before the per-segment frames
        frames = frames.with_variable_frames(knot_hint_times(frames, objective.knot_times(), KNOT_MIN_GAP))
    if options.subdivision in ("global", "adaptive") and options.per_segment > 0:
        new = global_times(frames, options.per_segment)
        if options.max_frames:
            new = new[: max(0, options.max_frames - frames.n_variable)] if options.subdivision == "global" else new
        frames = frames.with_variable_frames(new)
        if project is not None and new.size:
            var = np.zeros(frames.count, bool)
            var[np.searchsorted(frames.times, new)] = True  # the new times are among the frames' times
            vals = frames.values.copy()
            vals[var] = project(vals[var])
            frames = replace(frames, values=vals)
    n_rounds = 1 + (options.rounds if options.subdivision == "adaptive" else 0)
    tol = options.tol if options.subdivision == "adaptive" else 0.0
    if tol and not options.max_frames:
        options = replace(options, max_frames=TOL_FRAMES_PER_INTERVAL * (int(initial.is_keyframe.sum()) - 1))
    estimates: list[float] = []
    final_estimate, converged = float("nan"), False
    rounds: list[Round] = []
    traces: list[np.ndarray] = []
    status, message = Status.CONVERGED, "converged"
    n_evals = 0
    boosts = 0
    last_over: dict[str, float] = {}  # the violations that made the last boost
    stalled: dict[str, float] = {}  # terms whose violation a boost did not halve: not boosted again
    reported: set[str] = set()
    r = 0
    scores = None
    while True:
        if should_stop is not None and should_stop():  # e.g. Ctrl-C during subdivision
            status, message = Status.INTERRUPTED, "stopped on request"
            break
        remaining = 0.0
        if options.max_time_s:
            remaining = options.max_time_s - (time.perf_counter() - t_start)
            if remaining <= 0:
                status, message = Status.MAX_TIME, f"time limit of {options.max_time_s:g} s reached"
                break
        if progress:
            progress("round", {"round": len(rounds), "frames": frames.count, "variable": frames.n_variable})
        result = optimize_round(objective, frames, options, remaining, should_stop, progress, n_evals)
        if result.status is Status.FAILED and options.precondition:
            # nlopt's generic failure (a line search that found no decrease) was seen with the
            # preconditioner on extreme inputs (a root inside the floor); the plain variables recover
            plain = replace(options, precondition=False)
            retry = optimize_round(objective, frames.with_x(result.x), plain, remaining, should_stop, progress,
                              n_evals + result.n_evals)
            result = replace(retry, n_evals=result.n_evals + retry.n_evals, grad=None,  # not in z
                             trace=np.concatenate([result.trace, retry.trace]),
                             wall_time_s=result.wall_time_s + retry.wall_time_s,
                             fun_time_s=result.fun_time_s + retry.fun_time_s)
        frames = frames.with_x(result.x)
        objective.prepare(frames.times, frames.values)  # for the next round, the scores, the report
        for arr in (result.x, result.trace, scores):
            _read_only(arr)
        rounds.append(Round(frames.count, frames.n_variable, result, scores, _read_only(frames.times.copy())))
        traces.append(result.trace)
        n_evals += result.n_evals
        status, message = result.status, result.message
        if status is Status.MAX_TIME:  # the round had what was left; report the whole solve's limit
            message = f"time limit of {options.max_time_s:g} s reached"
        if status in (Status.INTERRUPTED, Status.MAX_TIME, Status.NONFINITE, Status.FAILED):
            break
        over = _over_limits(objective, frames, options.limits) if boosts < options.max_boosts else {}
        for name in [n for n in over if n in last_over and over[n] > STALL_FRACTION * last_over[n]]:
            stalled[name] = over[name]  # a boost that did not halve it: the bound is out of reach here
        if stalled and progress and set(stalled) - reported:
            progress("stalled", {"terms": {n: stalled[n] for n in set(stalled) - reported}})
            reported |= set(stalled)
        over = {n: v for n, v in over.items() if n not in stalled}
        if over:  # penalty continuation: stiffen the violated terms, optimize the same frames again
            boosts += 1
            last_over = over
            for name in over:
                objective.weights[objective.names.index(name)] *= options.boost
            if progress:
                progress("boost", {"terms": over, "boosts": boosts})
            scores = None
            continue
        last_over = {}
        r += 1
        if r >= n_rounds and not tol:
            break
        budget = options.per_round or (frames.count - 1)
        if options.max_frames:
            budget = min(budget, options.max_frames - frames.n_variable)
        if budget <= 0 and not tol:
            break
        try:
            if options.score == "decrease" or tol:  # the ranking and the estimate: free with "decrease"
                est, D = refinement_estimate(objective, frames, result.fun)
                estimates.append(est)
                if progress:
                    progress("estimate", {"round": len(rounds) - 1, "estimate": est, "tol": tol})
            if tol:
                final_estimate = est
                if est <= tol:
                    converged, message = True, f"refinement estimate {est:.2g} <= tol {tol:g}"
                    break
                if budget <= 0:
                    message = (f"frame budget of {options.max_frames} variable frames reached at refinement "
                               f"estimate {est:.2g} (tol {tol:g})")
                    break
            scores = D if options.score == "decrease" else weak_form_scores(objective, frames)
        except NonFiniteError as e:  # keep the optimized frames; say which term failed
            status, message = Status.NONFINITE, f"{e} while choosing new frames"
            break
        new = adaptive_times(scores, frames, budget)
        if new.size == 0:
            if tol:
                message = f"no segment to refine at refinement estimate {est:.2g} (tol {tol:g})"
            break
        frames = frames.with_variable_frames(new)
    if tol and status is Status.MAX_TIME and estimates:
        message += f" at refinement estimate {estimates[-1]:.2g} (tol {tol:g})"
    ev1 = objective.evaluate(frames.times, frames.values, grad=False)
    if boosts:  # report both ends under the final weights, so E_initial and E_final compare
        ev0 = objective.evaluate(initial.times, initial.values, grad=False)
    return Solution(
        _read_only_frames(frames), _read_only_frames(initial), tuple(rounds), status, message, ev0.E, ev1.E,
        ev0.integrals, ev1.integrals, scales, _read_only(np.concatenate(traces) if traces else np.array([ev0.E])),
        time.perf_counter() - t_start, n_evals, dict(zip(objective.names, objective.weights.tolist())), objective,
        tuple(estimates), converged if tol else None, final_estimate, dict(stalled),
    )


def _working_copy(objective):
    """A copy of `objective` with its own weights and scales (what `solve` changes); the terms and the
    spline-matrix cache are shared. Anything but an Objective is returned as is (`_check_inputs` says)."""
    if not isinstance(objective, Objective):
        return objective
    work = copy.copy(objective)
    work.weights = objective.weights.copy()
    work.scales = objective.scales.copy()
    return work


def _read_only(a):
    """`a` (an array this module made) marked not writeable; None stays None."""
    if a is not None:
        a.flags.writeable = False
    return a


def _read_only_frames(frames: FrameSet) -> FrameSet:
    """A FrameSet of read-only copies of `frames`' arrays (they may be shared with the caller's)."""
    return FrameSet(*(_read_only(np.array(a)) for a in (frames.times, frames.values, frames.fixed, frames.is_keyframe)))


def _check_inputs(objective, initial, options):
    """Raise InputError for inputs `solve` cannot use; returns the objective evaluated (no gradient) on
    the initial frames."""
    if not isinstance(initial, FrameSet):
        hint = " (make one with FrameSet.from_keyframes(keyframes, layout.quat_slots))" if hasattr(
            initial, "mask") else ""
        raise InputError(f"initial must be a FrameSet, got {type(initial).__name__}{hint}")
    if not isinstance(options, SolveOptions):
        raise InputError(f"options must be a SolveOptions, got {type(options).__name__}")
    if not isinstance(objective, Objective):
        raise InputError(f"objective must be an Objective (e.g. from figure_objective), got {type(objective).__name__}")
    t0, t1 = float(initial.times[0]), float(initial.times[-1])
    if abs(objective.t0 - t0) > 1e-9 * max(1.0, abs(t0)) or abs(objective.t1 - t1) > 1e-9 * max(1.0, abs(t1)):
        raise InputError(
            f"the objective integrates over [{objective.t0:g}, {objective.t1:g}] s but the frames span "
            f"[{t0:g}, {t1:g}] s; build the objective with keyframes.times[0] and keyframes.times[-1]")
    try:
        return objective.evaluate(initial.times, initial.values, grad=False)
    except (ValueError, IndexError) as e:
        raise InputError(
            f"the objective cannot be evaluated on frames of shape {initial.values.shape} ({e}); are the "
            "keyframes for the model the objective was built from (same nq)?") from None


def _over_limits(objective: Objective, frames: FrameSet, limits) -> dict[str, float]:
    """{term name: violation} for the terms whose violation on the path exceeds their limit."""
    if not limits:
        return {}
    # Dense: a swing foot moves ~6 mm per ms, so a graze of a box edge can last about a millisecond;
    # a check at the 1000 Hz of the acceptance figures would see it or not depending on phase.
    Y = frames.path(sample_times(frames.times[0], frames.times[-1], LIMIT_CHECK_RATE))
    over = {}
    for name, tol in limits:
        if name not in objective.names:
            continue
        term = objective.terms[objective.names.index(name)]
        v = term.violation(Y)
        if v is not None and v > tol and objective.weights[objective.names.index(name)] > 0:
            over[name] = float(v)
    return over
