"""`solve` (solver/solve.py, paper fig. 5) on problems with known optima, and the immutability of its
inputs and results."""
import dataclasses

import numpy as np
import pytest

from solver.frames import FrameSet
from solver.objective import Objective
from solver.optimize import Status
from solver.paper.solve import SolveOptions, solve
from solver.terms.base import Term, TermEval

A, B = np.array([0.5, -1.0]), np.array([2.0, 0.25])  # the target line a + b t


class TrackLine(Term):
    """f = |Y - (A + B t)|^2 [units^2]; violation: max |Y - line| along the path."""

    name, needs = "track", (0,)

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        r = Y - (A + np.outer(t, B))
        return TermEval((r**2).sum(axis=1), dY=2 * r if grad else None)


class Bending(Term):
    """f = |Y''|^2 (zero on any straight line)."""

    name, needs = "bend", (2,)

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        return TermEval((Y2**2).sum(axis=1), dY2=2 * Y2 if grad else None)


class Lift(Term):
    """f = (Y_0 - 1)^2, a soft preference Y_0 = 1 that keyframes at Y_0 = 0 keep from ever holding."""

    name, needs = "lift", (0,)

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        r = Y[:, 0] - 1.0
        dY = np.zeros_like(Y)
        dY[:, 0] = 2 * r
        return TermEval(r**2, dY=dY if grad else None)



def perturbed_line_frames(seed=0):
    """Keyframes on the line at 0 and 2 s, three variable frames off it (a FrameSet made by hand)."""
    times = np.array([0.0, 0.5, 0.8, 1.4, 2.0])
    values = A + np.outer(times, B) + np.random.default_rng(seed).normal(scale=0.3, size=(5, 2))
    is_key = np.array([True, False, False, False, True])
    values[is_key] = A + np.outer(times[is_key], B)
    return FrameSet(times, values, np.repeat(is_key[:, None], 2, axis=1), is_key)


@pytest.mark.parametrize("precondition", [False, True])
def test_reaches_the_known_optimum_a_straight_line(precondition):
    """Both terms vanish exactly on the line through the keyframes: the variable frames must go there."""
    fs = perturbed_line_frames()
    obj = Objective([TrackLine(), Bending()], [1.0, 0.1], 0.0, 2.0, rate=100.0)
    sol = solve(obj, fs, SolveOptions(subdivision="none", renormalize=False, ftol_rel=1e-15,
                                      precondition=precondition))
    assert sol.status is Status.CONVERGED
    np.testing.assert_allclose(sol.frames.values, A + np.outer(fs.times, B), atol=1e-5)
    assert sol.E_final < 1e-9 < sol.E_initial
    np.testing.assert_array_equal(sol.frames.values[[0, -1]], fs.values[[0, -1]])  # keyframes exactly


def lift_problem():
    times = np.array([0.0, 1.0, 2.0])
    values = np.zeros((3, 2))
    is_key = np.array([True, True, True])
    fs = FrameSet(times, values, np.ones((3, 2), bool), is_key)
    obj = Objective([Lift(), Bending()], [1.0, 1.0], 0.0, 2.0, rate=50.0)
    options = SolveOptions(subdivision="global", per_segment=2, ftol_rel=1e-10)
    return fs, obj, options


def test_solving_twice_gives_the_same_result_and_leaves_the_objective_alone():
    fs, obj, options = lift_problem()
    weights, scales = obj.weights.copy(), obj.scales.copy()
    first = solve(obj, fs, options)
    np.testing.assert_array_equal(obj.weights, weights)  # the caller's objective is as it was
    np.testing.assert_array_equal(obj.scales, scales)
    second = solve(obj, fs, options)
    np.testing.assert_array_equal(second.frames.values, first.frames.values)
    np.testing.assert_array_equal(second.trace, first.trace)
    assert (second.E_initial, second.E_final, second.n_evals) == (first.E_initial, first.E_final, first.n_evals)
    assert [r.kind for r in first.rounds] == ["start"] and first.round_counts == {"start": 1}
    # E_initial and E_final are under the weights and the eq. 7 scales
    for sol_E, ints in ((first.E_initial, first.integrals_initial), (first.E_final, first.integrals_final)):
        assert sol_E == pytest.approx(sum(first.weights[n] * ints[n] / first.scales[n] for n in ints), rel=1e-12)


def test_results_are_read_only_and_inputs_untouched():
    fs, obj, options = lift_problem()
    times_before, values_before = fs.times.copy(), fs.values.copy()
    sol = solve(obj, fs, options)
    with pytest.raises(dataclasses.FrozenInstanceError):
        sol.E_final = 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        sol.rounds[0].times = None
    for arr in (sol.frames.values, sol.frames.times, sol.initial.values, sol.trace, sol.rounds[0].times,
                sol.rounds[0].result.x):
        assert not arr.flags.writeable
        with pytest.raises(ValueError):
            arr[...] = 0.0
    assert fs.values.flags.writeable and fs.times.flags.writeable  # the caller's arrays stay theirs
    np.testing.assert_array_equal(fs.times, times_before)
    np.testing.assert_array_equal(fs.values, values_before)
    assert isinstance(sol.rounds, tuple)


def test_fixed_rounds_say_which_round_was_which():
    """`rounds=1`: the start round, then one adaptive round that adds frames; the progress events name
    the same kinds."""
    fs, obj, options = lift_problem()
    events = []
    sol = solve(obj, fs, dataclasses.replace(options, subdivision="adaptive", rounds=1),
                progress=lambda e, i: events.append((e, i)))
    kinds = [r.kind for r in sol.rounds]
    assert kinds == ["start", "refine"]
    assert [i["kind"] for e, i in events if e == "round"] == kinds
    assert sol.rounds[1].n_variable > sol.rounds[0].n_variable  # the refinement round added frames
    assert sol.round_summary == "2 rounds: 1 start, 1 refine"
