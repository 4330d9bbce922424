"""The one-call API for a figure: the in-betweens of keyframes in a scene.

`animate(model, keyframes)` builds what the command line `dynsplines animate` builds - the problem
(`build_problem`: the plain spline through the keyframes as the reference motion, the contact schedule,
the flights) - and solves it (`solve_problem`): the least change to the plain spline that meets the
figure's constraints (`solver.least_change`, docs/design.md). The same model, keyframes and options give
the command's path bit for bit (with the same BLAS thread count: the command uses one).
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from solver.errors import InputError
from solver.least_change import LeastChangeOptions
from solver.optimize import Status
from solver.problem import Problem, ProblemSpec, build_problem
from solver.solution import Solution

__all__ = ["animate", "solve_problem"]

#: [1] a certificate is checked at FINER times the solve's quadrature rate: one bisection of the quadrature
#: interval, so the least violation's finest segment (two intervals, `solver.feasibility`) halves
FINER = 2.0


def animate(
    model,
    keyframes,
    *,
    forces: bool = False,
    options: LeastChangeOptions | None = None,
    should_stop: Callable[[], bool] | None = None,
    progress: Callable[[str, dict], None] | None = None,
    tol: float | None = None,
    contacts=(),
    capture=None,
    airborne=None,
) -> Solution:
    """Optimize the in-betweens of a figure's keyframes in a scene (docs/design.md).

    The path is the C2 natural cubic spline through the keyframes and variable frames; the variable
    frames and the components partial keyframes leave free make the least change to the plain spline
    (the mass-weighted acceleration change plus a small pose term) that meets the figure's constraints,
    every keyframe exact at every iterate; variable frames are added where the Euler-Lagrange residual
    of the augmented Lagrangian predicts the largest decrease.

    Args:
        model: mujoco.MjModel of a scene holding the figure (one free root joint, ball joints, the
            contact sites) and its floor/boxes. Not modified.
        keyframes: Keyframes of the figure's qpos, values (k, nq) with nq = model.nq, times (k,) [s].
        forces: also the force bounds (`solver.constraints.forces`; `--terms all`).
        options: LeastChangeOptions (default: the command line's).
        should_stop: polled during the optimization; True ends it, keeping the best path so far.
        progress: progress(event, info) for "round", "eval" and "estimate".
        tol: `LeastChangeOptions.tol` (replacing the options').
        contacts: the contact schedule (`solver.contacts.Contact`s: site, start, end [s], surface), e.g.
            `KeyframeFileInfo.contacts` or `runner.capture.contact_detection.reference_contacts`.
        capture: None, or (times (n,) [s] on the keyframes' clock, qpos (n, nq)): the motion capture the
            keyframes were made from (`ProblemSpec.capture`).
        airborne: None, or ((start, end), ...) [s] where the motion flies (`ProblemSpec.airborne`).
    Returns:
        Solution: `frames` (the optimized FrameSet, values (m, nq) qpos at times (m,) [s]; the path is
        the spline through them, `frames.path(t)`), `initial` (the plain spline's), status, message and
        `unmet` (the constraints the keyframes put out of reach: where and by how much).
    Raises:
        InputError: `keyframes` is not Keyframes or does not fit the model (nq), a bad contact, a scene
            without what a constraint needs, bad `options`.
    """
    problem = build_problem(model, ProblemSpec(keyframes, tuple(contacts or ()), bool(forces), capture, airborne))
    options = options or LeastChangeOptions()
    if tol is not None:
        options = replace(options, tol=float(tol))
    return solve_problem(problem, options, should_stop=should_stop, progress=progress)


def solve_problem(problem: Problem, options: LeastChangeOptions | None = None, *,
                  should_stop: Callable[[], bool] | None = None,
                  progress: Callable[[str, dict], None] | None = None) -> Solution:
    """Solve a `Problem`: the least change to the plain spline that meets the figure's constraints
    (`solver.least_change`, docs/design.md). Where the least violation raised a limit, it is checked at a
    finer spacing (`_checked_finer`: the search again at twice the rate, from the returned path).

    Args:
        problem: from `build_problem`. options: LeastChangeOptions (default: the command line's).
        should_stop, progress: as for `animate`; progress also gets "finer" (rate [1/s], segment [s]: the
            check's rate and its search's finest segment) before the check's own events.
    Returns:
        Solution (`Solution.finer`: what the check found).
    Raises:
        InputError: `problem` is not a Problem, `options` is not LeastChangeOptions.
    """
    from solver.least_change import solve_least_change

    if not isinstance(problem, Problem):
        raise InputError(f"problem must be a solver.Problem (from build_problem), got {type(problem).__name__}")
    options = LeastChangeOptions() if options is None else options
    if not isinstance(options, LeastChangeOptions):
        raise InputError(f"options must be a solver.LeastChangeOptions, got {type(options).__name__}")
    solution = solve_least_change(_built(problem, options.rate), options, should_stop=should_stop, progress=progress)
    if solution.certificate and solution.status is Status.INFEASIBLE:
        return _checked_finer(problem, options, solution, should_stop, progress)
    return solution


def _built(problem: Problem, rate: float):
    """The problem's `solver.least_change.LeastChange` with quadrature points at `rate` [1/s]."""
    from solver.least_change import build_least_change

    return build_least_change(problem.model, problem.keyframes, contacts=tuple(problem.contacts),
                              flights=problem.airborne, capture=problem.capture, rate=rate,
                              forces=problem.forces, peaks=problem.force_bounds, bounds=problem.bounds)


def _checked_finer(problem: Problem, options: LeastChangeOptions, coarse: Solution, should_stop, progress) -> Solution:
    """A certificate checked at a finer spacing: the least violation sought again at FINER times the rate, from
    the returned path, so that the search (`solver.feasibility`) splits segments down to half the length. Where
    it beats the certificate (`_beats`: it raises no column the certificate does not, none by more, and is not
    the same), the least change is solved at that rate from the returned path and its answer returned; else
    the coarse answer stands, checked. Where the budget ends before the least change at that rate does, the
    coarse path is returned with the status that says so (not INFEASIBLE: its certificate is beaten, no proof).
    The least violation of a nonconvex problem is a search's, so the finer search can also land higher.
    `Solution.finer` says what the other found; evaluations, time and rounds are all of them. Within the
    options' budget; a check whose search stopped early (time, evaluations, a stop request) leaves the coarse
    answer.
    """
    from solver.least_change import least_violation_of, solve_least_change

    spent = {"max_time_s": coarse.wall_time_s, "max_evals": coarse.n_evals}
    left = {k: getattr(options, k) - v for k, v in spent.items() if getattr(options, k)}
    if any(v <= 0 for v in left.values()):
        return coarse
    finer = replace(options, rate=FINER * options.rate, **{k: type(getattr(options, k))(v) for k, v in left.items()})
    if progress:
        progress("finer", {"rate": finer.rate, "segment": 2.0 / finer.rate})
    t0 = time.perf_counter()
    lc = _built(problem, finer.rate)
    cert = least_violation_of(lc, coarse.frames, finer, should_stop=should_stop,
                              progress=_counted_on(progress, coarse.n_evals))
    checked = {"n_evals": coarse.n_evals + cert.n_evals, "wall_time_s": coarse.wall_time_s + time.perf_counter() - t0}
    if cert.status is not Status.CONVERGED:
        return replace(coarse, **checked)
    if not _beats(cert.raises, coarse.certificate):
        return replace(coarse, finer=(finer.rate, False, tuple(cert.raises)), **checked)
    fine = solve_least_change(lc, finer, should_stop=should_stop, progress=_counted_on(progress, checked["n_evals"]),
                              from_frames=coarse.frames)
    checked = {"n_evals": checked["n_evals"] + fine.n_evals, "wall_time_s": checked["wall_time_s"] + fine.wall_time_s}
    if fine.status not in (Status.CONVERGED, Status.INFEASIBLE):  # the budget ended at the finer rate: its search
        # beat the certificate, which is then no proof; the coarse path, with the status that says why it stopped
        return replace(coarse, status=fine.status, finer=(finer.rate, False, tuple(cert.raises)), **checked,
                       message=f"{fine.message}; the least violation at {finer.rate:g} points/s raised less than at "
                               f"{options.rate:g}, so the limits raised are not proved out of reach")
    if not _beats(fine.certificate, coarse.certificate):
        return replace(coarse, finer=(finer.rate, False, tuple(fine.certificate)), **checked)
    return replace(fine, rounds=coarse.rounds + fine.rounds, trace=np.concatenate([coarse.trace, fine.trace]),
                   finer=(finer.rate, True, tuple(coarse.certificate)), **checked)


def _counted_on(progress, before: int):
    """`progress` with the evaluations its events report ("evals") counted on from `before` (a solve's so far): the
    check's search and least change each count from 0. None stays None."""
    if progress is None:
        return None
    return lambda event, info: progress(event, {**info, "evals": info["evals"] + before} if "evals" in info else info)


def _beats(fine, coarse) -> bool:
    """Whether the Raises `fine` beat `coarse`: every (constraint, column) raised in `fine` is raised in `coarse`,
    by at least as much [SI], and `fine` is not the same (fewer raised, or one by less)."""
    was = {(r.constraint, r.label): r.amount for r in coarse}
    now = {(r.constraint, r.label): r.amount for r in fine}
    if any(k not in was or a > was[k] for k, a in now.items()):
        return False
    return len(now) < len(was) or any(a < was[k] for k, a in now.items())
