"""The one-call API for a figure: the in-betweens of keyframes in a scene.

`animate(model, keyframes)` builds what the command line `dynsplines animate` builds - the problem
(`build_problem`: the plain spline through the keyframes as the reference motion, the contact schedule,
the flights) - and solves it (`solve_problem`): the least change to the plain spline that meets the
figure's constraints (`solver.least_change`, docs/design.md). The same model, keyframes and options give
the command's path bit for bit (with the same BLAS thread count: the command uses one).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from solver.errors import InputError
from solver.least_change import LeastChangeOptions
from solver.problem import Problem, ProblemSpec, build_problem
from solver.solution import Solution

__all__ = ["animate", "solve_problem"]


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
    (`solver.least_change`, docs/design.md).

    Args:
        problem: from `build_problem`. options: LeastChangeOptions (default: the command line's).
        should_stop, progress: as for `animate`.
    Returns:
        Solution.
    Raises:
        InputError: `problem` is not a Problem, `options` is not LeastChangeOptions.
    """
    from solver.least_change import build_least_change, solve_least_change

    if not isinstance(problem, Problem):
        raise InputError(f"problem must be a solver.Problem (from build_problem), got {type(problem).__name__}")
    options = LeastChangeOptions() if options is None else options
    if not isinstance(options, LeastChangeOptions):
        raise InputError(f"options must be a solver.LeastChangeOptions, got {type(options).__name__}")
    lc = build_least_change(problem.model, problem.keyframes, contacts=tuple(problem.contacts),
                            flights=problem.airborne, capture=problem.capture, rate=options.rate,
                            forces=problem.forces, peaks=problem.force_bounds, bounds=problem.bounds)
    return solve_least_change(lc, options, should_stop=should_stop, progress=progress)
