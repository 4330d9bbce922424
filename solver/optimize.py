"""The one wrapper around nlopt: gradient-based, unconstrained, every iterate a valid path.

Paper sec. 2, "Minimization of the objective": the variable frames move to minimize E; the keyframes
are not variables, so any iterate meets them and can be returned at any time (figure 1). We keep the
best iterate seen; a stop request (Ctrl-C, a time limit), a non-finite objective, or an exception in
the objective ends the run and returns that best iterate with a status saying why.
"""
from __future__ import annotations

import enum
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import nlopt
import numpy as np

from solver.errors import InputError

#: Gradient-based local algorithms offered by name (nlopt's documentation, "NLopt Algorithms").
ALGORITHMS = {
    "lbfgs": nlopt.LD_LBFGS,
    "mma": nlopt.LD_MMA,
    "ccsaq": nlopt.LD_CCSAQ,
    "slsqp": nlopt.LD_SLSQP,
    "tnewton": nlopt.LD_TNEWTON_PRECOND_RESTART,
    "var2": nlopt.LD_VAR2,
}


#: [1] The relative-decrease stopping test of a plain `minimize` (and of `solve`'s rounds unless the options
#: say otherwise): 1e-7, of the order of the square root of double precision's 2.2e-16, the usual floor of
#: a relative-decrease test (Gill, Murray & Wright, Practical Optimization, 1981, ch. 8, termination criteria).
FTOL_REL = 1e-7

#: [doubles] nlopt's luksan/luksan.h MEMAVAIL: the scratch memory its L-BFGS sizes its default storage by.
_LUKSAN_MEMAVAIL = 1310720


