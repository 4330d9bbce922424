"""The algorithm of the paper's figure 5, end to end: frames -> optimize -> subdivide -> optimize ...

`solve` composes three units:

1. the starting frames: the plain spline through the keyframes (partial keyframes' free components
   filled), optionally renormalized on (eq. 7), plus `per_segment` frames per segment for "global" and
   "adaptive" subdivision, valued on the current path;
2. the optimizer back end (`solver.paper.backend`): one round moves the free components, keyframes hold
   exactly at every iterate;
3. the refinement strategy (`solver.paper.refinement`): after each accepted round, stop or add frames where
   the weak-form Euler-Lagrange score is largest (fixed rounds, or until a tolerance on the decrease
   refinement still predicts; `solver.paper.orient_refine.GapToOptimum` for the orientation's gap).
"""
from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from solver.errors import InputError
from solver.frames import FrameSet
from solver.objective import NonFiniteError, Objective
from solver.optimize import ALGORITHMS, FTOL_REL, OptimizeResult, Status
from solver.paper.backend import Backend, nlopt_backend
from solver.paper.refinement import (  # noqa: F401 (TOL_FRAMES_PER_INTERVAL, refinement_estimate re-exported)
    TOL_FRAMES_PER_INTERVAL,
    FixedRounds,
    NoRefinement,
    Refinement,
    ToTolerance,
    refinement_estimate,
)
from solver.solution import ROUND_KINDS, Round, Solution, round_summary  # noqa: F401 (re-exported)
from solver.subdivide import global_times

SUBDIVISIONS = ("none", "global", "adaptive")
SCORES = ("gradient", "decrease")
#: `SolveOptions.refine`: how adaptive subdivision decides when to stop.
REFINES = ("rounds", "tol")
#: [rounds] `SolveOptions.rounds` when not given (refine "rounds"): two adaptive rounds after the first
#: optimization; for an accuracy, refine "tol" stops on an estimate instead of a count.
DEFAULT_ROUNDS = 2
_ENDS = (Status.INTERRUPTED, Status.MAX_TIME, Status.NONFINITE, Status.FAILED)  # statuses that end a solve


