"""Flight and ground bounds at a flight's ends (`solver.constraint_set`, module docstring "flight" and "ground").

A capture's flights are found on its frames (`solver.contacts.airborne_intervals`): a flight starts midway
between the last frame with a site down and the first with every site up. Between those two frames the
capture does not say when the foot crossed the flight height, so a bound posed there asks for a crossing
time no data gave. Known answer: the capture itself, which the schedule was read from, meets its own flight
and ground bounds at every quadrature point, wherever between two frames its foot crossed.
"""
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

import solver
from solver.contact_thresholds import FLIGHT_HEIGHT
from solver.contacts import contact_points, site_heights
from solver.inverse_dynamics import InverseDynamics
from solver.kinematics import TangentMap
from solver.least_change import build_least_change
from solver.path_state import PathState
from solver.problem import capture_airborne

from conftest import shipped_standing

FPS = 120.0  # [1/s] a capture's frame rate (CMU's)
RATE = 1000.0  # [1/s] quadrature points: a point every 1 ms, so some fall between the crossing and the flight's start
SPEED = 2.0  # [m/s] the root's rise after take-off, a jump's (a CMU jump's toe leaves at about 3 m/s)


def _jump(model, q, crossing: float):
    """(times, qpos): the figure standing in pose q, then its root rising at SPEED, timed so that its lowest
    site crosses FLIGHT_HEIGHT `crossing` of a frame interval after a frame (0 < crossing < 1)."""
    times = np.arange(0.0, 0.4, 1.0 / FPS)
    h0 = float(site_heights(model, contact_points(model, q[None]))[0].min())  # [m] standing, lowest site
    t_cross = times[24] + crossing / FPS
    t_lift = t_cross - (FLIGHT_HEIGHT - h0) / SPEED
    qpos = np.tile(q, (len(times), 1))
    qpos[:, 2] += SPEED * np.maximum(times - t_lift, 0.0)
    return times, qpos


@pytest.mark.parametrize("crossing", [0.15, 0.85])
def test_the_capture_meets_its_own_flight_and_ground_bounds(crossing):
    model, _, _, layout, q = shipped_standing()
    times, qpos = _jump(model, q, crossing)
    flights = capture_airborne(model, times, qpos)
    assert len(flights) == 1
    a = flights[0][0]
    keys = solver.Keyframes(times[[0, -1]], qpos[[0, -1]], np.ones((2, model.nq), bool))
    lc = build_least_change(model, keys, flights=flights, capture=(times, qpos), rate=RATE)
    t = lc.al.t
    spline = CubicSpline(times, qpos, bc_type="natural")  # the capture as a path (the constraints' own witness)
    sites = solver.Figure.from_model(model).contact_sites
    state = PathState(t, spline(t), spline(t, 1), spline(t, 2), TangentMap.from_layout(layout),
                      InverseDynamics(model, sites))
    bounds = {c.name: c for c in lc.al.constraints if c.name in ("flight", "ground")}
    assert set(bounds) == {"flight", "ground"}
    for c in bounds.values():
        assert np.all(c.values(state) <= c.tolerance + 1e-9), c.name  # met within its tolerance [m]
    # the premise: at the flight's start the capture is more than a tolerance from the flight height, so a
    # bound posed at the points between the two frames (either side of a) would be broken
    lowest = site_heights(model, contact_points(model, spline([a])))[0].min()
    assert abs(lowest - FLIGHT_HEIGHT) > 2 * bounds["flight"].tolerance
    # and the bounds still hold at the frames either side: ground at the last frame down, flight from the first up
    down, up = a - 0.5 / FPS, a + 0.5 / FPS  # [s] the two frames either side of the flight's start
    ground_t, flight_t = t[bounds["ground"].rows], t[bounds["flight"].rows]
    assert np.isclose(ground_t, down, rtol=0, atol=1e-9).any() and flight_t.min() == pytest.approx(up, abs=1e-9)
    assert not np.any((ground_t > down + 1e-9) & (ground_t < up - 1e-9))  # none between the two frames


def test_edge_frames_are_each_frame_once_and_leave_the_keys_alone():
    """A one-frame flight (frame 0.1 s of a 100 Hz capture airborne alone: (0.095, 0.105)) has three frames
    about its ends, 0.09, 0.1 and 0.11 s, the middle one once however a -+ h rounds; a key at 0.11 s (within
    round-off) is a point already."""
    from solver.constraint_set import flight_edge_frames

    frames = np.arange(0.0, 0.5, 0.01)
    one = [(0.1 - 0.005, 0.1 + 0.005)]
    np.testing.assert_allclose(flight_edge_frames(one, frames), [0.09, 0.1, 0.11], atol=1e-12)
    np.testing.assert_allclose(flight_edge_frames(one, frames, keytimes=[0.11 + 1e-12]), [0.09, 0.1], atol=1e-12)
    assert flight_edge_frames((), frames).size == 0
