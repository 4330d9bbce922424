"""Optimization of one round in the preconditioned variables (`optimize_round`, used by `solver.paper.backend.nlopt_backend`)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from solver.objective import NonFiniteError
from solver.optimize import OptimizeResult, Status, Stop, minimize
from solver.paper.precondition import AccelerationPreconditioner
from solver.terms.covariant import unit_and_normalized


def optimize_round(objective, frames, options, remaining, should_stop, progress, evals_before) -> OptimizeResult:
    """One round of `solve`: nlopt moves the free components of `frames` to minimize `objective`, in the
    preconditioned variables z (`AccelerationPreconditioner`) when `options.precondition`.

    Args:
        objective: Objective. frames: FrameSet (its free components are the variables). options:
            SolveOptions (algorithm, ftol_rel, max_evals, precondition, radial_weight, quat_slots).
        remaining: time left [s] (0 = no limit). should_stop: callable or None. progress: callable(event,
            info) or None, told of every evaluation. evals_before: evaluations of earlier rounds.
    Returns:
        OptimizeResult with x in the frame variables (`frames.values_from_x`).
    """
    knots = frames.times

    def fun(x, need_grad):
        P = frames.values_from_x(x)
        try:
            ev = objective.evaluate(knots, P, grad=need_grad)
        except NonFiniteError as e:
            raise Stop(Status.NONFINITE, str(e)) from e
        return ev.E, (ev.grad[frames.free] if need_grad else None)

    def report(n, f):
        progress("eval", {"evals": evals_before + n, "E": f})

    cb = report if progress else None

    x0 = frames.x()
    if not options.precondition or x0.size == 0:
        return minimize(
            fun, x0, algorithm=options.algorithm, ftol_rel=options.ftol_rel,
            max_evals=options.max_evals, max_time_s=remaining, should_stop=should_stop, callback=cb,
        )
    pre = AccelerationPreconditioner(objective, frames, options.radial_weight, options.quat_slots)
    rows = pre.whole_rows()
    radial = pre.whole_radial() if rows is not None else None
    if radial is not None and len(objective.needs) == 3 and not objective.basis(knots).banded:
        # every free component belongs to whole free frames sharing one factor: fold R^-1 into the
        # spline matrices, Y = B P0 + (B[:, rows] R^-1) Z, and skip the scatter/gather of x and z
        # (the orientation problem; the figure without partial keyframes). With a radial weight the
        # frames' radial directions U are stretched between R^-1 and the spline: X = R^-1 Z,
        # X += c (X.U) U, Y = B P0 + B[:, rows] X (the same map as `pre.apply`).
        maker = _orientation_fun if objective.fused_orientation else _whole_frames_fun
        fun_z = maker(objective, objective.basis(knots), frames, rows, pre.groups[0][2], radial)
    else:
        def fun_z(z, need_grad):
            f, g = fun(x0 + pre.apply(z), need_grad)
            return f, (pre.apply_transpose(g) if need_grad else None)

    res = minimize(
        fun_z, np.zeros_like(x0), algorithm=options.algorithm, ftol_rel=options.ftol_rel,
        max_evals=options.max_evals, max_time_s=remaining, should_stop=should_stop, callback=cb,
    )
    return replace(res, x=x0 + pre.apply(res.x))


def _whole_frames_fun(objective, basis, frames, rows, Rinv, radial):
    """fun(z, need_grad) -> (E, dE/dz) of `optimize_round` for whole free frames with one factor R^-1
    (`AccelerationPreconditioner.whole_rows`), through `Objective.evaluate_path`."""
    U, c = radial
    Brows = basis.B[:, rows]
    Bz = Brows @ Rinv if U is None else None  # (3n, r)
    Y0 = basis.B @ frames.values
    n, shape = len(basis.t), (len(rows), frames.values.shape[1])

    def fun_z(z, need_grad):
        if U is None:
            Y = Y0 + Bz @ z.reshape(shape)
        else:
            X = Rinv @ z.reshape(shape)
            Y = Y0 + Brows @ (X + (c * np.einsum("ri,ri->r", X, U))[:, None] * U)
        Yk = (Y[:n], Y[n:2 * n], Y[2 * n:])
        try:
            E, _, acc = objective.evaluate_path(basis, *Yk, grad=need_grad)
        except NonFiniteError as e:
            raise Stop(Status.NONFINITE, str(e)) from e
        if not need_grad:
            return E, None
        G = np.concatenate([np.zeros_like(Y0[:n]) if a is None else a for a in acc])
        if U is None:
            g = Bz.T @ G
        else:
            GX = Brows.T @ G
            g = Rinv.T @ (GX + (c * np.einsum("ri,ri->r", GX, U))[:, None] * U)
        if not np.all(np.isfinite(g)):
            name = objective.blame(basis, *Yk)
            raise Stop(Status.NONFINITE, str(NonFiniteError(name, "gradient")))
        return E, g.ravel()

    return fun_z


def _orientation_fun(objective, basis, frames, rows, Rinv, radial):
    """`_whole_frames_fun` for the orientation objective (`Objective.fused_orientation`: unit +
    normalized covariant acceleration of one quaternion, Gauss quadrature), component-major end to end.

    The path is formed transposed, Y^T = Y0^T + X^T B_rows^T (4, 3n), so that its (3, 4, n) view is
    what `unit_and_normalized` reads, and the kernel's (3, 4, n) gradient goes back as one (4, 3n) x
    (3n, r) product: no transposed copies of Y, Y', Y'' in and out, no per-term bookkeeping of
    `evaluate_path` (the same E and gradient to rounding; ~15% of an evaluation, docs/orient.md "Speed against the earlier methods").
    """
    U, c = radial
    Brows = basis.B[:, rows]  # (3n, r)
    BT = np.ascontiguousarray(Brows.T)
    Y0T = np.ascontiguousarray((basis.B @ frames.values).T)  # (4, 3n)
    RinvT = np.ascontiguousarray(Rinv.T)
    n, shape, w = len(basis.t), (len(rows), 4), basis.weights
    names = objective.names

    def fun_z(z, need_grad):
        (w1, w2), (s1, s2) = objective.weights, objective.scales
        c1, c2 = w1 / s1, w2 / s2
        X = Rinv @ z.reshape(shape)
        if U is not None:
            X += (c * np.einsum("ri,ri->r", X, U))[:, None] * U
        YT = X.T @ BT
        YT += Y0T
        I1, I2, D = unit_and_normalized(YT.reshape(4, 3, n).transpose(1, 0, 2), w, c1, c2, need_grad)
        for name, I in zip(names, (I1, I2)):
            if not math.isfinite(I):
                raise Stop(Status.NONFINITE, str(NonFiniteError(name, "value")))
        E = (c1 * I1 if w1 != 0.0 else 0.0) + (c2 * I2 if w2 != 0.0 else 0.0)
        if not need_grad:
            return E, None
        GX = (D.transpose(1, 0, 2).reshape(4, 3 * n) @ Brows).T  # (r, 4)
        if U is not None:
            GX = GX + (c * np.einsum("ri,ri->r", GX, U))[:, None] * U
        g = RinvT @ GX
        if not math.isfinite(float(g.sum())):  # a NaN or inf anywhere makes the sum one
            Y = YT.T
            name = objective.blame(basis, Y[:n], Y[n:2 * n], Y[2 * n:])
            raise Stop(Status.NONFINITE, str(NonFiniteError(name, "gradient")))
        return E, g.ravel()

    return fun_z
