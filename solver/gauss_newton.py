"""The Levenberg-Marquardt back end of `solve` (`lm_backend`, `SolveOptions.backend = "lm"`).

Gauss-Newton on the terms' residuals (`Term.residual`) with Levenberg-Marquardt damping, in the free
B-spline coefficients of `solver.least_squares` (a banded J^T J); iterates are frame sets, so every
iterate meets the keyframes exactly, and the best one is kept (a step is only taken when it lowers E).

Each iteration solves (J^T J + mu D) h = -J^T rho with D = diag(J^T J) (Marquardt's scaling), evaluates
E at the step (value only) and compares the actual decrease with the model's, the gain ratio
rho_g = (E(x) - E(x + h)) / (L(0) - L(h)). The damping update is Nielsen's (Madsen, Nielsen & Tingleff,
"Methods for non-linear least squares problems", 2nd ed. 2004, sec. 3.2, eq. 3.15 and algorithm
3.16): on a decrease mu *= max(1/3, 1 - (2 rho_g - 1)^3) and nu = 2; otherwise mu *= nu, nu *= 2.
A step that makes E non-finite counts as a failed step. Stopping (Madsen et al. sec. 3.2 eq. 3.16
and Nocedal & Wright sec. 10.3 use the same tests): an accepted step that lowered E by at most
`ftol_rel` of E (the relative-decrease test nlopt's L-BFGS uses, so `--ftol` means the same for both
back ends), a step shorter than 1e-12 of |x|, damping grown past 1e16 without a decrease (no
descent left at rounding level), the evaluation or time budget, or a stop request.

Evaluations: each value evaluation at a trial step counts one, and each residual-and-Jacobian
evaluation at an accepted point counts one (`OptimizeResult.n_evals`).
"""
from __future__ import annotations

import math
import time

import numpy as np
from threadpoolctl import threadpool_limits

from solver.objective import NonFiniteError
from solver.optimize import OptimizeResult, Status
from solver.terms.base import Term

#: Initial damping relative to diag(J^T J) (Madsen et al. 2004 sec. 3.2: tau = 1e-3 when the start
#: may be far from the minimum).
TAU = 1e-3
#: Damping beyond which a failed step means no descent is left at rounding level.
MU_MAX = 1e16
MIN_FACTOR = 1.0 / 3.0
#: The relative-decrease test stops only after a step damped at most this much (with Marquardt's
#: scaling, mu = 1 halves the Gauss-Newton step along every eigendirection of equal curvature): a small
#: decrease of a heavily damped step says that the step was short, not that E is near its minimum.
MU_CONVERGED = 1.0
#: After an accepted step whose gain ratio is at least LAG_GAIN, the next step keeps J^T J and takes the
#: exact gradient of the trial evaluation (at most MAX_LAG steps in a row; module docstring).
LAG_GAIN = 0.5
MAX_LAG = 4
#: After a failed step the damping is raised until the step is at most this fraction of the failed one's
#: length (in the scaled norm |D^1/2 h|) before E is evaluated again: the trust-region reduction of
#: Moré ("The Levenberg-Marquardt algorithm: implementation and theory", 1978, sec. 7, the radius cut to
#: between 1/10 and 1/2 of the failed step); a raise that leaves the step as it was (mu far below the
#: curvature) costs a damped solve, not an evaluation.
SHRINK = 0.5


def has_residuals(objective) -> bool:
    """True if every weighted term of `objective` gives a residual form (`Term.residual` overridden)
    and the objective is not the orientation problem's fused pass (which `solve` leaves to nlopt)."""
    if getattr(objective, "fused_orientation", False):
        return False
    return all(type(t).residual is not Term.residual for t, w in zip(objective.terms, objective.weights) if w != 0)


