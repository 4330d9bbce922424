"""The clearance term's flights follow the capture's own (docs/contacts.md "The contact terms"): hand-built
heights and motions of the toy figure of conftest.py (identity pose, root at z = FOOT + h: every contact
site h above the floor), checked against intervals and windows computed by hand."""
import numpy as np
import pytest

import solver
from solver.contact_thresholds import FLIGHT_HEIGHT
from solver.contacts import Contact
from solver.errors import InputError
from solver.layout import StateLayout
from solver.problem import capture_airborne, make_problem
from solver.terms.clearance import (
    FLIGHT_LIFT,
    LANDING_DESCENT,
    TAKEOFF_RISE,
    Clearance,
    airborne_intervals,
    flight_windows,
)

FOOT = 0.95  # root height minus site height at identity rotations
LEAD = TAKEOFF_RISE * FLIGHT_HEIGHT / FLIGHT_LIFT  # 30 ms: the lift is at 3 cm this long after its start
LAG = LANDING_DESCENT * FLIGHT_HEIGHT / FLIGHT_LIFT  # 42.9 ms: ... and this long before its end


#: a glide (0.3, 0.5): the capture's feet stay 1.5 cm up; a hop (0.7, 0.9): they rise to 10 cm
SCHEDULE = (Contact("l_toe", 0.0, 0.3), Contact("r_toe", 0.5, 0.7), Contact("l_toe", 0.9, 1.2))
FPS = 120.0
HOP = range(89, 104)  # frames 0.742 .. 0.858 s: every site 10 cm up


def pose(layout, heights):
    """(n, nq) identity poses with every contact site heights[i] [m] above the floor."""
    Y = np.zeros((len(heights), layout.nq))
    Y[:, 2] = FOOT + np.asarray(heights, float)
    Y[:, layout.quat_slots[:, 0]] = 1.0
    return Y


def capture_heights():
    """(n,) the hand-built capture's site height [m] at 120 Hz over 0 .. 1.2 s."""
    t = np.arange(int(1.2 * FPS) + 1) / FPS
    h = np.where(np.array([any(c.start <= x <= c.end for c in SCHEDULE) for x in t]), 0.0, 0.015)
    h[list(HOP)] = 0.10
    return t, h


def test_airborne_intervals_are_the_runs_of_frames_with_every_site_clear():
    t = np.arange(10) * 0.1
    h = np.full((10, 2), 0.01)
    h[2:5] = 0.05
    h[7] = 0.04
    h[5] = [0.05, 0.02]  # one site low: not airborne
    h[8] = [FLIGHT_HEIGHT, 0.05]  # exactly at the flight height: not above it (as the flight metric)
    got = airborne_intervals(t, h)
    np.testing.assert_allclose(got, [(0.15, 0.45), (0.65, 0.75)], atol=1e-12)
    assert airborne_intervals(t, np.zeros((10, 2))) == ()
    with pytest.raises(InputError, match="airborne_intervals"):
        airborne_intervals(t, h[:5])


def test_flight_windows_are_the_capture_flights_inside_the_gaps():
    gaps = [(0.3, 0.5), (0.7, 0.9), (1.2, 1.4), (2.0, 2.5)]
    # grazes shorter than the ramps (85 ms): the lift stays inside them
    airborne = [(0.75, 0.80), (0.80, 0.84), (0.86, 0.93), (1.19, 1.25), (1.6, 1.7)]
    got = flight_windows(gaps, airborne)
    # the glide has none; the touching runs merge, the one over the landing and the one over the
    # take-off are clipped to their gaps; the last is in no gap (the schedule has the capture in contact)
    np.testing.assert_allclose(got, [(0.75, 0.84), (0.86, 0.9), (1.2, 1.25)], atol=1e-12)
    assert flight_windows(gaps, []) == []
    # a ballistic flight (>= 85 ms) is widened so that the lift crosses the flight height where it does
    from solver.terms.clearance import flight_lift

    (a, b), = flight_windows(gaps, [(2.1, 2.3)])
    assert (a, b) == pytest.approx((2.1 - LEAD, 2.3 + LAG), abs=1e-12)
    np.testing.assert_allclose(flight_lift(np.array([2.1, 2.3]), a, b, FLIGHT_LIFT), FLIGHT_HEIGHT, rtol=1e-12)
    assert flight_windows(gaps, [(2.0, 2.47)]) == [(2.0, 2.5)]  # clipped to the gap


