"""The one-call API for a figure: the in-betweens of keyframes in a scene (the paper's whole method).

`animate(model, keyframes)` builds what the command line `dynsplines animate` builds - the state layout
of the figure, the objective (`figure_objective`: paper eq. 1 with the terms of sec. 5 and 6,
renormalized by eq. 7), the plain spline through the keyframes (`FrameSet.from_keyframes`) - and runs
the loop of the paper's figure 5 (`solve`) with the command's settings (`default_options`). The same
model, keyframes, terms and weights give the command's path bit for bit (with the same BLAS thread
count: the command uses one).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from solver.errors import InputError
from solver.keyframes import Keyframes
from solver.least_change import LeastChangeOptions
from solver.problem import CONTACT_TERMS, Problem, default_limits, make_problem
from solver.quadrature import DEFAULT_RATE
from solver.solve import Solution, SolveOptions, solve

__all__ = ["DEFAULT_RATE", "DEFAULT_TOL", "animate", "default_options", "solve_problem"]

#: Default accuracy of the figure (`SolveOptions.tol`): adaptive rounds until the decrease of E that
#: refinement still predicts is at most 1% of E. On the shipped clip (run-and-step) the estimate is
#: 3.4%, 1.3% and 0.47% after the starting round and the two adaptive rounds, so this stops after two
#: adaptive rounds (docs/orient.md "At the command line, and on the figure").
DEFAULT_TOL = 1e-2


def default_options(weights: dict[str, float]) -> SolveOptions:
    """The solve options of the command line (`dynsplines animate` with no optimization options).

    One variable frame per keyframe interval, then rounds of adaptive subdivision ranked by the
    decrease of E each midpoint frame predicts (paper fig. 5 and sec. 4.2) until the predicted decrease
    still available, summed over all segments, is at most DEFAULT_TOL of E (`SolveOptions.refine` "tol"
    with `tol`; a frame budget of 10 per keyframe interval), renormalized terms
    (eq. 7), L-BFGS preconditioned in the spline-acceleration metric (quaternions' radial directions
    weighted by the unit term's curvature: `radial_weight="auto"`; 1 with contact terms, whose
    curvature in the frame values the auto weight does not see: run-and-step with its contacts took
    668 evaluations with "auto" and 484 with 1, 35_17 406 and 336) with relative tolerance 1e-6, no
    evaluation or time limit, and penalty continuation to `default_limits(weights)` (penetration
    0.5 mm, hyperextension 1 deg, |1 - |q|| 0.03, planted 2 cm / 20 cm/s, clearance 1 cm into its band,
    for the terms switched on); with contact terms, variable frames first at every touch-down and
    lift-off (`SolveOptions.term_knots`).

    Args:
        weights: {term name: lambda_j >= 0} as from `parse_terms`; only which terms have a nonzero
            weight matters (it chooses the limits).
    Returns:
        SolveOptions. Change fields with `dataclasses.replace(default_options(w), tol=1e-3)`; for a
        fixed number of rounds choose that mode: `replace(default_options(w), refine="rounds", tol=0,
        rounds=4)` (a tolerance left with refine "rounds", or rounds with refine "tol", is an
        InputError: it would be ignored).
    Raises:
        InputError: `weights` is not a mapping of term names to weights.
    """
    if not hasattr(weights, "items"):
        raise InputError(f"weights must be a dict {{term name: weight}} (e.g. from parse_terms), got "
                         f"{type(weights).__name__}")
    return SolveOptions(
        subdivision="adaptive", per_segment=1, renormalize=True, algorithm="lbfgs", ftol_rel=1e-6,
        max_evals=0, max_time_s=0.0, limits=default_limits(weights), precondition=True,
        radial_weight=1.0 if any(weights.get(n, 0) > 0 for n in CONTACT_TERMS) else "auto",
        score="decrease", refine="tol", tol=DEFAULT_TOL,
    )


def animate(
    model,
    keyframes: Keyframes,
    terms: str | list[str] | tuple[str, ...] | None = None,
    weights: dict[str, float] | None = None,
    options: SolveOptions | None = None,
    *,
    rate: float | None = None,
    should_stop: Callable[[], bool] | None = None,
    progress: Callable[[str, dict], None] | None = None,
    tol: float | None = None,
    contacts=(),
    capture=None,
    airborne=None,
) -> Solution:
    """Optimize the in-betweens of a figure's keyframes in a scene (paper sec. 2-6, fig. 5).

    The path is the C2 natural cubic spline through the keyframes and variable frames; the variable
    frames and the components partial keyframes leave free minimize E = sum_j lambda_j integral f_j dt
    (eq. 1, each term renormalized by its value on the plain spline, eq. 7) while every keyframe holds
    exactly. Variable frames are added where the Euler-Lagrange equations are furthest from holding.

    Args:
        model: mujoco.MjModel of a scene holding the figure (one free root joint, ball joints, the
            contact sites l_heel, l_toe, r_heel, r_toe) and its floor/boxes. Not modified.
        keyframes: Keyframes of the figure's qpos, values (k, nq) with nq = model.nq, times (k,) [s].
        terms: which objective terms: None (penetration, unit, bending, smooth, hinge, rom), "all", a
            comma-separated string or a list of names from `term_names()`.
        weights: {term name: lambda_j >= 0} overriding the default weights (`DEFAULT_WEIGHTS`); a name
            here also switches the term on.
        options: LeastChangeOptions (the least change that meets the figure's constraints,
            docs/design.md) or SolveOptions (the weighted terms); default: LeastChangeOptions when
            neither `terms` nor `weights` is given (the command line's default), else
            `default_options(weights)`.
        rate: quadrature points per second [1/s]; default DEFAULT_RATE.
        should_stop: polled during the optimization; True ends it, keeping the best path so far.
        progress: progress(event, info) for "round", "eval", "boost", "stalled", "undo" and "estimate" (see `solve`).
        tol: refine adaptively until the decrease of E refinement still predicts, relative to E, is at
            most tol (`SolveOptions.tol`, replacing the options' fixed rounds), or a frame or time
            budget runs out (`Solution.converged_to_tol`, `Solution.refinement_estimate`).
        contacts: the contact schedule (`solver.contacts.Contact`s: site, start, end [s], surface), e.g.
            `KeyframeFileInfo.contacts` or `reference_contacts`. With one, the default terms add planted
            and clearance and "all" adds cone too (docs/contacts.md "Contact schedules"; `terms="penetration,unit,bending,smooth"`
            leaves them out); without one, naming them is an InputError. Keyframes that contradict it
            are excused from the bounds (`solver.problem.keyframe_conflicts`).
        capture: None, or (times (n,) [s] on the keyframes' clock, qpos (n, nq)): the motion capture the
            keyframes were made from; with the `forces` term its peak ground force and pelvis
            acceleration, low-pass filtered, join the term's bounds (`make_problem`, docs/dynamics.md).
        airborne: None, or ((start, end), ...) [s] where the motion flies, e.g. `KeyframeFileInfo.flights`:
            the clearance term lifts the feet only there (docs/contacts.md "Flights where the capture
            flies"); None: computed from `capture` when given, else every gap of the schedule is a flight.
    Returns:
        Solution: `frames` (the optimized FrameSet, values (m, nq) qpos at times (m,) [s]; the path is
        the spline through them, `frames.path(t)`), `initial` (the plain spline's), E and the term
        integrals before and after, `weights` after penalty continuation, status and message.
    Raises:
        InputError: `keyframes` is not Keyframes or does not fit the model (nq), an unknown term or a
            bad weight (lists the valid ones), a scene without what a term needs (contact sites),
            bad `options` or `rate`.
        NonFiniteError: the objective is NaN or infinite on the plain spline.
    """
    problem = make_problem(model, keyframes, terms, weights, contacts, rate, capture=capture,
                           airborne=airborne)
    if options is None and terms is None and weights is None:  # the command line's default method
        options = LeastChangeOptions() if tol is None else LeastChangeOptions(tol=float(tol))
    if tol is not None and (options is None or isinstance(options, SolveOptions)):
        options = replace(options or default_options(dict(problem.weights)), refine="tol", tol=float(tol), rounds=None)
    return solve_problem(problem, options, should_stop=should_stop, progress=progress)


def solve_problem(problem: Problem, options: SolveOptions | None = None, *,
                  should_stop: Callable[[], bool] | None = None,
                  progress: Callable[[str, dict], None] | None = None) -> Solution:
    """Solve a `Problem`: with `LeastChangeOptions`, the least change to the plain spline that meets the
    figure's constraints (`solver.least_change`, docs/design.md); with SolveOptions, the penalty
    objective of paper eq. 1 (`solve(problem.objective, problem.initial, options)`, paper fig. 5).

    Args:
        problem: from `make_problem`.
        options: LeastChangeOptions or SolveOptions; default `default_options(problem.weights)`.
        should_stop, progress: as for `solve`.
    Returns:
        Solution.
    Raises:
        InputError: `problem` is not a Problem, bad `options`.
        NonFiniteError: the objective is NaN or infinite on the plain spline.
    """
    if not isinstance(problem, Problem):
        raise InputError(f"problem must be a solver.Problem (from make_problem), got {type(problem).__name__}")
    if isinstance(options, LeastChangeOptions):
        from solver.least_change import build_least_change, solve_least_change

        lc = build_least_change(problem.model, problem.keyframes, contacts=tuple(problem.contacts),
                                flights=problem.airborne, capture=problem.capture, rate=options.rate,
                                forces=problem.weights.get("forces", 0) > 0)
        return solve_least_change(lc, options, should_stop=should_stop, progress=progress)
    if options is None:
        options = default_options(dict(problem.weights))
    elif not isinstance(options, SolveOptions):
        raise InputError(f"options must be a SolveOptions (e.g. default_options(weights)), got {type(options).__name__}")
    return solve(problem.objective, problem.initial, options, should_stop=should_stop, progress=progress)