@dataclass(frozen=True)
class SolveOptions:
    """How to optimize.

    Attributes:
        subdivision: "none" (only the frames given), "global" (`per_segment` frames in every segment,
            once) or "adaptive" (rounds of weak-form Euler-Lagrange subdivision).
        per_segment: variable frames per segment (of the keyframes) for "global",
            and to start "adaptive" with.
        refine: how adaptive subdivision stops (with "none" and "global" it is not used):
            "rounds" (default): after `rounds` rounds that add frames; "tol": when the decrease of E
            refinement still predicts, relative to E (`refinement_estimate`, after each round's
            optimization), is at most `tol`, or `max_frames` (default
            TOL_FRAMES_PER_INTERVAL per keyframe interval) or `max_time_s` runs out
            (`Solution.converged_to_tol` False, the message says which and gives the estimate).
        rounds: with refine "rounds", the adaptive rounds after the first (each adds frames, then
            re-optimizes); None: DEFAULT_ROUNDS. Giving it with refine "tol" is an InputError.
        per_round: at most this many frames per adaptive round (0 = one per segment).
        max_frames: cap on variable frames in total (0 = none).
        renormalize: divide each term by its value on the plain spline (eq. 7).
        algorithm, ftol_rel, max_evals (per round), max_time_s (whole solve): the nlopt optimizer's
            settings (each round in the preconditioned variables, `solver.paper.backend.nlopt_backend`).
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
            0.1 saves 25-40% of the evaluations on the orientation test sets (`solver.paper.orient`,
            docs/orient.md "Defaults, and what they deliver"). "auto": from the curvatures the objective's terms declare, on the slots
            the unit term acts on (`solver.paper.precondition.auto_radial_weight`; `quat_slots` unused):
            the default for an objective whose unit term makes the radial directions stiff (about
            20x the acceleration metric), where a weight of 1 leaves L-BFGS with a
            condition number of ~1e4 and an evaluation count that grows with the clip's length.
        tol: with refine "tol", the tolerance (> 0). With refine "rounds" it must be 0 (not given): an
            InputError otherwise, since it would be ignored.
    Rounds: every optimization is a `Round` of `Solution.rounds`, with a `kind`: "start" (the first),
    "refine" (after adding frames), "boost" and "polish" (the same frames again under a raised weight or
    at a stricter stopping test: the orientation's gap strategy); `Solution.round_summary` counts them.
    Raises (on construction):
        InputError: a field out of range or unknown; refine "tol" without tol > 0; tol > 0 with
            refine "rounds"; rounds given with refine "tol".
    """

    subdivision: str = "adaptive"
    per_segment: int = 1
    rounds: int | None = None
    per_round: int = 0
    max_frames: int = 0
    renormalize: bool = True
    algorithm: str = "lbfgs"
    ftol_rel: float = FTOL_REL
    max_evals: int = 0
    max_time_s: float = 0.0
    score: str = "decrease"
    precondition: bool = False
    radial_weight: float | str = 1.0
    quat_slots: tuple = ()
    tol: float = 0.0
    refine: str = "rounds"

    def __post_init__(self):
        if self.subdivision not in SUBDIVISIONS:
            raise InputError(f"unknown subdivision {self.subdivision!r}; choose one of: {', '.join(SUBDIVISIONS)}")
        if self.score not in SCORES:
            raise InputError(f"unknown subdivision score {self.score!r}; choose one of: {', '.join(SCORES)}")
        if self.rounds is not None:
            _whole("rounds", self.rounds)
        for name in ("per_segment", "per_round", "max_frames", "max_evals"):
            _whole(name, getattr(self, name))
        if self.algorithm not in ALGORITHMS:
            raise InputError(f"unknown algorithm {self.algorithm!r}; choose one of: {', '.join(ALGORITHMS)}")
        if not self.ftol_rel >= 0:
            raise InputError(f"ftol_rel must be >= 0, got {self.ftol_rel}")
        if self.radial_weight != "auto" and not (isinstance(self.radial_weight, (int, float, np.number))
                                                 and self.radial_weight > 0):
            raise InputError(f"radial_weight must be a number > 0 or 'auto', got {self.radial_weight!r}")
        if any(len(slot) != 4 for slot in self.quat_slots):
            raise InputError(f"quat_slots must be groups of 4 qpos indices, got {self.quat_slots!r}")
        if not self.max_time_s >= 0:
            raise InputError(f"max_time_s must be >= 0, got {self.max_time_s}")
        if not (self.tol >= 0 and np.isfinite(self.tol)):
            raise InputError(f"tol must be a number >= 0, got {self.tol!r}")
        self._check_refine()

    def _check_refine(self):
        """The refinement mode and its parameters agree (class docstring, `refine`)."""
        if self.refine not in REFINES:
            raise InputError(f"unknown refine {self.refine!r}; choose one of: {', '.join(REFINES)}")
        if self.refine == "tol" and not self.tol > 0:
            raise InputError(f"refine='tol' needs a tolerance tol > 0, got tol={self.tol!r}; give one (e.g. 1e-2) "
                             "or refine='rounds'")
        if self.refine == "tol" and self.rounds is not None:
            raise InputError(f"rounds={self.rounds} is the parameter of refine='rounds'; with refine='tol' the "
                             "tolerance decides the rounds: leave rounds out (None) or give refine='rounds'")
        if self.refine == "rounds" and self.tol:
            raise InputError(f"tol={self.tol:g} is the parameter of refine='tol'; with refine='rounds' it would "
                             "be ignored: give refine='tol' or leave tol at 0")

    @property
    def n_rounds(self) -> int:
        """The adaptive rounds of refine "rounds": `rounds`, or DEFAULT_ROUNDS when not given."""
        return DEFAULT_ROUNDS if self.rounds is None else int(self.rounds)


def _whole(name, v):
    """InputError unless v is a whole number >= 0 (field `name` of SolveOptions)."""
    if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 0:
        raise InputError(f"{name} must be a whole number >= 0, got {v!r}")


