"""The optimizer back end of `solve`'s rounds: what moves the free components of one frame set.

`solve` asks a `Backend` for one round at a time (paper fig. 5, step "optimize"): the objective, the
frames whose free components are the variables, the options, the time left, the stop poll, the
progress callback and the evaluations of earlier rounds. The default, `nlopt_backend`, is nlopt's
L-BFGS (or another of `solver.optimize.ALGORITHMS`) in the preconditioned variables
(`solver.paper.round.optimize_round`), with one retry in the plain variables after nlopt's generic failure.
Another method (e.g. Gauss-Newton on residuals) implements the same call and returns an
`OptimizeResult` whose `x` is in the frame variables (`FrameSet.values_from_x`).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Protocol

import numpy as np

from solver.optimize import OptimizeResult, Status
from solver.paper.round import optimize_round


class Backend(Protocol):
    """One optimization round of `solve`.

    Args:
        objective: the `Objective` (working copy; its weights may change between rounds).
        frames: FrameSet; its free components (`frames.x()`, (n_free,)) are the variables.
        options: SolveOptions (the back end reads the optimizer settings it knows: algorithm,
            ftol_rel, max_evals, precondition, radial_weight, quat_slots).
        remaining: time left for the round [s]; 0 = no limit.
        should_stop: polled during the round, or None; True ends it (status INTERRUPTED, best x kept).
        progress: progress("eval", {"evals": evals_before + n, "E": f}) per evaluation, or None.
        evals_before: objective evaluations of earlier rounds (for the progress count).
    Returns:
        OptimizeResult with x (n_free,) in the frame variables, n_evals this round's evaluations,
        trace (n_evals,) the best objective after each, status and message.
    """

    def __call__(self, objective, frames, options, remaining: float, should_stop: Callable[[], bool] | None,
                 progress: Callable[[str, dict], None] | None, evals_before: int) -> OptimizeResult: ...


def nlopt_backend(objective, frames, options, remaining, should_stop, progress, evals_before) -> OptimizeResult:
    """`Backend`: `optimize_round` (nlopt, preconditioned when `options.precondition`), and where that
    ends in nlopt's generic failure (a line search that found no decrease, seen with the
    preconditioner on extreme inputs such as a root inside the floor), the same round again in the
    plain variables from the point it reached. The retry's result carries both attempts' evaluations,
    traces and times, and no gradient (the first attempt's is in the preconditioned variables).

    Returns: OptimizeResult (see `Backend`).
    """
    result = optimize_round(objective, frames, options, remaining, should_stop, progress, evals_before)
    if result.status is not Status.FAILED or not options.precondition:
        return result
    plain = replace(options, precondition=False)
    retry = optimize_round(objective, frames.with_x(result.x), plain, remaining, should_stop, progress,
                           evals_before + result.n_evals)
    return replace(retry, n_evals=result.n_evals + retry.n_evals, grad=None,
                   trace=np.concatenate([result.trace, retry.trace]),
                   wall_time_s=result.wall_time_s + retry.wall_time_s,
                   fun_time_s=result.fun_time_s + retry.fun_time_s)