def lbfgs_storage(n: int) -> int:
    """Correction pairs nlopt's L-BFGS (Luksan's PLIS) keeps for n variables.

    nlopt's default is max(MEMAVAIL // n, 10) pairs, and PLIS allocates and zeroes 2 n doubles per pair
    on every call: ~21 MB whatever n is; 1.9 MB for the orientation problem's ~120 variables with the
    earlier cap of 1000 pairs, still ~0.4 ms of a ~5 ms `orient` call (with the caches it evicts). A run
    uses min(iterations, pairs) pairs, so a run of at most `lbfgs_storage(n)` iterations has the same
    iterates as with the default. Here: at most 1000 pairs, and at most max(n, 200): n pairs (2n
    rank-one terms) can already span the whole n x n inverse-Hessian update, so more only repeat older
    curvature. Problems with n >= ~1300 variables (the figure's) keep nlopt's own default.

    Args:
        n: number of variables, >= 1.
    Returns:
        pairs to pass to `nlopt.opt.set_vector_storage`.
    """
    return min(max(_LUKSAN_MEMAVAIL // n, 10), 1000, max(n, 200))


class Status(enum.Enum):
    """Why an optimization ended."""

    CONVERGED = "converged"  # ftol/xtol reached, or no progress possible (roundoff)
    MAX_EVALS = "max_evals"
    MAX_TIME = "max_time"
    INTERRUPTED = "interrupted"  # stop requested (Ctrl-C) by the caller
    NONFINITE = "nonfinite"  # the objective or its gradient was NaN/inf; best finite iterate kept
    FAILED = "failed"  # nlopt reported a failure
    NOTHING_TO_DO = "nothing_to_do"  # no free variables
    INFEASIBLE = "infeasible"  # the least change converged with limits the keyframes leave out of reach raised


_NLOPT_STATUS = {
    nlopt.SUCCESS: Status.CONVERGED,
    nlopt.STOPVAL_REACHED: Status.CONVERGED,
    nlopt.FTOL_REACHED: Status.CONVERGED,
    nlopt.XTOL_REACHED: Status.CONVERGED,
    nlopt.MAXEVAL_REACHED: Status.MAX_EVALS,
    nlopt.MAXTIME_REACHED: Status.MAX_TIME,
}


@dataclass(frozen=True)
class OptimizeResult:
    """The outcome of `minimize`.

    Attributes:
        x: (n,) best iterate found (never worse than x0).
        fun: objective at x.
        status: Status. message: human-readable reason.
        n_evals: objective+gradient evaluations.
        n_improvements: evaluations that improved on the best so far (accepted iterates).
        trace: (n_evals,) best objective so far after each evaluation.
        wall_time_s: [s].
        algorithm: the nlopt algorithm's name.
        grad: (n,) gradient of the minimized function at x, in the optimizer's variables (those of
            `fun`: for `solve`'s preconditioned rounds the z of `AccelerationPreconditioner`), or None
            (x never evaluated with a gradient). Kept so that a caller can check stationarity without
            another evaluation (`solver.paper.orient_refine`).
        fun_time_s: [s] wall time spent in `fun` (value and gradient, in the optimizer's variables).
            wall_time_s - fun_time_s is the optimizer's own work and this wrapper's: for nlopt's L-BFGS
            O(n k) per iteration with k <= `lbfgs_storage(n)` stored pairs (measured: ~5 ms an iteration
            at n = 1326, k = 300; docs/contacts.md "Known limits").
    """

    x: np.ndarray
    fun: float
    status: Status
    message: str
    n_evals: int
    n_improvements: int
    trace: np.ndarray
    wall_time_s: float
    algorithm: str
    grad: np.ndarray | None = None
    fun_time_s: float = 0.0

    @property
    def ok(self) -> bool:
        return self.status not in (Status.FAILED, Status.NONFINITE)


class Stop(Exception):
    """Raise from an objective to stop the optimization and keep the best iterate.

    Attributes: status (Status.NONFINITE or INTERRUPTED), message."""

    def __init__(self, status: Status, message: str):
        super().__init__(message)
        self.status = status
        self.message = message


class _Guarded:
    """nlopt's objective around `fun`: applies the limits and the stop request, keeps the best iterate
    and the trace, and turns an exception into a forced stop (nlopt cannot unwind a Python exception)."""

    def __init__(self, fun, opt, t_start: float, max_evals: int, max_time_s: float, should_stop, callback):
        self.fun, self.opt, self.t_start = fun, opt, t_start
        self.max_evals, self.max_time_s = max_evals, max_time_s
        self.should_stop, self.callback = should_stop, callback
        self.best = {"x": None, "f": np.inf, "n": 0, "imp": 0, "t": 0.0}
        self.trace: list[float] = []
        self.stop: dict = {}

    def _checked(self, x, need_grad: bool):
        if self.should_stop is not None and self.should_stop():
            raise Stop(Status.INTERRUPTED, "stopped on request")
        if self.max_time_s and time.perf_counter() - self.t_start > self.max_time_s:
            raise Stop(Status.MAX_TIME, f"time limit of {self.max_time_s:g} s reached")
        if self.max_evals and self.best["n"] >= self.max_evals:
            raise Stop(Status.MAX_EVALS, f"evaluation limit of {self.max_evals} reached")
        t_fun = time.perf_counter()
        f, g = self.fun(x, need_grad)  # under errstate(all="ignore"), set around opt.optimize
        self.best["t"] += time.perf_counter() - t_fun
        if not math.isfinite(f) or (need_grad and not np.isfinite(g).all()):
            raise Stop(Status.NONFINITE, "the objective or its gradient is not finite")
        return f, g

    def __call__(self, x, grad):
        best = self.best
        if not self.stop:
            try:
                f, g = self._checked(x, grad.size > 0)
            except Stop as s:
                self.stop["status"], self.stop["message"] = s.status, s.message
            except BaseException as e:  # noqa: BLE001 - re-raised after nlopt unwinds
                self.stop["status"], self.stop["message"], self.stop["error"] = Status.FAILED, repr(e), e
        if self.stop:
            self.opt.force_stop()
            return best["f"] if np.isfinite(best["f"]) else 0.0
        if grad.size:
            grad[:] = g
        best["n"] += 1
        if f < best["f"]:
            best["f"], best["x"], best["imp"] = float(f), x.copy(), best["imp"] + 1
            best["g"] = grad.copy() if grad.size else None
        self.trace.append(best["f"])
        if self.callback is not None:
            self.callback(best["n"], best["f"])
        return float(f)


def _run_nlopt(opt, x0: np.ndarray, algorithm: str, max_evals: int, max_time_s: float) -> tuple[Status, str]:
    """opt.optimize(x0) and nlopt's ending as (Status, message); a forced stop reads as converged here
    (the caller replaces it with the guard's reason)."""
    try:
        # a trial point may overflow: reported by status (NONFINITE), not as numpy warnings. Set once
        # here, not per evaluation (the context manager costs ~3 us, a few % of a small evaluation)
        with np.errstate(all="ignore"):
            opt.optimize(x0)
        code = opt.last_optimize_result()
        status = _NLOPT_STATUS.get(code, Status.FAILED)
        return status, {Status.CONVERGED: "converged (tolerance reached)", Status.MAX_EVALS:
                        f"evaluation limit of {max_evals} reached", Status.MAX_TIME:
                        f"time limit of {max_time_s:g} s reached"}.get(status, f"nlopt code {code}")
    except nlopt.RoundoffLimited:
        return Status.CONVERGED, "converged (no further progress possible: roundoff-limited)"
    except nlopt.ForcedStop:
        return Status.CONVERGED, "converged"
    except Exception as e:  # nlopt's SWIG runtime_error is not a RuntimeError subclass
        detail = f" ({e})" if str(e) else ""
        return Status.FAILED, (f"nlopt {algorithm} stopped with a generic failure "
                               f"({type(e).__name__}{detail}); another algorithm may get further")


def minimize(
    fun: Callable[[np.ndarray, bool], tuple[float, np.ndarray | None]],
    x0: np.ndarray,
    *,
    algorithm: str = "lbfgs",
    ftol_rel: float = FTOL_REL,
    xtol_rel: float = 0.0,
    max_evals: int = 0,
    max_time_s: float = 0.0,
    should_stop: Callable[[], bool] | None = None,
    callback: Callable[[int, float], None] | None = None,
    pairs: int | None = None,
) -> OptimizeResult:
    """Minimize fun from x0 with an nlopt gradient-based algorithm.

    Args:
        fun: fun(x, need_grad) -> (value, gradient (n,) or None). May raise `Stop`.
        x0: (n,) start.
        algorithm: a key of `ALGORITHMS`.
        ftol_rel, xtol_rel: nlopt relative tolerances (0 = off).
        max_evals: evaluation limit (0 = none). max_time_s: wall-time limit [s] (0 = none).
        should_stop: polled at each evaluation; True stops with Status.INTERRUPTED.
        callback: called as callback(n_evals, best_value) after each evaluation (progress display).
        pairs: L-BFGS correction pairs to keep (None: `lbfgs_storage(n)`).
    Returns:
        OptimizeResult with the best iterate.
    Raises:
        InputError: unknown algorithm (lists the valid ones), negative limits.
        Any exception other than `Stop` raised by fun, after the optimizer is stopped.
    """
    if algorithm not in ALGORITHMS:
        raise InputError(f"unknown algorithm {algorithm!r}; choose one of: {', '.join(ALGORITHMS)}")
    if max_evals < 0 or max_time_s < 0 or ftol_rel < 0 or xtol_rel < 0:
        raise InputError("optimizer limits and tolerances must be >= 0")
    x0 = np.asarray(x0, dtype=float).copy()
    t_start = time.perf_counter()
    if x0.size == 0:
        f0, _ = fun(x0, False)
        wall = time.perf_counter() - t_start
        return OptimizeResult(x0, float(f0), Status.NOTHING_TO_DO, "no free variables", 1, 0,
                              np.array([f0]), wall, algorithm, fun_time_s=wall)

    opt = nlopt.opt(ALGORITHMS[algorithm], x0.size)
    if algorithm == "lbfgs":
        opt.set_vector_storage(int(pairs) if pairs else lbfgs_storage(x0.size))
    guard = _Guarded(fun, opt, t_start, max_evals, max_time_s, should_stop, callback)
    opt.set_min_objective(guard)
    for setter, value in ((opt.set_ftol_rel, ftol_rel), (opt.set_xtol_rel, xtol_rel),
                          (opt.set_maxeval, int(max_evals)), (opt.set_maxtime, float(max_time_s))):
        if value:
            setter(value)
    status, message = _run_nlopt(opt, x0, algorithm, max_evals, max_time_s)
    stop, best = guard.stop, guard.best
    if stop:
        status, message = stop["status"], stop["message"]
        if "error" in stop:
            raise stop["error"]
    if not np.isfinite(best["f"]):  # not a single finite evaluation: report x0 as it is
        best["x"] = x0
    return OptimizeResult(best["x"], best["f"], status, message, best["n"], best["imp"],
                          np.array(guard.trace), time.perf_counter() - t_start, algorithm, best.get("g"), best["t"])
