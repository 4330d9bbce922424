"""The Levenberg-Marquardt back end of `solve` (`lm_backend`, `SolveOptions.backend = "lm"`).

Gauss-Newton on the terms' residuals (`Term.residual`) with Levenberg-Marquardt damping, in the free
B-spline coefficients of `solver.least_squares` (a banded J^T J); iterates are frame sets, so every
iterate meets the keyframes exactly, and the best one is kept (a step is only taken when it lowers E).

Each iteration solves (J^T J + mu D) h = -J^T rho with D = diag(J^T J) (Marquardt's scaling), evaluates
E at the step (value only) and compares the actual decrease with the model's, the gain ratio
rho_g = (E(x) - E(x + h)) / (L(0) - L(h)). The damping update is Nielsen's (Madsen, Nielsen & Tingleff,
"Methods for non-linear least squares problems", 2nd ed. 2004, sec. 3.2, eq. 3.15 and algorithm
3.16): on a decrease mu *= max(1/3, 1 - (2 rho_g - 1)^3) and nu = 2; otherwise mu *= nu, nu *= 2.
A step that makes E non-finite counts as a failed step.

Kept Jacobians and secant pairs: after an accepted step with gain ratio >= LAG_GAIN the next step keeps
J^T J and takes the exact gradient of the trial evaluation, while its model predicts enough (LAG_...);
every accepted step's (step, change of the exact gradient) pair corrects the model by limited-memory
BFGS seeded with (J^T J + mu D)^-1 (`solver.least_squares.secant_solve`; Madsen et al. sec. 3.5, the
hybrid for residuals that stay large, where Gauss-Newton alone converges only linearly).

Stopping (`Tail`): the decrease still to come, predicted from the decreases between the last Jacobians
(a geometric tail), at most `ftol_rel` of E (the round's tolerance, the one nlopt's L-BFGS gets, so
`--ftol` means the same for both back ends); damping grown past MU_MAX without a decrease (no descent
left at rounding level); a step shorter than 1e-12 of |x| (Madsen et al.'s small-step test); the
evaluation or time budget (their iteration limit), or a stop request.

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
#: After an accepted step whose gain ratio is at least LAG_GAIN, the next step keeps J^T J and takes the
#: exact gradient of the trial evaluation (at most MAX_LAG steps in a row; module docstring), if its
#: model predicts a decrease of at least LAG_MIN_PREDICTION of the last fresh Jacobian's step (a
#: Jacobian costs 10-20 evaluations) and of at least the round's tolerance.
LAG_GAIN = 0.25
MAX_LAG = 20
LAG_MIN_PREDICTION = 0.05
#: Secant pairs of the last accepted steps that correct the Gauss-Newton model (`secant_solve`); 0: none.
SECANT_PAIRS = 5
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
        ftol_rel: the round's tolerance: stop when the decrease of E still predicted (`Tail`) is at most
            this fraction of E.
        max_evals: evaluation budget (0 = none). max_time_s: [s] time budget (0 = none).
        should_stop: polled between evaluations; True ends the run (INTERRUPTED, best x kept).
        callback: callback(n_evals, E) after every evaluation, or None.
        timings: if a dict, receives the seconds spent in "jacobian" (residuals, Jacobian blocks and
            the assembly of J^T J; wall), "factor" (damped solves) and "trial" (value evaluations at
            steps), "n_jacobians" (how many), "steps" (one dict per trial step: E before and after,
            predicted decrease, damping, gain ratio, kept Jacobians in a row), and the CPU seconds of
            the assembly's parts (`normal_equations`: "residuals", "blocks", "gram", "band").
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
    if not (math.isfinite(ne.E) and np.all(np.isfinite(ne.g))):
        return run.result(x, ne.E, Status.NONFINITE, "the residuals are not finite at the start", 0, t_start)
    state = _State(x, ne.E, ne, Tail(ftol_rel))
    state.tail.jacobian(ne.E)
    state.budget = lambda: _budget(len(run.trace), max_evals, t_start, max_time_s, should_stop)
    while True:
        stop = state.budget()
        if stop is None:
            stop = _iterate(run, state)
        if stop is not None:
            status, message = stop
            break
    return run.result(state.x, state.F, status, message, state.improvements, t_start)


class _State:
    """The iterate of `levenberg_marquardt`: x (n_free,), F = E(x), the normal equations `ne` (fresh, or
    kept with `lag` steps since the last Jacobian), the damping mu and its factor nu (Nielsen's update),
    the scaled length of the last failed step (inf after a success), accepted steps, and the `Tail`."""

    def __init__(self, x, F, ne, tail):
        self.x, self.F, self.ne, self.tail = x, F, ne, tail
        self.mu, self.nu, self.lag, self.failed, self.improvements = TAU, 2.0, 0, math.inf, 0
        self.fresh_decrease = 0.0  # of the last accepted step taken with a fresh Jacobian
        self.budget = lambda: None  # (status, message) once a budget is spent or a stop requested
        self.grad = ne.g  # J^T rho at x (exact: from the Jacobian or the trial evaluation)
        self.pairs: list = []  # secant pairs (step, change of J^T rho), oldest first

    def secant(self, h, g_old, g_new):
        """Keep the pair (h, g_new - g_old) of an accepted step if its curvature is positive (at most
        SECANT_PAIRS); g_new None (no gradient) keeps nothing."""
        if g_new is None or not SECANT_PAIRS:
            return
        y = g_new - g_old
        if y @ h > 1e-12 * np.sqrt((y @ y) * (h @ h)):
            self.pairs = [*self.pairs, (h, y)][-SECANT_PAIRS:]
        self.grad = g_new

    def raise_damping(self):
        """mu *= nu, nu *= 2 (Madsen et al. algorithm 3.16); True if mu passed MU_MAX."""
        self.mu, self.nu = self.mu * self.nu, self.nu * 2.0
        return self.mu > MU_MAX


def _iterate(run, st):
    """One damped step of `levenberg_marquardt` from `st` (updated in place). Returns None to go on,
    or (status, message) to stop."""
    h, pred = run.step(st.ne, st.mu)
    if st.lag and (h is None or not max(LAG_MIN_PREDICTION * st.fresh_decrease, st.tail.tol * st.F) <= pred < st.F):
        return _refresh(run, st)  # the kept model is no least-squares model here, or it predicts little
    length = st.ne.scaled_norm(h) if h is not None else math.inf
    if h is None or not pred > 0 or length > SHRINK * st.failed:  # not solvable, or not yet shorter
        return (Status.CONVERGED, "converged (no descent left at this damping)") if st.raise_damping() else None
    dx = run.local.E @ h
    if np.linalg.norm(dx) <= 1e-12 * (np.linalg.norm(st.x) + 1e-12):
        return Status.CONVERGED, "converged (step below rounding)"
    F_new, g_new = run.trial(st.x + dx)
    grad_old = st.grad
    gain = (st.F - F_new) / pred if math.isfinite(F_new) else -math.inf
    run.note(F=st.F, F_new=F_new, pred=pred, mu=st.mu, gain=gain, lag=st.lag)
    if not gain > 0:
        if st.lag:  # a kept J^T J's failure says nothing about the damping: retry with a fresh Jacobian
            return _refresh(run, st)
        st.failed = length
        return (Status.CONVERGED, "converged (no decrease left at this damping)") if st.raise_damping() else None
    if not st.lag:
        st.fresh_decrease = st.F - F_new
    st.x, st.F, st.improvements, st.failed = st.x + dx, F_new, st.improvements + 1, math.inf
    st.secant(h, grad_old, g_new)
    st.mu, st.nu = st.mu * max(MIN_FACTOR, 1.0 - (2.0 * gain - 1.0) ** 3), 2.0
    if gain >= LAG_GAIN and st.lag < MAX_LAG:
        st.ne, st.lag = st.ne.lagged(h, g_new, F_new), st.lag + 1
        st.ne.pairs = tuple(st.pairs)
        return None
    return _refresh(run, st)


def _refresh(run, st):
    """A fresh Jacobian at st.x, unless the `Tail` test says the round is done. Returns None or
    (status, message)."""
    remaining = st.tail.remaining(st.F)
    if remaining <= st.tail.tol * st.F:
        return Status.CONVERGED, f"converged (predicted decrease {remaining / st.F:.1e} of E <= ftol)"
    spent = st.budget()
    if spent is not None:  # no Jacobian that no step would use
        return spent
    st.ne, st.lag = run.jacobian(st.x), 0
    if not (math.isfinite(st.ne.E) and np.all(np.isfinite(st.ne.g))):
        return Status.NONFINITE, "the residuals' Jacobian is not finite"
    st.grad, st.ne.pairs = st.ne.g, tuple(st.pairs)
    st.tail.jacobian(st.F)
    return None


class Tail:
    """The stopping test of a Levenberg-Marquardt round: the decrease of E still to come, predicted from
    the decreases between successive Jacobians.

    Madsen, Nielsen & Tingleff ("Methods for non-linear least squares problems", 2004, sec. 3.2) stop on a
    small gradient, a small step or an iteration budget; Nocedal & Wright (sec. 10.3) note that on
    large-residual problems Levenberg-Marquardt converges only linearly. With linear convergence the
    decreases d_k between successive Jacobians fall geometrically, d_k+1 = c d_k, and what is left after
    d_k is d_k c / (1 - c). The rate c is the larger of the last two ratios d_k / d_k-1 (an overestimate
    stops later, not earlier); where it is not below 1, nothing is predicted (the round goes on). The
    test does not look at the damping: a heavily damped round with steadily falling decreases stops
    too; nor at the steps that keep a Jacobian (they are parts of one decrease d_k), so a short step of a
    stale model cannot end the round.

    Args:
        tol: the round's relative tolerance (`SolveOptions.ftol_rel`, the one nlopt gets).
    """

    def __init__(self, tol: float):
        self.tol = tol
        self.E: list[float] = []  # E at each fresh Jacobian

    def jacobian(self, E: float) -> None:
        """A fresh Jacobian was taken where the objective is E."""
        self.E.append(E)

    def remaining(self, E: float) -> float:
        """The decrease predicted after the current point, where the objective is E (<= the last one
        given to `jacobian`); inf until three decreases are known or while they do not fall."""
        d = -np.diff(np.r_[self.E[-3:], E])
        if len(d) < 3 or np.any(d <= 0):
            return math.inf
        c = max(d[-1] / d[-2], d[-2] / d[-3])
        return d[-1] * c / (1.0 - c) if c < 1.0 else math.inf


class _Run:
    """The bookkeeping of one `levenberg_marquardt` call: the evaluation trace (best E after each
    evaluation), the callback, and the time spent in Jacobians, damped solves and trial evaluations."""

    def __init__(self, objective, frames, local, callback, timings):
        self.objective, self.frames, self.local = objective, frames, local
        self.callback, self.timings = callback, timings
        self.clock = {"jacobian": 0.0, "factor": 0.0, "trial": 0.0, "n_jacobians": 0}
        self.trace: list[float] = []
        self.steps: list[dict] = []

    def note(self, **step) -> None:
        """Record one trial step (E before and after, predicted decrease, damping, gain ratio, kept
        Jacobians in a row) in `timings["steps"]`."""
        if self.timings is not None:
            self.steps.append(step)

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
            self.timings["steps"] = self.steps
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
