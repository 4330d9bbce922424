"""Penalty continuation (solver/continuation.py) alone, with terms whose violations are scripted."""
import numpy as np
import pytest

from solver.continuation import STALL_FRACTION, PenaltyContinuation, over_limits
from solver.frames import FrameSet
from solver.objective import Objective
from solver.terms.base import Term, TermEval


class Scripted(Term):
    """f = 0; violation: the next value of `script` at each check (the path does not matter)."""

    needs = (0,)

    def __init__(self, name, script):
        self.name, self.script = name, list(script)

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        return TermEval(np.zeros(len(t)), dY=np.zeros_like(Y) if grad else None)

    def violation(self, Y):
        return self.script.pop(0) if self.script else 0.0


def frames():
    t = np.array([0.0, 1.0])
    return FrameSet(t, np.zeros((2, 1)), np.ones((2, 1), bool), np.ones(2, bool))


def test_over_limits_skips_unknown_unweighted_and_unmeasured_terms():
    class NoMeasure(Scripted):
        def violation(self, Y):
            return None

    obj = Objective([Scripted("a", [2.0]), Scripted("b", [2.0]), NoMeasure("c", [])], [1.0, 0.0, 1.0], 0.0, 1.0,
                    rate=10.0)
    over = over_limits(obj, frames(), (("a", 1.0), ("b", 1.0), ("c", 0.0), ("zzz", 0.0)))
    assert over == {"a": 2.0}  # b has weight 0, c no violation measure, zzz is not a term
    assert over_limits(obj, frames(), ()) == {}


def test_boosts_while_the_violation_falls_then_stops_at_max_boosts():
    # the quadratic penalty's rate: each boost cuts the violation ~10x
    obj = Objective([Scripted("a", [1.0, 0.1, 0.01, 1e-3, 1e-4])], [1.0], 0.0, 1.0, rate=10.0)
    cont, events = PenaltyContinuation((("a", 1e-6),), boost=10.0, max_boosts=3), []
    made = [cont.after_round(obj, frames(), lambda e, i: events.append((e, i))) for _ in range(4)]
    assert made == [{"a": 1.0}, {"a": 0.1}, {"a": 0.01}, {}]  # the fourth check: max_boosts reached
    assert obj.weights[0] == pytest.approx(1e3) and cont.boosts == 3 and not cont.stalled
    assert [e for e, _ in events] == ["boost"] * 3 and events[-1][1]["boosts"] == 3


def test_a_boost_that_does_not_cut_the_violation_enough_gives_the_term_up():
    falls_little = 0.9  # of what it was (1.0): above STALL_FRACTION
    assert falls_little > STALL_FRACTION
    obj = Objective([Scripted("a", [1.0, falls_little, 0.5]), Scripted("b", [1.0, 0.01, 0.0])], [1.0, 1.0], 0.0,
                    1.0, rate=10.0)
    cont, events = PenaltyContinuation((("a", 1e-3), ("b", 1e-3)), boost=10.0, max_boosts=5), []
    assert cont.after_round(obj, frames(), lambda e, i: events.append((e, i))) == {"a": 1.0, "b": 1.0}
    assert cont.after_round(obj, frames(), lambda e, i: events.append((e, i))) == {"b": 0.01}  # a stalled
    assert cont.stalled == {"a": pytest.approx(0.9)}
    assert cont.after_round(obj, frames(), lambda e, i: events.append((e, i))) == {}  # a is not boosted again
    np.testing.assert_allclose(obj.weights, [10.0, 100.0])
    assert [e for e, _ in events] == ["boost", "stalled", "boost"]  # "stalled" said once


def test_a_boost_whose_every_term_stalled_is_undone():
    # a: 1.0 -> 0.9 after its boost (stalled); on the restored path it reads 1.0 again and stays given up
    obj = Objective([Scripted("a", [1.0, 0.9, 1.0]), Scripted("b", [0.0, 0.0, 0.0])], [1.0, 1.0], 0.0, 1.0,
                    rate=10.0)
    cont, events = PenaltyContinuation((("a", 1e-3), ("b", 1e-3)), boost=10.0, max_boosts=5), []
    before, boosted = frames(), frames()
    assert cont.after_round(obj, before, lambda e, i: events.append((e, i)), result="round 0") == {"a": 1.0}
    np.testing.assert_allclose(obj.weights, [10.0, 1.0])
    assert cont.after_round(obj, boosted, lambda e, i: events.append((e, i)), result="round 1") == {}
    assert cont.restored is not None and cont.restored[0] is before and cont.restored[1] == "round 0"
    np.testing.assert_allclose(obj.weights, [1.0, 1.0])  # the weights from before the boost
    assert cont.undone == 1 and cont.stalled == {"a": pytest.approx(0.9)}
    assert [e for e, _ in events] == ["boost", "stalled", "undo"]


def test_a_boost_that_halved_one_of_its_terms_stands():
    obj = Objective([Scripted("a", [1.0, 0.9]), Scripted("b", [1.0, 0.1])], [1.0, 1.0], 0.0, 1.0, rate=10.0)
    cont = PenaltyContinuation((("a", 1e-3), ("b", 1e-3)), boost=10.0, max_boosts=5)
    cont.after_round(obj, frames())
    assert cont.after_round(obj, frames()) == {"b": 0.1} and cont.restored is None and cont.undone == 0
    np.testing.assert_allclose(obj.weights, [10.0, 100.0])


def test_undo_can_be_switched_off():
    obj = Objective([Scripted("a", [1.0, 0.9])], [1.0], 0.0, 1.0, rate=10.0)
    cont = PenaltyContinuation((("a", 1e-3),), undo_stalled=False)
    cont.after_round(obj, frames())
    assert cont.after_round(obj, frames()) == {} and cont.restored is None
    np.testing.assert_allclose(obj.weights, [10.0])


class Excusing(Scripted):
    """A scripted term with parts its violation leaves out: `for_boost` gives a copy with `kept` divided
    by the factor (the protocol of `solver.terms.contact.Planted.for_boost`)."""

    kept = 1.0

    def for_boost(self, factor):
        new = Excusing(self.name, self.script)
        new.kept = self.kept / factor
        return new


def test_a_boost_keeps_the_excused_parts_weight_and_an_undo_restores_the_terms():
    term = Excusing("a", [1.0, 0.9, 1.0])
    obj = Objective([term, Scripted("b", [0.0] * 3)], [1.0, 1.0], 0.0, 1.0, rate=10.0)
    caller_terms = obj.terms
    cont = PenaltyContinuation((("a", 1e-3),), boost=10.0, max_boosts=5)
    assert cont.after_round(obj, frames()) == {"a": 1.0}
    np.testing.assert_allclose(obj.weights, [10.0, 1.0])
    assert obj.terms[0] is not term and obj.terms[0].kept == pytest.approx(0.1)  # weight x kept stays 1
    assert caller_terms[0] is term and term.kept == 1.0  # the old list and term are not changed
    assert cont.after_round(obj, frames()) == {} and cont.undone == 1  # stalled (1.0 -> 0.9): undone
    assert obj.terms[0] is term and obj.terms[1] is caller_terms[1]
    np.testing.assert_allclose(obj.weights, [1.0, 1.0])
