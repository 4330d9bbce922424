"""The default optimizer back end (solver/backend.py): one nlopt round, and the retry in the plain
variables after nlopt's generic failure with the preconditioner."""
from dataclasses import replace

import numpy as np
import pytest

import solver.paper.backend as backend_mod
from solver.frames import FrameSet
from solver.objective import Objective
from solver.optimize import OptimizeResult, Status
from solver.paper.backend import nlopt_backend
from solver.paper.solve import SolveOptions
from solver.terms.base import Term, TermEval


class Bend(Term):
    """f = |Y''|^2: zero on the straight line through the two keyframes."""

    name, needs = "bend", (0, 2)  # Y only for the objective's block size

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        return TermEval((Y2**2).sum(axis=1), dY2=2 * Y2 if grad else None)


def problem():
    """Keyframes at (0, 0) and (2, 2) [s, units] and two variable frames off the line between them."""
    t = np.array([0.0, 0.7, 1.3, 2.0])
    v = np.array([[0.0], [1.5], [0.4], [2.0]])
    key = np.array([True, False, False, True])
    return FrameSet(t, v, np.repeat(key[:, None], 1, axis=1), key), Objective([Bend()], [1.0], 0.0, 2.0, rate=100.0)


@pytest.mark.parametrize("precondition", [False, True])
def test_one_round_reaches_the_straight_line(precondition):
    fs, obj = problem()
    res = nlopt_backend(obj, fs, SolveOptions(precondition=precondition, ftol_rel=1e-14), 0.0, None, None, 0)
    np.testing.assert_allclose(fs.values_from_x(res.x)[:, 0], fs.times, atol=1e-5)  # x in frame variables
    assert res.status is Status.CONVERGED and res.n_evals == res.trace.size


def test_generic_failure_with_the_preconditioner_is_retried_in_the_plain_variables(monkeypatch):
    fs, obj = problem()
    real, calls = backend_mod.optimize_round, []

    def failing_first(objective, frames, options, remaining, should_stop, progress, evals_before):
        calls.append((options.precondition, evals_before, frames.values.copy()))
        res = real(objective, frames, options, remaining, should_stop, progress, evals_before)
        if len(calls) == 1:  # stand for nlopt's "generic failure" after a few steps
            return replace(res, status=Status.FAILED, message="nlopt failure")
        return res

    monkeypatch.setattr(backend_mod, "optimize_round", failing_first)
    first_n = real(obj, fs, SolveOptions(precondition=True, ftol_rel=1e-14), 0.0, None, None, 5).n_evals
    res = nlopt_backend(obj, fs, SolveOptions(precondition=True, ftol_rel=1e-14), 0.0, None, None, 5)
    assert [c[0] for c in calls] == [True, False]  # retried without the preconditioner
    assert calls[1][1] == 5 + first_n  # the retry's progress counts on from the first attempt
    assert res.status is Status.CONVERGED and res.grad is None
    assert res.n_evals == res.trace.size > first_n  # both attempts' evaluations and traces


def test_failure_without_the_preconditioner_is_returned(monkeypatch):
    fs, obj = problem()
    failed = OptimizeResult(fs.x(), 1.0, Status.FAILED, "nlopt failure", 1, 0, np.array([1.0]), 0.0, "fake")
    monkeypatch.setattr(backend_mod, "optimize_round", lambda *a: failed)
    assert nlopt_backend(obj, fs, SolveOptions(precondition=False), 0.0, None, None, 0) is failed
