"""Where the least-change path needs variable frames: the Euler-Lagrange residual of the augmented
integrand, as the decrease of Phi a midpoint frame predicts (paper sec. 4.2), marked by equidistribution.

A candidate frame at the midpoint of each segment, where the spline through the current frames already
passes (so adding it leaves the path unchanged), has gradient g_c = dPhi/dx_c: the weak-form
Euler-Lagrange residual of Phi's integrand tested with that frame's basis function (paper sec. 4.2:
"the Euler-Lagrange equations are furthest from holding"). A Newton step in that frame alone, d_c =
-H_c^-1 g_c with H_c the measure of change's own curvature there (the preconditioner's block of frame c,
`solver.lagrangian.Preconditioner`), predicts the decrease (g_c . d_c)^2 / (2 d_c^T H_true d_c), the
true curvature along d_c measured by one gradient difference (all even and all odd midpoints at once:
their basis functions barely overlap).

The solve stops when the predicted decreases sum to at most tol of Phi + shift. A segment is marked when
its own predicted decrease exceeds its share of that allowance, tol (Phi + shift) h / T for a segment h
long on a path T long: the equidistribution strategy (Babuska & Rheinboldt, "Error estimates for adaptive
finite element computations", SIAM J. Numer. Anal. 15, 1978; Verfuerth, "A Review of A Posteriori Error
Estimation and Adaptive Mesh-Refinement Techniques", 1996, sec. 4.1). Where no segment exceeds its share
the sum is within the allowance, so the test that ends the solve and the marking agree; and each segment is
judged by its own share, not by its rank among all of them, so a clip twice as long, made of the same
motion, is refined in the same steps (Doerfler's bulk rule, which marks the fewest segments that carry half
the total, marked one local peak of the residual a step and took more steps on longer clips).
"""
from __future__ import annotations

import numpy as np

from solver.feasibility import on_points
from solver.frames import FrameSet
from solver.lagrangian import AugmentedLagrangian, _frame_grams, _variable_dofs
from solver.manifold import FrameVariables
from solver.spline_basis import SplineBasis

__all__ = ["equidistributed_times", "predicted_decreases", "refinement"]


def predicted_decreases(al: AugmentedLagrangian, frames: FrameSet, quat_slots: np.ndarray,
                        min_gap: float) -> tuple[np.ndarray, float]:
    """The decrease of Phi a variable frame at each segment's midpoint predicts (module docstring).

    Args:
        al: the AugmentedLagrangian (its multipliers and penalty as they are). frames: FrameSet (m frames).
        quat_slots: (s, 4) the layout's quaternion slots. min_gap: [s] a segment shorter than 2 min_gap
            cannot be split (its prediction is 0).
    Returns:
        ((m - 1,) predicted decreases of Phi >= 0 (dimensionless), Phi on the frames).
    """
    cand = frames.with_midpoints()
    basis = SplineBasis(cand.times, al.t)
    var = FrameVariables(cand, quat_slots)
    fr, dof = _variable_dofs(var, al.tmap)
    phi, G, _ = al.evaluate(basis, cand.values)
    g = var.pullback(np.zeros(var.size), G)
    ch = al.change
    K2, K0 = _frame_grams(basis, ch, al.d0)
    mids = np.flatnonzero(np.arange(cand.count) % 2 == 1)
    at = [np.flatnonzero(fr == c) for c in mids]
    d = np.zeros(var.size)
    for c, idx in zip(mids, at):
        if idx.size:
            D = dof[idx]
            H = K2[c, c] * ch.mbar[np.ix_(D, D)] + K0[c, c] * ch.pbar[np.ix_(D, D)]  # D/D0's, as the preconditioner's
            d[idx] = -np.linalg.solve(H, g[idx])
    gd = np.array([g[idx] @ d[idx] for idx in at])
    curv = np.zeros(len(mids))
    for parity in (0, 1):
        sel = np.zeros(var.size, bool)
        for k in range(parity, len(mids), 2):
            sel[at[k]] = True
        dd = np.where(sel, d, 0.0)
        size = np.abs(dd).max()
        if size == 0:
            continue
        eps = 1e-4 / size  # a step of 1e-4 in the largest variable (m or rad): a difference well above round-off
        _, G2, _ = al.evaluate(basis, var.values(eps * dd))
        g2 = var.pullback(eps * dd, G2)
        for k in range(parity, len(mids), 2):
            curv[k] = (g2[at[k]] - g[at[k]]) @ d[at[k]] / eps
    ok = curv > 0
    dec = np.where(ok, gd * gd / (2.0 * np.where(ok, curv, 1.0)), 0.0)
    dec[np.diff(frames.times) < 2 * min_gap] = 0.0
    return dec, float(phi)


def equidistributed_times(decreases: np.ndarray, frames: FrameSet, allowed: float) -> np.ndarray:
    """The midpoints of the segments whose predicted decrease exceeds their share of `allowed` by length.

    Args:
        decreases: (m - 1,) from `predicted_decreases`. frames: the FrameSet they were computed on (m frames).
        allowed: the decrease of Phi the whole path may still predict (dimensionless, tol (Phi + shift)).
    Returns:
        (r,) sorted times [s] for new variable frames; empty when every segment is within its share, and then
        the decreases sum to at most `allowed`.
    """
    h = np.diff(frames.times)
    share = allowed * h / (frames.times[-1] - frames.times[0])
    return 0.5 * (frames.times[:-1] + frames.times[1:])[decreases > share]


def refinement(al: AugmentedLagrangian, frames: FrameSet, quat_slots: np.ndarray, min_gap: float, tol: float) -> tuple:
    """One refinement step on `frames`: (times (r,) [s] of new variable frames, the segments over their share of tol
    (`equidistributed_times`) each moved to a quadrature point (`solver.feasibility.on_points`), the predicted
    decrease of Phi over Phi + shift (dimensionless, Phi itself can be <= 0), (m - 1,) each segment's predicted
    decrease (`predicted_decreases`))."""
    dec, phi = predicted_decreases(al, frames, quat_slots, min_gap)
    scale = max(phi + al.shift(), 1e-300)
    return on_points(equidistributed_times(dec, frames, tol * scale), al.t, frames), float(dec.sum() / scale), dec
