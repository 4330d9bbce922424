"""A-posteriori estimate of the relative energy gap (E - E*)/E* of an orientation path
(docs/orient.md "Accuracy on request: tol and the gap estimate").

E is the covariant energy of the normalized path, E* that of the exact optimum (the natural Riemannian
cubic spline on S^3 through the keyframes), which is not known while solving. The estimate:

    estimated gap = GAP_FACTOR * sum_c D_c / E

with D_c the predicted decrease of the objective from a variable frame inserted at the midpoint of
segment c and moved to its best place (`solver.subdivide.predicted_decreases`: the weak-form
Euler-Lagrange gradient g_c of the new frame and its curvature, |g_c|^4 / (2 g_c^T H_cc g_c)), summed
over every segment, and E the objective on the current (optimized) path.

Why this estimates the gap. Halving every segment turns the path into one of the next refinement level,
whose gap is 2^-p of this one (p = 5-6 measured: docs/orient.md "Two objective forms"), so the decrease that refinement buys is
(1 - 2^-p) ~ 97-98% of the current gap. sum_c D_c predicts that decrease to first order: each D_c is the
decrease of moving its frame alone, the others held (a Newton step on the diagonal block of the
quadratic model). It misses (i) the coupling between new frames and the re-optimization of the old
ones, which the joint optimum exploits (the sum underestimates: true/sum 0.57-5.0, median 1.34, 90%
within 0.97-2.3, over rounds 1-6 of adaptive refinement on 18 tuning sets), and (ii) the part of the gap the optimizer's tolerance leaves (checked
separately: `optimization_gap`). GAP_FACTOR calibrates (i) on the tuning sets
(runner/bench/random_sets.py seeds 0-49).

Assumptions: the path is optimized for its frames (the estimate is of the discretization gap: it is
computed after every round's optimization), the path is in the asymptotic regime where one midpoint
per segment captures most of what refinement buys (less so on the starting frames, one per keyframe
interval: 2.2x below the truth on the moderate test set), and the objective is the normalized form with a light unit term (its
optimum in the exact-unit limit is E*; with the paper form the optimum of the objective is not E* and
the estimate does not apply).

The quadrature is assumed exact: D_c and E use the objective's own rule (Gauss, 4 points per segment),
which the optimizer may exploit. `solver.paper.orient`'s tolerance loop therefore adds the discrepancy
|E_8 - E_4| / E_8 between 8 and 4 points per segment (~1e-6 usually, 1.6e-3 on one generated set), and
ranks segments by their share of it too.

The optimizer's own gap is assumed small; `optimization_gap` checks it (`solver.paper.orient_refine`
adds it to the estimate of every round, so a stalled round is not accepted; there it is read off the
gradient the optimizer last evaluated, `OptimizeResult.grad`, and this function is the fallback).

Cost: three gradient evaluations with a frame inserted in every segment (the predicted decreases are
also what adaptive subdivision ranks segments by, so the estimate is free when another round follows).
"""
from __future__ import annotations

import numpy as np

from solver.frames import FrameSet
from solver.objective import Objective
from solver.paper.precondition import AccelerationPreconditioner
from solver.subdivide import predicted_decreases

#: [1] true gap / (sum of predicted decreases / E), calibrated on the tuning sets (median of the ratio)
GAP_FACTOR = 1.4


def estimate_gap(objective: Objective, frames: FrameSet, E: float | None = None) -> tuple[float, np.ndarray]:
    """Estimated relative gap (E - E*)/E* of the optimized path through `frames`.

    Args:
        objective: the normalized objective the frames were optimized for (scales set).
        frames: optimized frame set.
        E: the objective on the path (evaluated here if not given).
    Returns:
        (estimate, D): D (m-1,) the predicted decreases per segment [units of E] (`predicted_decreases`),
        reusable to choose the next round's frames.
    """
    D = predicted_decreases(objective, frames)
    if E is None:
        E = objective.evaluate(frames.times, frames.values, grad=False).E
    if not E > 0:
        return 0.0, D
    return float(GAP_FACTOR * D.sum() / E), D


def optimization_gap(objective: Objective, frames: FrameSet, radial_weight: float = 1.0, quat_slots=()) -> float:
    """The decrease of E still available to the optimizer on these frames, relative to E: 0.5 |g_z|^2 / E,
    g_z the gradient in the preconditioned variables of `solve` (`AccelerationPreconditioner`, z = R S
    (x - x0) with R^T R the Hessian of integral |Y''|^2 dt and S the radial stretch).

    Why: for the normalized covariant acceleration of a path with |q| near 1 the Hessian in the
    tangential directions is close to that of integral |Y''|^2 (which is why the preconditioner works),
    so in z the Hessian is close to the identity and a Newton step from the current frames lowers E by
    about 0.5 |g_z|^2. It is a first-order check, not a bound: on a generated set where L-BFGS stopped on
    its relative-decrease test far from the optimum (ftol_rel 3e-5, true gap 1.6e-3 against 9e-5 when
    converged) it gave 1.0e-4, 8-100x its value on converged rounds (1e-6 to 1.3e-5 on the tuning seeds),
    an underestimate but a clear flag. The estimate of `estimate_gap` assumes this is small.

    Args:
        objective: the objective the frames were optimized for. frames: the optimized frame set.
        radial_weight, quat_slots: as the optimizer used them (`SolveOptions`).
    Returns:
        0.5 |g_z|^2 / E (>= 0; 0 without free components or where E is not positive).
    """
    ev = objective.evaluate(frames.times, frames.values, grad=True)
    if not ev.E > 0 or not frames.free.any():
        return 0.0
    pre = AccelerationPreconditioner(objective, frames, radial_weight, quat_slots)
    gz = pre.apply_transpose(ev.grad[frames.free])
    return float(0.5 * (gz @ gz) / ev.E)
