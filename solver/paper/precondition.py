"""The acceleration preconditioner of `SolveOptions.precondition`: optimize in z = R (x - x0), with
R^T R the Hessian of integral |Y''|^2 dt over the free components of a frame set.

For acceleration-dominated objectives (the covariant acceleration, eq. 9 f2) this removes most of the
ill-conditioning of frame values (the Hessian of a spline's bending energy grows like 1/h^3 in the
frame spacing h), and L-BFGS needs 2-3x fewer evaluations.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

from solver.frames import FrameSet
from solver.objective import Objective

__all__ = ["AccelerationPreconditioner", "auto_radial_weight"]


class AccelerationPreconditioner:
    """x = x0 + R^-1 z for `SolveOptions.precondition`: R upper triangular with R^T R = H + a tiny
    ridge, H the Hessian of integral |Y''|^2 dt (= 2 h W2^T W2 for each component) over the free
    components, in the order of `FrameSet.x`.

    `radial_weight` w (a number, or "auto": `auto_radial_weight` from the objective's terms) with
    `quat_slots`: the curvature assumed along each free quaternion's radial direction is w H (see below).

    H is block diagonal by component, and components whose free frames are the same share one block
    (all of a figure's components are free in the variable frames; partial keyframes add a few more
    patterns), so R^-1 is applied per group as an (r, r) matrix times an (r, c) block: O(r^2 c) work
    instead of the O(n_free^2) of a dense R^-1 (1600 x 1600 for the figure: ~3 ms per evaluation).
    """

    def __init__(self, objective: Objective, frames: FrameSet, radial_weight: float | str = 1.0, quat_slots=()):
        basis = objective.basis(frames.times)
        # H and the factors depend on the knots alone: kept with the spline basis (itself cached per
        # objective and knots), so the rounds and checks on the same frames factor once
        cache = basis.__dict__.setdefault("_preconditioner", {})
        if "H" not in cache or cache["h"] != objective.h:
            cache.clear()
            # the Hessian of integral |Y''|^2 dt per component; long clips (banded bases) without forming W2
            cache["H"] = basis.gram(2, 2.0 * (objective.h if basis.weights is None else basis.weights))
            cache["h"] = objective.h
        H = cache["H"]
        self.free = frames.free
        if radial_weight == "auto":
            radial_weight, quat_slots = auto_radial_weight(objective, frames, H)
        self.radial_weight = float(radial_weight)
        patterns: dict[bytes, list[int]] = {}
        for c in range(self.free.shape[1]):
            if self.free[:, c].any():
                patterns.setdefault(self.free[:, c].tobytes(), []).append(c)
        self.groups = []
        for key, comps in patterns.items():
            rows = np.flatnonzero(np.frombuffer(key, dtype=bool))
            if key not in cache:
                cache[key] = np.linalg.inv(_upper_factor(H[np.ix_(rows, rows)]))
            self.groups.append((rows, np.array(comps), cache[key]))
        # `whole_rows`: one group of whole free frames, or None
        self._whole = self.groups[0][0] if len(self.groups) == 1 and len(self.groups[0][1]) == self.free.shape[1] else None
        # radial stretch (see SolveOptions.radial_weight): x = S^-1 R^-1 z with, per free frame and
        # quaternion, S^-1 = I + c u u^T (u its unit direction at the start), c = 1/sqrt(w) - 1:
        # the assumed Hessian S (H x I) S has curvature w H along u
        self.c = 1.0 / np.sqrt(radial_weight) - 1.0
        self.radial = []  # (rows, slot (4,), U (len(rows), 4)) for quaternions free in those rows
        if self.c != 0.0:
            for slot in np.asarray(quat_slots, dtype=int).reshape(-1, 4):
                rows = np.flatnonzero(self.free[:, slot].all(axis=1))
                if rows.size:
                    U = frames.values[np.ix_(rows, slot)]
                    norm = np.linalg.norm(U, axis=1, keepdims=True)
                    U = np.where(norm > 0, U / np.where(norm > 0, norm, 1.0), 0.0)
                    self.radial.append((rows, slot, U))

    def whole_rows(self) -> np.ndarray | None:
        """The free frames' rows if every free component is in one group covering all components
        (whole frames free, as in the orientation problem): then x = x0 + (R^-1 Z).ravel() with
        Z = z.reshape(len(rows), nq), R^-1 = groups[0][2]. Otherwise None."""
        return self._whole

    def whole_radial(self):
        """For `whole_rows` frames: (None, 0) without radial stretch; (U, c) if it acts on one
        quaternion filling the state in every free frame (the orientation problem: x = R^-1 Z, then
        X += c (X.U) U row by row); None otherwise (use apply/apply_transpose)."""
        if not self.radial:
            return None, 0.0
        rows, slot, U = self.radial[0]
        whole = self.whole_rows()
        if (len(self.radial) == 1 and whole is not None and np.array_equal(rows, whole)
                and np.array_equal(slot, np.arange(self.free.shape[1]))):
            return U, self.c
        return None

    def apply(self, z: np.ndarray) -> np.ndarray:
        """R^-1 z for z of shape (n_free,)."""
        return self._map(z, transpose=False)

    def apply_transpose(self, g: np.ndarray) -> np.ndarray:
        """R^-T g: a gradient with respect to x as one with respect to z."""
        return self._map(g, transpose=True)

    def _map(self, v, transpose):
        rows = self._whole
        if rows is not None:  # whole free frames, one factor: no scatter into (m, nq) and gather back
            (_, _, Rinv), = self.groups
            X = v.reshape(len(rows), self.free.shape[1])
            if transpose:
                X = X.copy()
                self._stretch(X, rows)
                return (Rinv.T @ X).ravel()
            out = Rinv @ X
            self._stretch(out, rows)
            return out.ravel()
        X = np.zeros(self.free.shape)
        X[self.free] = v
        if transpose:
            self._stretch(X)
        out = np.zeros_like(X)
        for rows, comps, Rinv in self.groups:
            block = X[np.ix_(rows, comps)]
            out[np.ix_(rows, comps)] = (Rinv.T if transpose else Rinv) @ block
        if not transpose:
            self._stretch(out)
        return out[self.free]

    def _stretch(self, X, whole=None):
        """X[row, slot] += c (X[row, slot].u) u for the radial directions u (in place; symmetric). X is
        (m, nq) over all frames, or with `whole` (the sorted `whole_rows`) (len(whole), nq) over those."""
        for rows, slot, U in self.radial:
            at = rows if whole is None else np.searchsorted(whole, rows)  # radial rows are whole rows
            B = X[np.ix_(at, slot)]
            X[np.ix_(at, slot)] = B + (self.c * np.einsum("ri,ri->r", B, U))[:, None] * U


def auto_radial_weight(objective: Objective, frames: FrameSet, H: np.ndarray) -> tuple[float, np.ndarray]:
    """The radial weight for `radial_weight="auto"`, from the curvature the objective's terms declare
    (`Term.acceleration_curvature`, `Term.radial_curvature`), and the quaternion slots it acts on.

    Along a quaternion's radial direction the covariant acceleration has (nearly) no curvature and the
    unit term's is a value (mass-matrix) curvature, G = beta W^T diag(w) W; tangential directions get
    the acceleration curvature A = alpha W2^T diag(w) W2 (alpha, beta: the terms' curvatures times
    their weights over their renormalization scales). The preconditioner can only assume a multiple
    w A along radial directions; their ratio over the free frames' modes spans a wide range (about
    20 to 800 for the figure: values outweigh accelerations most at low frequency), and the largest w
    with w A <= G on every mode is the smallest generalized eigenvalue of (G, A). This removes the
    unit term's stiff radial directions (most of the ill-conditioning on the figure: the condition
    number of the preconditioned Hessian 1.2e4 -> 950 on run-and-step's gait) without assuming more
    curvature than there is on any mode.

    Args:
        objective: the round's Objective (weights and scales as optimized). frames: FrameSet.
        H: (m, m) the Hessian of integral |Y''|^2 dt per component (2 W2^T diag(w) W2).
    Returns:
        (w, quat_slots (s, 4)); (1.0, ()) where no term declares both curvatures or no quaternion
        is free.
    """
    alpha = beta = 0.0
    slots = []
    for term, lam, scale in zip(objective.terms, objective.weights, objective.scales):
        c = lam / scale
        alpha += c * term.acceleration_curvature
        if term.radial_curvature and term.radial_slots is not None and c > 0:
            beta += c * term.radial_curvature
            slots.append(np.asarray(term.radial_slots, dtype=int).reshape(-1, 4))
    if not (alpha > 0 and beta > 0):
        return 1.0, ()
    slots = np.unique(np.concatenate(slots), axis=0)
    rows = np.flatnonzero(frames.free[:, slots].all(axis=2).any(axis=1))
    if rows.size == 0:
        return 1.0, ()
    basis = objective.basis(frames.times)
    G = beta * basis.gram(0, objective.h if basis.weights is None else basis.weights)[np.ix_(rows, rows)]
    R = _upper_factor(0.5 * alpha * H[np.ix_(rows, rows)])  # A = alpha/2 H
    M = solve_triangular(R, solve_triangular(R, G, trans="T").T, trans="T")  # R^-T G R^-1
    lam_min = float(np.linalg.eigvalsh(0.5 * (M + M.T))[0])
    return (lam_min if np.isfinite(lam_min) and lam_min > 0 else 1.0), slots


def _upper_factor(Hg: np.ndarray) -> np.ndarray:
    """R upper triangular with R^T R = Hg + ridge; directions the acceleration does not see get the
    identity (two frames: the spline is a line, Y'' = 0, H = 0, and the ridge alone would scale the
    first step by ~1e150 - an overflow)."""
    Hg = Hg.copy()
    d = np.diag(Hg).copy()
    flat = d <= 1e-12 * d.max(initial=0.0)
    if flat.any():
        Hg[flat, :] = 0.0
        Hg[:, flat] = 0.0
        Hg[flat, flat] = d[~flat].mean() if (~flat).any() else 1.0
    Hg.flat[:: len(Hg) + 1] += 1e-10 * np.trace(Hg) / len(Hg) + 1e-300  # the diagonal
    return np.linalg.cholesky(Hg).T  # Hg = L L^T, R = L^T
