"""Subdivision: where to add variable frames (paper sec. 2 "Subdivision", sec. 3, appendix C).

Global subdivision adds n variable frames in every segment. Adaptive subdivision adds them where the
path is furthest from optimal by the *weak form* of the Euler-Lagrange residual (DESIGN.md): a
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


def adaptive_times(scores: np.ndarray, frames: FrameSet, budget: int, ratio: float = 0.25) -> np.ndarray:
    """Midpoints of the segments to subdivide: those scoring at least `ratio` x the best, at most
    `budget` of them, best first (paper: "subdivide in regions where EL > epsilon").

    Args:
        scores: (m-1,) from `weak_form_scores`. frames: the frame set scored.
        budget: maximum number of new frames. ratio: threshold relative to the largest score.
    Returns:
        (r,) midpoint times [s], sorted.
    """
    if budget <= 0 or scores.size == 0 or not np.any(scores > 0):
        return np.zeros(0)
    order = np.argsort(-scores, kind="stable")
    keep = [i for i in order if scores[i] >= ratio * scores[order[0]]][:budget]
    mids = 0.5 * (frames.times[:-1] + frames.times[1:])
    return np.sort(mids[keep])