def lm_backend(objective, frames, options, remaining, should_stop, progress, evals_before) -> OptimizeResult:
    """`solver.backend.Backend`: `levenberg_marquardt` on the round; objectives with a term that is not
    a sum of squares (or the orientation problem) go to `nlopt_backend` instead.

    Returns: OptimizeResult (see `Backend`); `algorithm` "lm" (or nlopt's where it fell back).
    """
    from solver.backend import nlopt_backend

    if not has_residuals(objective):
        return nlopt_backend(objective, frames, options, remaining, should_stop, progress, evals_before)

    def report(n, f):
        progress("eval", {"evals": evals_before + n, "E": f})

    with threadpool_limits(1):  # the Jacobian's dense products are small: BLAS threads only add contention
        return levenberg_marquardt(objective, frames, ftol_rel=options.ftol_rel, max_evals=options.max_evals,
                                   max_time_s=remaining, should_stop=should_stop,
                                   callback=report if progress else None)


def levenberg_marquardt(objective, frames, ftol_rel: float = 1e-7, max_evals: int = 0, max_time_s: float = 0.0,
                        should_stop=None, callback=None, timings: dict | None = None) -> OptimizeResult:
    """Minimize `objective` over the free components of `frames` by Levenberg-Marquardt (module docstring).

    Args:
        objective: Objective whose weighted terms all give `Term.residual`. frames: FrameSet (start).
        ftol_rel: stop after an accepted step that lowered E by at most this fraction of E.
        max_evals: evaluation budget (0 = none). max_time_s: [s] time budget (0 = none).
        should_stop: polled between evaluations; True ends the run (INTERRUPTED, best x kept).
        callback: callback(n_evals, E) after every evaluation, or None.
        timings: if a dict, receives the seconds spent in "jacobian" (residuals, Jacobian blocks and
            the assembly of J^T J; wall), "factor" (damped solves) and "trial" (value evaluations at
            steps), "n_jacobians" (how many), and the CPU seconds of the assembly's parts (`normal_equations`: "residuals",
            "blocks", "gram", "band").
    Returns:
        OptimizeResult with x (n_free,) the best frame values found, algorithm "lm".
    Raises:
        solver.least_squares.NoResidualError: a weighted term without a residual form.
    """
    from solver.least_squares import LocalSpline

    t_start = time.perf_counter()
    x = frames.x()
    if x.size == 0:
        return OptimizeResult(x, math.nan, Status.NOTHING_TO_DO, "no free variables", 0, 0, np.zeros(0), 0.0, "lm")
    run = _Run(objective, frames, LocalSpline(frames, objective.basis(frames.times).t), callback, timings)
    ne = run.jacobian(x)
    F, improvements = ne.E, 0
    if not (math.isfinite(F) and np.all(np.isfinite(ne.g))):
        return run.result(x, F, Status.NONFINITE, "the residuals are not finite at the start", improvements, t_start)
    mu, nu, lag, failed = TAU, 2.0, 0, math.inf  # failed: scaled length of the last failed step
    status, message = Status.CONVERGED, "converged"
    while True:
        stop = _budget(len(run.trace), max_evals, t_start, max_time_s, should_stop)
        if stop is not None:
            status, message = stop
            break
        h, pred = run.step(ne, mu)
        if lag and (h is None or not 0 < pred < F):  # the kept J^T J's model is no least-squares model here
            ne, lag = run.jacobian(x), 0
            continue
        length = ne.scaled_norm(h) if h is not None else math.inf
        if h is None or not pred > 0 or length > SHRINK * failed:  # not solvable, or not yet shorter
            mu, nu = mu * nu, nu * 2.0
            if mu > MU_MAX:
                message = "converged (no descent left at this damping)"
                break
            continue
        dx = run.local.E @ h
        if np.linalg.norm(dx) <= 1e-12 * (np.linalg.norm(x) + 1e-12):
            message = "converged (step below rounding)"
            break
        F_new, g_new = run.trial(x + dx)
        gain = (F - F_new) / pred if math.isfinite(F_new) else -math.inf
        if gain > 0:
            decrease, step_mu, failed = F - F_new, mu, math.inf
            x, F, improvements = x + dx, F_new, improvements + 1
            mu, nu = mu * max(MIN_FACTOR, 1.0 - (2.0 * gain - 1.0) ** 3), 2.0
            if decrease <= ftol_rel * abs(F + decrease) and step_mu <= MU_CONVERGED:
                break  # on a kept J^T J's step too, as nlopt's test on L-BFGS's steps (an approximate Hessian)
            if _budget(len(run.trace), max_evals, t_start, max_time_s, should_stop) is not None:
                continue  # the loop's test reports it
            if gain >= LAG_GAIN and lag < MAX_LAG:
                ne, lag = ne.lagged(h, g_new, F), lag + 1
                continue
            ne, lag = run.jacobian(x), 0
            if not (math.isfinite(ne.E) and np.all(np.isfinite(ne.g))):
                status, message = Status.NONFINITE, "the residuals' Jacobian is not finite"
                break
        elif lag:
            ne, lag = run.jacobian(x), 0
        else:
            failed, mu, nu = length, mu * nu, nu * 2.0
            if mu > MU_MAX:
                message = "converged (no decrease left at this damping)"
                break
    return run.result(x, F, status, message, improvements, t_start)


