"""The nlopt wrapper against known optima, and why it stops."""
import numpy as np
import pytest

from solver.errors import InputError
from solver.optimize import ALGORITHMS, Status, Stop, minimize


def rosenbrock(x, need_grad):
    f = float(np.sum(100 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2))
    if not need_grad:
        return f, None
    g = np.zeros_like(x)
    g[:-1] = -400 * x[:-1] * (x[1:] - x[:-1] ** 2) - 2 * (1 - x[:-1])
    g[1:] += 200 * (x[1:] - x[:-1] ** 2)
    return f, g


@pytest.mark.parametrize("algorithm", ["lbfgs", "slsqp", "tnewton"])
def test_reaches_rosenbrock_minimum(algorithm):
    res = minimize(rosenbrock, np.array([-1.2, 1.0]), algorithm=algorithm, ftol_rel=1e-14)
    np.testing.assert_allclose(res.x, 1.0, atol=1e-4)
    assert res.status is Status.CONVERGED and res.fun < 1e-8
    assert len(res.trace) == res.n_evals and np.all(np.diff(res.trace) <= 0)


def test_eval_limit_and_stop_request_keep_best_iterate():
    res = minimize(rosenbrock, np.zeros(4), max_evals=7)
    assert res.status is Status.MAX_EVALS and res.n_evals == 7
    assert res.fun == min(res.trace) and np.isclose(rosenbrock(res.x, False)[0], res.fun)
    calls = []
    res = minimize(rosenbrock, np.zeros(4), should_stop=lambda: len(calls) > 10 or calls.append(1))
    assert res.status is Status.INTERRUPTED and res.n_evals == 11
    assert np.isclose(rosenbrock(res.x, False)[0], res.fun) and res.fun < rosenbrock(np.zeros(4), False)[0]


def test_nonfinite_objective_stops_with_last_good_iterate():
    n = [0]

    def f(x, g):
        n[0] += 1
        if n[0] > 5:
            return np.nan, np.full_like(x, np.nan)
        return rosenbrock(x, g)

    res = minimize(f, np.zeros(3))
    assert res.status is Status.NONFINITE and np.isfinite(res.fun) and res.n_evals == 5
    assert np.isclose(rosenbrock(res.x, False)[0], res.fun)


def test_stop_exception_and_errors_in_objective():
    def f(x, g):
        raise Stop(Status.INTERRUPTED, "user said so")

    assert minimize(f, np.zeros(2)).message == "user said so"

    def broken(x, g):
        raise ZeroDivisionError("bug")

    with pytest.raises(ZeroDivisionError):
        minimize(broken, np.zeros(2))


def test_unknown_algorithm_lists_choices():
    with pytest.raises(InputError, match="choose one of: " + ", ".join(ALGORITHMS)):
        minimize(rosenbrock, np.zeros(2), algorithm="newton")


def test_result_keeps_the_gradient_at_the_best_iterate():
    """`OptimizeResult.grad` is the gradient the optimizer evaluated at x (a stationarity check
    without another evaluation), also when the run stops early on its evaluation limit."""
    for max_evals in (0, 7):
        res = minimize(rosenbrock, np.array([-1.2, 1.0]), ftol_rel=1e-12, max_evals=max_evals)
        _, g = rosenbrock(res.x, True)
        np.testing.assert_allclose(res.grad, g, rtol=0, atol=1e-12 * max(1.0, np.abs(g).max()))
