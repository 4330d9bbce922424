"""Subdivision: where to add variable frames (paper sec. 2 "Subdivision", sec. 3, appendix C).

Global subdivision adds n variable frames in every segment. Adaptive subdivision adds them where the
path is furthest from optimal by the *weak form* of the Euler-Lagrange residual (docs/design.md): a
candidate frame inserted at a segment midpoint, valued on the current path, leaves the path unchanged
(natural spline); the gradient of E with respect to its value is the integral of the Euler-Lagrange
residual EL(Y) against the candidate's basis function phi_c,

    dE/dP_c = integral EL(Y(t)) phi_c(t) dt,

i.e. the first-order decrease of E per unit move of the new frame, the quantity appendix C bounds
(eq. 27-30). It works for any objective with a gradient, and one gradient evaluation with every
midpoint inserted scores every segment at once.
"""
from __future__ import annotations

import numpy as np

from solver.frames import FrameSet
from solver.objective import Objective
from solver.quadrature import GAUSS_POINTS


def global_times(frames: FrameSet, per_segment: int) -> np.ndarray:
    """Times of `per_segment` equally spaced new frames in every segment.

    Args:
        frames: current frame set (m frames). per_segment: n >= 0.
    Returns:
        ((m-1) * n,) times [s].
    """
    if per_segment <= 0:
        return np.zeros(0)
    a, b = frames.times[:-1], frames.times[1:]
    s = np.arange(1, per_segment + 1) / (per_segment + 1)
    return (a[:, None] + (b - a)[:, None] * s[None, :]).ravel()


def knot_hint_times(frames: FrameSet, hints: np.ndarray, min_gap: float) -> np.ndarray:
    """The hinted times (the contacts' touch-downs and lift-offs, `solver.least_change`) at least `min_gap`
    from every frame and from each other (earlier hints win), strictly inside the path.

    Args:
        frames: current frame set. hints: (r,) times [s]. min_gap: [s] >= 0.
    Returns:
        (r',) sorted times [s], r' <= r.
    """
    keep: list[float] = []
    occupied = list(np.asarray(frames.times, float))
    for x in np.sort(np.asarray(hints, float).ravel()):
        if not frames.times[0] < x < frames.times[-1]:
            continue
        if min(abs(x - y) for y in occupied) >= max(min_gap, 1e-9):
            keep.append(float(x))
            occupied.append(float(x))
    return np.array(keep)


def weak_form_scores(objective: Objective, frames: FrameSet) -> np.ndarray:
    """Weak-form Euler-Lagrange score of each segment: |dE/dP_c| for a frame at its midpoint.

    Args:
        objective: the objective (its scales already set).
        frames: frame set with m frames.
    Returns:
        (m-1,) scores [units of E per unit of qpos]; 0 where the path is locally optimal.
    """
    mids = 0.5 * (frames.times[:-1] + frames.times[1:])
    cand = frames.with_variable_frames(mids)
    ev = objective.evaluate(cand.times, cand.values, grad=True)
    is_mid = np.isin(cand.times, mids)
    return np.linalg.norm(ev.grad[is_mid], axis=1)