def solve(
    objective: Objective,
    initial: FrameSet,
    options: SolveOptions = SolveOptions(),
    *,
    should_stop: Callable[[], bool] | None = None,
    progress: Callable[[str, dict], None] | None = None,
    project: Callable[[np.ndarray], np.ndarray] | None = None,
    refinement: Refinement | None = None,
    backend: Backend | None = None,
) -> Solution:
    """Optimize the variable frames (and partial keyframes' free components) of a frame set.

    Args:
        objective: the weighted terms on the keyframe interval.
        initial: the plain spline's frames (`FrameSet.from_keyframes`); may already hold variable frames.
        options: SolveOptions.
        should_stop: polled during optimization (Ctrl-C handler); True ends the solve, keeping the
            best path so far (it meets every keyframe).
        progress: progress(event, info) for "round" (start of a round: {"round", "frames", "variable",
            "kind"}, `Round.kind`), "eval" (each evaluation) and "estimate" (after a round: the refinement
            estimate).
        project: maps the values (r, nq) of the variable frames placed on the plain spline before the
            first round (`per_segment`) to the values to start from (e.g. `solver.paper.orient` puts the
            quaternions back on the unit sphere); frames inserted by adaptive rounds keep the path's
            values (the path is then unchanged by the insertion).
        refinement: the refinement strategy (a fresh `solver.paper.refinement.Refinement`, e.g.
            `solver.paper.orient_refine.GapToOptimum`); default from `options` (`default_refinement`).
        backend: the optimizer of one round (`solver.paper.backend.Backend`); default nlopt
            (`solver.paper.backend.nlopt_backend`).
    Returns:
        Solution.
    Raises:
        InputError: `initial` is not a FrameSet or `options` not SolveOptions; the objective's interval
            is not the frames' [first, last] time; the objective cannot be evaluated on the frames
            (their nq does not fit the objective's model).
        NonFiniteError: the objective is NaN or infinite on the initial path (nothing to keep).

    `objective` is not changed: renormalization (eq. 7) acts on a copy
    (`Solution.objective`), so solving twice with the same inputs gives the same result. The copy
    shares the terms, whose per-round state (`Term.prepare`) `solve` sets afresh from `initial`.
    """
    objective = _working_copy(objective)
    ev_check = _check_inputs(objective, initial, options)
    if backend is None:
        backend = nlopt_backend
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
    strategy = default_refinement(options) if refinement is None else refinement
    frames = strategy.first_frames(objective, starting_frames(objective, initial, options, project))
    log = _rounds(objective, frames, options, strategy, backend, t_start, should_stop, progress)
    message = strategy.final_message(log.status, log.message)
    if any(r.kind in ("boost", "polish") for r in log.rounds):
        message += f" ({round_summary(log.rounds)})"
    ev1 = objective.evaluate(log.frames.times, log.frames.values, grad=False)
    return Solution(
        _read_only_frames(log.frames), _read_only_frames(initial), tuple(log.rounds), log.status, message, ev0.E,
        ev1.E, ev0.integrals, ev1.integrals, scales,
        _read_only(np.concatenate(log.traces) if log.traces else np.array([ev0.E])),
        time.perf_counter() - t_start, log.n_evals, dict(zip(objective.names, objective.weights.tolist())),
        objective, tuple(strategy.estimates), strategy.converged, strategy.final_estimate,
        {},
    )


def default_refinement(options: SolveOptions) -> Refinement:
    """The strategy `options` choose: adaptive subdivision with refine "rounds" -> `FixedRounds`, with
    refine "tol" -> `ToTolerance`; subdivision "none" or "global" -> `NoRefinement`."""
    if options.subdivision != "adaptive":
        return NoRefinement()
    if options.refine == "tol":
        return ToTolerance(options.tol, options.per_round, options.max_frames, options.score)
    return FixedRounds(options.n_rounds, options.per_round, options.max_frames, options.score)