def test_only_the_gap_the_capture_flies_through_is_a_flight(toy_model):
    layout = StateLayout.from_model(toy_model)
    t, h = capture_heights()
    airborne = capture_airborne(toy_model, t, pose(layout, h))
    np.testing.assert_allclose(airborne, [((HOP[0] - 0.5) / FPS, (HOP[-1] + 0.5) / FPS)], atol=1e-9)
    term = Clearance(toy_model, SCHEDULE, clearance=0.02, airborne=airborne)
    window = ((HOP[0] - 0.5) / FPS - LEAD, 0.9)  # 125 ms in the air: widened, up to the landing (0.863 + 43 ms)
    np.testing.assert_allclose(term.flights, [window], atol=1e-9)
    np.testing.assert_allclose(term.knot_times(), [window[0] + TAKEOFF_RISE, window[1] - LANDING_DESCENT])
    swing_only = Clearance(toy_model, SCHEDULE, clearance=0.02, flight=False)
    everywhere = Clearance(toy_model, SCHEDULE, clearance=0.02)  # no capture: both gaps are flights
    assert everywhere.flights == [(0.3, 0.5), (0.7, 0.9)]
    low = 0.015
    Y = pose(layout, [low, low])
    # the glide's middle: no flight, l_toe keeps its swing band alone (r_toe and the heels have no swing)
    glide = np.array([0.4])
    assert term.split_windows(glide)[1][0] == 0.0
    assert term.evaluate(glide, Y[:1], None, None).f[0] == pytest.approx(
        swing_only.evaluate(glide, Y[:1], None, None).f[0], rel=1e-12)
    assert everywhere.evaluate(glide, Y[:1], None, None).f[0] > swing_only.evaluate(glide, Y[:1], None, None).f[0]
    # the hop's middle: every site lifted to FLIGHT_LIFT, on top of l_toe's swing band
    hop = np.array([0.8])
    _, Uf, Bf, _ = term.split_windows(hop)
    assert Uf[0] == 1.0 and Bf[0] == pytest.approx(FLIGHT_LIFT, rel=1e-12)
    extra = term.evaluate(hop, Y[:1], None, None).f[0] - swing_only.evaluate(hop, Y[:1], None, None).f[0]
    assert extra == pytest.approx(4 * (FLIGHT_LIFT - low) ** 2, rel=1e-12)
    assert term.violation(Y, np.array([0.4, 0.8])) == pytest.approx(FLIGHT_LIFT - low, rel=1e-9)


def test_make_problem_takes_the_flights_from_the_capture(toy_model):
    layout = StateLayout.from_model(toy_model)
    t, h = capture_heights()
    keys = np.array([0.0, 0.4, 0.8, 1.2])
    kf = solver.Keyframes(keys, pose(layout, np.interp(keys, t, h)), np.ones((4, layout.nq), bool))
    with_capture = make_problem(toy_model, kf, "clearance", contacts=SCHEDULE, rate=40.0,
                                capture=(t, pose(layout, h)))
    plain = make_problem(toy_model, kf, "clearance", contacts=SCHEDULE, rate=40.0)
    (a, b), = next(term for term in with_capture.objective.terms if term.name == "clearance").flights
    assert a == pytest.approx((HOP[0] - 0.5) / FPS - LEAD, abs=1e-9) and b == pytest.approx(0.9)
    assert next(term for term in plain.objective.terms if term.name == "clearance").flights == [(0.3, 0.5), (0.7, 0.9)]
    # flights stated (a keyframe file's "flights") are used instead of the capture's: [] = never flies
    stated = make_problem(toy_model, kf, "clearance", contacts=SCHEDULE, rate=40.0, capture=(t, pose(layout, h)),
                          airborne=[])
    assert next(term for term in stated.objective.terms if term.name == "clearance").flights == []


@pytest.mark.parametrize("bad", [[(0.5, 0.4)], [("x", 1.0)], [(0.1,)], [(0.1, np.inf)]])
def test_bad_airborne_is_an_input_error(toy_model, bad):
    with pytest.raises(InputError, match=r"airborne\[0\]"):
        Clearance(toy_model, SCHEDULE, airborne=bad)