class _Run:
    """The bookkeeping of one `levenberg_marquardt` call: the evaluation trace (best E after each
    evaluation), the callback, and the time spent in Jacobians, damped solves and trial evaluations."""

    def __init__(self, objective, frames, local, callback, timings):
        self.objective, self.frames, self.local = objective, frames, local
        self.callback, self.timings = callback, timings
        self.clock = {"jacobian": 0.0, "factor": 0.0, "trial": 0.0, "n_jacobians": 0}
        self.trace: list[float] = []

    def count(self, E: float) -> None:
        self.trace.append(min(self.trace[-1], E) if self.trace else E)
        if self.callback is not None:
            self.callback(len(self.trace), E)

    def jacobian(self, x):
        """The normal equations (`solver.least_squares.normal_equations`) at the free values x; counts one."""
        from solver.least_squares import normal_equations

        t0 = time.perf_counter()
        ne = normal_equations(self.objective, self.frames.with_x(x), self.local, self.timings)
        self.clock["jacobian"] += time.perf_counter() - t0
        self.clock["n_jacobians"] += 1
        self.count(ne.E if math.isfinite(ne.E) else math.inf)
        return ne

    def step(self, ne, mu: float):
        """(h, predicted decrease) of the damped step, or (None, 0) where the damped system cannot be solved."""
        from numpy.linalg import LinAlgError

        t0 = time.perf_counter()
        try:
            h, pred = ne.step(mu)
        except (LinAlgError, ValueError):
            h, pred = None, 0.0
        self.clock["factor"] += time.perf_counter() - t0
        return h, pred

    def trial(self, x):
        """`_trial` at the free values x, timed and counted."""
        t0 = time.perf_counter()
        F, g = _trial(self.objective, self.frames, x, self.local)
        self.clock["trial"] += time.perf_counter() - t0
        self.count(F)
        return F, g

    def result(self, x, F, status, message, improvements, t_start) -> OptimizeResult:
        if self.timings is not None:
            self.timings.update(self.clock)
        wall = time.perf_counter() - t_start
        return OptimizeResult(np.array(x), float(F), status, message, len(self.trace), improvements,
                              np.array(self.trace), wall, "lm", None, self.clock["jacobian"] + self.clock["trial"])


def _trial(objective, frames, x, local) -> tuple[float, np.ndarray | None]:
    """(E, J^T rho in the free coefficients (half of dE / d xi)) at the free values x; (inf, None)
    where E or its gradient is not finite."""
    try:
        ev = objective.evaluate(frames.times, frames.values_from_x(x), grad=True)
    except NonFiniteError:
        return math.inf, None
    if not math.isfinite(ev.E):
        return math.inf, None
    return ev.E, 0.5 * (local.E.T @ ev.grad[frames.free])


def _budget(n_evals, max_evals, t_start, max_time_s, should_stop):
    """(status, message) if a budget is spent or a stop was requested, else None."""
    if should_stop is not None and should_stop():
        return Status.INTERRUPTED, "stopped on request"
    if max_evals and n_evals >= max_evals:
        return Status.MAX_EVALS, f"{max_evals} evaluations reached"
    if max_time_s and time.perf_counter() - t_start >= max_time_s:
        return Status.MAX_TIME, f"time limit of {max_time_s:g} s reached"
    return None
