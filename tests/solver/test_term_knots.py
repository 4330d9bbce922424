"""Term knots (`Term.knot_times`, `SolveOptions.term_knots`): variable frames at the contacts'
touch-downs and lift-offs before the first round, the per-segment frames after them."""
import mujoco
import numpy as np
import pytest

from solver.contacts import Contact
from solver.frames import FrameSet
from solver.keyframes import Keyframes
from solver.layout import StateLayout
from solver.objective import Objective
from solver.problem import figure_objective
from solver.solve import KNOT_MIN_GAP, SolveOptions, solve
from solver.subdivide import knot_hint_times
from solver.terms import UnitQuaternion
from solver.terms.base import Term

from conftest import TOY_SCENE, random_qpos


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


def test_planted_knots_are_the_contact_starts_and_ends():
    model = mujoco.MjModel.from_xml_string(TOY_SCENE)
    sched = (Contact("l_toe", 0.1, 0.4), Contact("r_toe", 0.55, 0.9))
    obj = figure_objective(model, {"planted": 1.0}, 0.0, 1.0, rate=50, contacts=sched)
    np.testing.assert_array_equal(np.sort(obj.terms[0].knot_times()), [0.1, 0.4, 0.55, 0.9])
    np.testing.assert_array_equal(obj.knot_times(), [0.1, 0.4, 0.55, 0.9])


@pytest.mark.parametrize("term_knots", [True, False])
def test_solve_starts_with_frames_at_the_knots_then_splits_every_segment(term_knots):
    model = mujoco.MjModel.from_xml_string(TOY_SCENE)
    layout = StateLayout.from_model(model)
    times = np.array([0.0, 0.5, 1.0])
    qpos = random_qpos(np.random.default_rng(0), layout, 3)
    kf = Keyframes(times, qpos, np.ones_like(qpos, bool))
    sched = (Contact("l_toe", 0.1, 0.3), Contact("r_toe", 0.52, 0.8))  # 0.52: 20 ms from a keyframe
    obj = figure_objective(model, {"unit": 1.0, "planted": 1.0}, 0.0, 1.0, rate=50, contacts=sched)
    opts = SolveOptions(subdivision="global", per_segment=1, max_evals=2, renormalize=False, term_knots=term_knots)
    sol = solve(obj, FrameSet.from_keyframes(kf, layout.quat_slots), opts)
    knots = np.array([0.1, 0.3, 0.8]) if term_knots else np.zeros(0)
    assert KNOT_MIN_GAP > 0.02
    base = np.sort(np.concatenate([times, knots]))
    expected = np.sort(np.concatenate([base, 0.5 * (base[:-1] + base[1:])]))
    np.testing.assert_allclose(sol.rounds[0].times, expected, atol=1e-15)
    np.testing.assert_array_equal(sol.frames.values[sol.frames.is_keyframe], qpos)


def test_clearance_knots_are_the_corners_of_the_lifted_flight_band():
    """A flight (a, b)'s lift reaches its ceiling TAKEOFF_RISE after a and leaves it LANDING_DESCENT
    before b (docs/contacts.md "The contact terms"): knots there; a flight shorter than both ramps has
    one at the ramps' top, (t - a) / rise = (b - t) / descent; no lift, no knots."""
    from solver.terms.clearance import FLIGHT_LIFT, LANDING_DESCENT, TAKEOFF_RISE, Clearance, flight_lift

    model = mujoco.MjModel.from_xml_string(TOY_SCENE)
    hop = (Contact("l_toe", 0.0, 0.3), Contact("r_toe", 0.65, 1.05), Contact("l_toe", 1.0, 1.3),
           Contact("r_toe", 1.37, 1.6))  # flights (0.3, 0.65): 0.35 s; (1.3, 1.37): 70 ms
    term = Clearance(model, hop, clearance=0.02)
    knots = term.knot_times()
    peak = 1.3 + 0.07 * TAKEOFF_RISE / (TAKEOFF_RISE + LANDING_DESCENT)
    np.testing.assert_allclose(knots, [0.3 + TAKEOFF_RISE, 0.65 - LANDING_DESCENT, peak], rtol=0, atol=1e-12)
    # independently: the band is at its ceiling from the first knot to the second, below it just outside
    band = flight_lift(np.array([0.3 + TAKEOFF_RISE, 0.65 - LANDING_DESCENT, 0.33, 0.62]), 0.3, 0.65, FLIGHT_LIFT)
    np.testing.assert_allclose(band[:2], FLIGHT_LIFT, rtol=1e-12)
    assert (band[2:] < 0.95 * FLIGHT_LIFT).all()
    # the short flight's ramps meet at the peak: the band is highest there
    t = np.linspace(1.3, 1.37, 7001)
    assert t[np.argmax(flight_lift(t, 1.3, 1.37, 1.0))] == pytest.approx(peak, abs=2e-5)
    assert Clearance(model, hop, clearance=0.02, flight_lift=None).knot_times().size == 0
    assert Clearance(model, hop, clearance=0.02, flight=False).knot_times().size == 0
    obj = figure_objective(model, {"clearance": 1.0}, 0.0, 1.6, rate=50, contacts=hop)
    np.testing.assert_allclose(obj.knot_times(), knots, rtol=0, atol=1e-12)
