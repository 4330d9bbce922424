"""Term knots (`Term.knot_times`, `SolveOptions.term_knots`): variable frames at the contacts'
touch-downs and lift-offs before the first round, the per-segment frames after them."""
import numpy as np

from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.objective import Objective
from solver.subdivide import knot_hint_times
from solver.terms import UnitQuaternion
from solver.terms.base import Term


class Knotted(Term):
    """A term with knots and nothing else (f = 0)."""

    name = "knotted"

    def __init__(self, knots):
        self.knots = np.asarray(knots, float)

    def knot_times(self):
        return self.knots

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        from solver.terms.base import TermEval

        return TermEval(np.zeros(len(t)), np.zeros_like(Y) if grad else None)


def frames_at(times, nq=4):
    times = np.asarray(times, float)
    vals = np.tile([1.0, 0, 0, 0], (len(times), 1))[:, :nq]
    return FrameSet.from_keyframes(Keyframes(times, vals, np.ones_like(vals, bool)), np.array([[0, 1, 2, 3]]))


def test_hints_keep_their_distance_from_frames_and_each_other():
    fs = frames_at([0.0, 0.25, 0.5])
    got = knot_hint_times(fs, [0.6, 0.26, 0.2, 0.11, 0.1, 0.01, 0.5, -1.0], 0.03)
    # 0.01 is 10 ms from the first keyframe, 0.11 10 ms from the hint 0.1 (the earlier wins), 0.26 10 ms
    # from a keyframe, 0.5 on the last, 0.6 and -1 outside
    np.testing.assert_array_equal(got, [0.1, 0.2])
    np.testing.assert_array_equal(knot_hint_times(fs, [0.2, 0.21], 0.0), [0.2, 0.21])
    assert knot_hint_times(fs, [], 0.03).size == 0


def test_objective_knots_come_from_weighted_terms_inside_the_interval():
    unit = UnitQuaternion(np.array([[0, 1, 2, 3]]))
    obj = Objective([unit, Knotted([0.3, -0.1, 0.3, 0.7]), Knotted([0.5])], [1.0, 1.0, 0.0], 0.0, 1.0, rate=50)
    np.testing.assert_array_equal(obj.knot_times(), [0.3, 0.7])  # sorted, distinct; weight 0 and outside dropped