def predicted_decreases(objective: Objective, frames: FrameSet, min_points: int = GAUSS_POINTS) -> np.ndarray:
    """Predicted decrease of E from a variable frame inserted at each segment midpoint.

    The weak-form score g_c = dE/dP_c (`weak_form_scores`) is a slope: it grows as segments shrink
    (a short segment's basis function has a large second derivative), so ranking segments by |g_c|
    keeps splitting the shortest ones. What a new frame buys is the decrease of E when it moves to its
    best place: for a step along -g_c, dE = |g_c|^4 / (2 g_c^T H_cc g_c) (a Newton step on the
    quadratic model; appendix C's bound, eq. 27-29, with the step length solved for). The curvature
    g_c^T H_cc g_c is a Hessian-vector product by forward differences of the gradient, with all
    midpoints of one parity (every other segment) moved at once: two extra gradient evaluations score
    every segment (neighbours of one parity are two knots apart; their coupling through the natural
    spline is a few percent).

    Segments too short for the uniform quadrature (a half with fewer than `min_points` quadrature points,
    by default as many as the Gauss rule gives every cubic piece, `GAUSS_POINTS`) score 0: a frame there
    would be under-determined by the integral (it could wiggle between the points). Gauss quadrature
    puts nodes in every segment, so there every segment may be split.

    Args:
        objective: the objective (scales already set).
        frames: frame set with m frames.
        min_points: minimum quadrature points in each half of a segment that may be split.
    Returns:
        (m-1,) predicted decreases [units of E], >= 0.
    """
    mids = 0.5 * (frames.times[:-1] + frames.times[1:])
    cand = frames.with_midpoints()
    is_mid = np.arange(cand.count) % 2 == 1  # one midpoint inside every segment: every other frame
    ev = objective.evaluate(cand.times, cand.values, grad=True)
    g = np.where(cand.fixed, 0.0, ev.grad)  # (M, nq); only the new frames' rows are used
    gm = g[is_mid]
    gg = (gm * gm).sum(axis=1)
    curv = np.zeros_like(gg)
    scale = np.abs(cand.values[is_mid]).max() + 1.0
    for parity in (0, 1):
        sel = np.zeros(len(mids), bool)
        sel[parity::2] = True
        d = np.zeros_like(g)
        d[np.flatnonzero(is_mid)[sel]] = gm[sel]
        nd = np.abs(d).max()
        if nd == 0:
            continue
        eps = 1e-6 * scale / nd
        g2 = objective.evaluate(cand.times, cand.values + eps * d, grad=True).grad[is_mid]
        curv[sel] = ((g2[sel] - ev.grad[is_mid][sel]) * gm[sel]).sum(axis=1) / eps
    ok = curv > 0
    fallback = np.median(curv[ok] / gg[ok]) if ok.any() else 1.0
    curv = np.where(ok, curv, fallback * gg)
    out = np.where(gg > 0, gg * gg / (2.0 * np.maximum(curv, 1e-300)), 0.0)
    if objective.h is None:  # Gauss quadrature: every segment has its own nodes, however short
        return out
    half = 0.5 * np.diff(frames.times)
    return np.where(half >= min_points * objective.h, out, 0.0)


def adaptive_times(scores: np.ndarray, frames: FrameSet, budget: int, ratio: float = 0.25) -> np.ndarray:
    """Midpoints of the segments to subdivide: those scoring at least `ratio` x the best, at most
    `budget` of them, best first (paper: "subdivide in regions where EL > epsilon").

    Args:
        scores: (m-1,) from `weak_form_scores`. frames: the frame set scored.
        budget: maximum number of new frames. ratio: threshold relative to the largest score
            (dimensionless; 0.25: a round refines the segments within a factor of four of the worst, the
            paper's "regions where EL > epsilon" with epsilon set by the worst, not every segment at once).
    Returns:
        (r,) midpoint times [s], sorted.
    """
    if budget <= 0 or scores.size == 0 or not np.any(scores > 0):
        return np.zeros(0)
    order = np.argsort(-scores, kind="stable")
    keep = [i for i in order if scores[i] >= ratio * scores[order[0]]][:budget]
    mids = 0.5 * (frames.times[:-1] + frames.times[1:])
    return np.sort(mids[keep])


def refinement_estimate(objective, frames: FrameSet, E: float | None = None) -> tuple[float, np.ndarray]:
    """The decrease of E still available from refinement, relative to E: sum_c D_c / E, with D_c the
    predicted decrease from a frame inserted at the midpoint of segment c and moved to its best place
    (`predicted_decreases`, what adaptive subdivision ranks segments by). A first-order prediction of
    what halving every segment would buy (each frame moved alone, the others held); 0 where the path
    is optimal for its frames and no frame could lower E.

    Args:
        objective: Objective. frames: FrameSet (m frames). E: the objective on frames, if known.
    Returns:
        (estimate, D): D (m-1,) the predicted decreases [units of E].
    Raises:
        NonFiniteError: a term is NaN or infinite on the path or a trial path.
    """
    D = predicted_decreases(objective, frames)
    if E is None:
        E = objective.evaluate(frames.times, frames.values, grad=False).E
    return (float(D.sum() / E) if E > 0 else 0.0), D
