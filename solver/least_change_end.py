"""How a least-change solve ends (`solver.least_change`): its budget, the progress that ends a grid's, the path and the
certificate it keeps.

A solve keeps the best path that met every limit as it goes (`better_path`, by D); the path it returns is its last, or
that best where the last broke a limit or, on a grid (one frame set, so every path on the same frames) where no limit
was raised, lies above the best's D (`kept_path`).
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from solver.feasibility import beyond, still_raised
from solver.frames import FrameSet
from solver.optimize import Status
from solver.spline_basis import SplineBasis

__all__ = ["as_posed", "budget_left", "better_path", "grid_done", "kept_certificate", "kept_path", "stop_message",
           "subproblem_progress", "worst_pair"]


def better_path(al, best: tuple, frames: FrameSet, basis=None) -> tuple:
    """(D, frames) of the better of `best` and `frames` (a path that meets every limit) by D."""
    basis = basis if basis is not None else SplineBasis(frames.times, al.t)
    D = al.evaluate(basis, frames.values, grad=False)[2]
    return (D, frames) if best[0] > D else best


def kept_path(al, frames: FrameSet, basis, best: tuple, message: str, raises: list, limits: list,
              grid: bool = False) -> tuple:
    """The path a solve returns: its last, or the best that met every limit where the last broke one or, on a `grid`
    (one frame set: every path on the same frames) with nothing `raises`d, has the lower D; and what stays raised on
    it (`solver.feasibility.still_raised` against the limits as posed). Not where a limit was raised: the rounds after
    the search bring a raised pair from the middle of its raised tolerance toward its least violation, which costs D
    (on the unseen jesse_dance and MDM cleans, the least D's path floated 0.7 mm more and slid 2-20 times as far).
    Returns (frames, basis, message, raises)."""
    broke = worst_pair(al, al.scaled_values(basis, frames.values))["value"] > 1.0
    lower = grid and not raises and best[0] < al.evaluate(basis, frames.values, grad=False)[2]
    if np.isfinite(best[0]) and (broke or lower):
        frames = best[1]  # the path ended beyond a limit, or above the least D of those that met them: that one
        basis = SplineBasis(frames.times, al.t)
        message += ("; the last path broke a limit: the best that met them all kept" if broke else
                    "; the path of least change among those that met every limit kept")
    if raises:  # what stays raised: the certified columns the path returned is beyond their limits as posed
        raises = still_raised(raises, beyond(al, al.constraints, frames, limits))
    return frames, basis, message, raises


def grid_done(result, shift: float, count: int, o, level_its: int, message: str) -> tuple:
    """On a grid with every constraint met: (the last subproblem's progress (`subproblem_progress`), the solve's message
    if it ends here (the progress within tol, or the frame set's subproblems spent), else `message`)."""
    estimate = subproblem_progress(result, shift)
    if estimate <= o.tol or level_its >= o.per_level:
        message = f"every constraint met on the grid's {count} frames; the last subproblem's decrease {estimate:.3g}"
    return estimate, message


def subproblem_progress(result, shift: float) -> float:
    """The decrease of Phi over a subproblem over Phi + shift at its start (dimensionless, >= 0): the method of
    multipliers is done when a subproblem started from the last one's path under the updated multipliers
    moves Phi by no more than the tolerance (Birgin & Martinez 2014, sec. 4.1: the subproblems' progress)."""
    trace = np.asarray(result.trace, float)
    if trace.size == 0 or not np.isfinite(trace[0]):
        return float("inf")
    return float(max(trace[0] - result.fun, 0.0) / max(trace[0] + shift, 1e-300))


def budget_left(o, start: float, evals: int) -> tuple[float, Status | None]:
    """([s] the time left of `o.max_time_s` (0: no limit), the status that ends the solve before its next
    subproblem: MAX_TIME or MAX_EVALS when that budget is spent, else None)."""
    left = o.max_time_s - (time.perf_counter() - start) if o.max_time_s else 0.0
    if o.max_time_s and left <= 0:
        return left, Status.MAX_TIME
    return left, Status.MAX_EVALS if o.max_evals and evals >= o.max_evals else None


def worst_pair(al, scaled: list) -> dict:
    """{"worst": the name of the constraint furthest over its tolerance ("" without one), "value": its largest c/tol (met at <= 1)}."""
    value, name = max(((float(s.max()), c.name) for c, s in zip(al.constraints, scaled) if s.size), default=(0.0, ""))
    return {"worst": name, "value": value}


def stop_message(status: Status, message: str, o) -> str:
    """Why a solve ended on `status`: the whole solve's budget for MAX_TIME and MAX_EVALS (a subproblem reports only its own
    share), else the subproblem's `message`."""
    return {Status.MAX_TIME: f"time limit of {o.max_time_s:g} s reached",
            Status.MAX_EVALS: f"evaluation budget of {o.max_evals} spent"}.get(status, message)


def as_posed(al, limits: list) -> None:
    """Set `al`'s constraints' limits back to `limits` (as posed), its multipliers to 0 and V to inf: the raises of
    a search whose path is kept only as a start for a later one are undone."""
    for c, limit in zip(al.constraints, limits):
        c.limit = limit.copy()
    al.lam, al.V = [np.zeros(c.size) for c in al.constraints], np.inf


def kept_certificate(al, cert, prior, limits: list, progress):
    """The certificate a clean keeps: the search after the rounds' `cert`, unless a clean's first search (`prior`:
    its Certificate and the limits it raised, or None) certified some column more than a tolerance lower; then the
    first's, its limits set again (the multipliers of its raised pairs from 0) and reported ("kept").

    Each certificate is a least violation of its own starts' basins, and each level's winner among starts is the
    lower F of that level alone (`solver.feasibility`): from another basin a small gain at a higher level can cost a
    lower one without bound (the unseen video2bvh_cxk: no-jolt 5.7 against 135 rad/s^2 beyond its peaks, bought with
    795 against 22 mm of slide). So the later certificate replaces the first only where it is no worse on any
    column by more than that column's tolerance: across basins, Pareto's order within the tolerances."""
    if prior is None or not cert.raises:
        return cert
    old = {(r.constraint, r.label): r.amount for r in prior[0].raises}
    worse = []
    for r in cert.raises:  # the column's tolerance [SI]: the largest of its pairs'
        tol = max(float(np.max(np.broadcast_to(c.tolerance, c.limit.shape)[np.asarray(c.labels) == r.label], initial=0.0))
                  for c in al.constraints if c.name == r.constraint)
        if r.amount > old.get((r.constraint, r.label), 0.0) + tol:
            worse.append(r)
    if not worse:
        return cert
    for c, limit in zip(al.constraints, prior[1]):
        c.limit = limit.copy()
    al.lam = [np.where(c.limit != posed, 0.0, lam) for c, lam, posed in zip(al.constraints, al.lam, limits)]
    al.V = np.inf
    if progress:
        progress("kept", {"worse": {f"{r.constraint} at {r.label}" if r.label else r.constraint: r.amount for r in worse}})
    return replace(prior[0], n_evals=cert.n_evals)