def starting_frames(objective: Objective, initial: FrameSet, options: SolveOptions,
                    project: Callable[[np.ndarray], np.ndarray] | None = None) -> FrameSet:
    """The frames of the first round: `initial`, and with "global" or "adaptive" subdivision variable frames,
    `per_segment` per segment (for "global" at most `max_frames`), valued on the plain spline, the
    per-segment ones mapped by `project` (`solve`). Returns a FrameSet (the same path as `initial`'s
    where `project` is None)."""
    frames = initial
    if options.subdivision not in ("global", "adaptive"):
        return frames
    if options.per_segment <= 0:
        return frames
    new = global_times(frames, options.per_segment)
    if options.max_frames and options.subdivision == "global":
        new = new[: max(0, options.max_frames - frames.n_variable)]
    frames = frames.with_variable_frames(new)
    if project is not None and new.size:
        var = np.zeros(frames.count, bool)
        var[np.searchsorted(frames.times, new)] = True  # the new times are among the frames' times
        vals = frames.values.copy()
        vals[var] = project(vals[var])
        frames = replace(frames, values=vals)
    return frames


@dataclass
class _Log:
    """What the loop of `_rounds` accumulates."""

    frames: FrameSet
    rounds: list = field(default_factory=list)
    traces: list = field(default_factory=list)
    n_evals: int = 0
    status: Status = Status.CONVERGED
    message: str = "converged"


def _rounds(objective, frames, options, strategy, backend, t_start, should_stop, progress) -> _Log:
    """The outer loop: optimize a round (`backend`), then the strategy stops, adds frames ("refine") or
    has the same frames optimized again ("boost", "polish"). Ends on a stop request, the time limit, a round ending in
    INTERRUPTED, MAX_TIME, NONFINITE or FAILED, or the strategy's stop."""
    log, kind, scores = _Log(frames), "start", None
    while True:
        remaining = _remaining(options, t_start, should_stop, log)
        if remaining is None:
            break
        if progress:
            progress("round", {"round": len(log.rounds), "frames": log.frames.count,
                               "variable": log.frames.n_variable, "kind": kind})
        result = backend(objective, log.frames, strategy.round_options(options), remaining, should_stop, progress,
                         log.n_evals)
        _record(log, objective, result, scores, kind, options)
        if log.status in _ENDS:
            break
        try:
            step = strategy.after_round(objective, log.frames, result, len(log.rounds) - 1, progress)
        except NonFiniteError as e:  # keep the optimized frames; say which term failed
            log.status, log.message = Status.NONFINITE, f"{e} while choosing new frames"
            break
        if step.message is not None:
            log.message = step.message
        if step.action == "stop":
            break
        kind, scores = step.action, step.scores
        if step.action == "refine":
            log.frames = log.frames.with_variable_frames(step.times)
    return log


def _remaining(options, t_start, should_stop, log) -> float | None:
    """Time left for the next round [s] (0: no limit), or None (status and message set in `log`) when
    a stop was requested or the time limit has passed."""
    if should_stop is not None and should_stop():  # e.g. Ctrl-C during subdivision
        log.status, log.message = Status.INTERRUPTED, "stopped on request"
        return None
    if not options.max_time_s:
        return 0.0
    remaining = options.max_time_s - (time.perf_counter() - t_start)
    if remaining <= 0:
        log.status, log.message = Status.MAX_TIME, f"time limit of {options.max_time_s:g} s reached"
        return None
    return remaining


def _record(log: _Log, objective, result: OptimizeResult, scores, kind: str, options) -> None:
    """Append the round's result to `log`: frames moved to result.x (the terms prepared on them for the
    next round, the scores and the report), a read-only Round, its trace, evaluations and status."""
    log.frames = log.frames.with_x(result.x)
    objective.prepare(log.frames.times, log.frames.values)
    for arr in (result.x, result.trace, scores):
        _read_only(arr)
    log.rounds.append(Round(log.frames.count, log.frames.n_variable, result, scores,
                            _read_only(log.frames.times.copy()), kind))
    log.traces.append(result.trace)
    log.n_evals += result.n_evals
    log.status, log.message = result.status, result.message
    if result.status is Status.MAX_TIME:  # the round had what was left; report the whole solve's limit
        log.message = f"time limit of {options.max_time_s:g} s reached"


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
        raise InputError(f"objective must be an Objective (e.g. `solver.paper.orient`'s), got {type(objective).__name__}")
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
