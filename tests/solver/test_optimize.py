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


def _raw_nlopt_lbfgs(fun, x0, pairs, ftol_rel):
    """nlopt's L-BFGS called directly with `pairs` correction pairs (the reference for the storage)."""
    import nlopt

    opt = nlopt.opt(nlopt.LD_LBFGS, x0.size)
    opt.set_vector_storage(pairs)
    opt.set_ftol_rel(ftol_rel)
    evals = []

    def f(x, grad):
        v, g = fun(x, grad.size > 0)
        if grad.size:
            grad[:] = g
        evals.append(1)
        return v

    opt.set_min_objective(f)
    x = opt.optimize(x0.copy())
    return x, len(evals)


def test_lbfgs_storage_keeps_nlopts_iterates():
    """The capped storage (`lbfgs_storage`) changes nothing for runs shorter than it: a 30-variable
    Rosenbrock from a rough start takes 172 evaluations (216 with 10 pairs: the memory matters here),
    and our wrapper (200 pairs) ends at the same bits as nlopt called directly with 1000 pairs. Large
    problems keep nlopt's own default."""
    from solver.optimize import _LUKSAN_MEMAVAIL, lbfgs_storage

    x0 = np.random.default_rng(3).uniform(-1.5, 1.5, 30)
    ref, ref_evals = _raw_nlopt_lbfgs(rosenbrock, x0, 1000, 1e-12)
    res = minimize(rosenbrock, x0, ftol_rel=1e-12)
    assert lbfgs_storage(30) == 200 and 100 < ref_evals < 200
    assert res.n_evals == ref_evals and np.array_equal(res.x, ref)
    for n in (1326, 8619, 10**6):  # the figure's sizes: nlopt's max(MEMAVAIL // n, 10)
        assert lbfgs_storage(n) == max(_LUKSAN_MEMAVAIL // n, 10)
    assert lbfgs_storage(1) == 200 and lbfgs_storage(500) == 500


def test_pairs_set_the_lbfgs_memory():
    """`pairs` is the correction pairs nlopt keeps: our wrapper with 10 pairs ends on the bits of nlopt called
    directly with 10 (the 30-variable Rosenbrock above takes more evaluations with 10 than with 200)."""
    x0 = np.random.default_rng(3).uniform(-1.5, 1.5, 30)
    ref, ref_evals = _raw_nlopt_lbfgs(rosenbrock, x0, 10, 1e-12)
    res = minimize(rosenbrock, x0, ftol_rel=1e-12, pairs=10)
    assert res.n_evals == ref_evals and np.array_equal(res.x, ref)
    assert not np.array_equal(minimize(rosenbrock, x0, ftol_rel=1e-12).x, ref)  # the default's 200 pairs differ


def test_time_inside_the_objective_is_counted_apart_from_the_optimizers():
    """`fun_time_s` is the wall time spent in fun: at least what fun sleeps on each call, never more
    than the whole run; the rest is the optimizer's own work (bookkeeping, not a speed claim)."""
    import time

    def slow(x, need_grad):
        time.sleep(0.002)
        return rosenbrock(x, need_grad)

    res = minimize(slow, np.array([-1.2, 1.0]), max_evals=15)
    assert res.n_evals == 15
    assert 0.002 * res.n_evals <= res.fun_time_s <= res.wall_time_s
    empty = minimize(slow, np.zeros(0))  # no variables: one evaluation, all of it in fun
    assert empty.fun_time_s == empty.wall_time_s >= 0.002
