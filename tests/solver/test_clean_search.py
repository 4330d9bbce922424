"""A clean (solver.displacement) whose first search, from the capture, raises a limit: the raise is undone, the
rounds of the method of multipliers run, and the search after them starts from the stalled path and from the first
search's (solver.least_change, docs/solvers.md); the certificate it keeps (`solver.least_change_end.kept_certificate`).
On the toy figure's hand-made capture of tests/solver/test_displacement.py, with a bound its pin puts out of reach."""
from dataclasses import replace

import numpy as np
import pytest

from solver.constraint_set import PENETRATION_TOLERANCE
from solver.constraints.base import SCHEDULE, Constraint
from solver.displacement import build_displacement, clean_solution, pin_frames, solve_displacement
from solver.feasibility import Certificate, Raise
from solver.lagrangian import AugmentedLagrangian
from solver.least_change import LeastChangeOptions
from solver.least_change_end import kept_certificate
from tests.solver.test_displacement import DIP, _capture, _lowest_site


class PelvisCeiling(Constraint):
    """A caller's bound (docs/design.md "A constraint of your own"): the pelvis height qpos[2] at one quadrature point
    at most `top` [m], tolerance 1 mm."""

    name, unit, scale, tolerance, priority = "pelvis ceiling", "mm", 1e-3, 1e-3, SCHEDULE

    def __init__(self, row: int, top: float):
        self.rows, self.labels, self.limit = np.array([row]), np.array(["pelvis"], object), np.array([top])

    def measure(self, state):
        return state.Y[self.rows, 2]

    def pull(self, state, g):
        np.add.at(state.gY[:, 2], self.rows, g)


@pytest.mark.slow
def test_a_clean_whose_first_search_raises_seeks_again_after_the_rounds(toy_model):
    """The dipped toy capture pinned at 0.5 s, with a pelvis ceiling 5 cm under the captured pelvis there: the pin
    holds the capture's pose at that quadrature point, so no path meets the ceiling, by exactly 5 cm. The clean's
    first search (from the capture) raises it; that raise is undone, the rounds run, and the search after them
    (from the stalled path and the first search's) certifies it at 5 cm. The answer meets every limit as certified,
    holds the pins and, by MuJoCo's kinematics at 1001 times, keeps the feet out of the floor."""
    t, q = _capture(toy_model, DIP)
    pin, gap = 0.5, 0.05  # [s] the pinned time, [m] the ceiling below the captured pelvis there
    disp = build_displacement(toy_model, t, q, pins=(pin,))
    al = disp.lc.al
    row = int(np.argmin(abs(al.t - pin)))
    assert abs(al.t[row] - pin) < 1e-12  # a capture frame is a quadrature point
    top = float(q[pin_frames(t, (pin,))[0], 2]) - gap
    al = AugmentedLagrangian(al.change, [*al.constraints, PelvisCeiling(row, top)], al.tmap, al.engine, al.d0,
                             base=al.base)
    disp = replace(disp, lc=replace(disp.lc, al=al))
    events = []
    sol = solve_displacement(disp, LeastChangeOptions(), progress=lambda kind, info: events.append((kind, info)))
    searches = [info for kind, info in events if kind == "certify"]
    first_round = next(i for i, (kind, _) in enumerate(events) if kind == "round")
    assert searches[0]["round"] == -1 and "pelvis ceiling" in searches[0]["raised"]  # the first search, before any round
    assert [kind for kind, _ in events[:first_round]].count("certify") == 1  # its raise undone: the rounds follow
    assert len(searches) >= 2 and searches[-1]["round"] >= 1  # sought again after the rounds
    [ceiling] = [r for r in sol.certificate if r.constraint == "pelvis ceiling"]
    assert abs(ceiling.amount - gap) <= 1e-9, ceiling.amount  # [m] the pinned pose's own excess, no more
    assert max(sol.integrals_final.values()) <= 1.0, sol.integrals_final  # every c/tol within the certified limits
    clean = clean_solution(disp, sol)
    pinned = pin_frames(t, (pin,))
    np.testing.assert_allclose(clean.frames.values[pinned], q[pinned], rtol=0, atol=1e-15)  # round-off of c + 0
    low = _lowest_site(toy_model, clean.frames.path(np.linspace(t[0], t[-1], 1001)))
    assert low.min() >= -PENETRATION_TOLERANCE - 1e-5, low.min()


class _Pairs:
    """A constraint's bookkeeping alone (name, labels, tolerance, limit), as `kept_certificate` reads it."""

    def __init__(self, name, labels, tolerance, limit):
        self.name, self.labels, self.tolerance, self.limit = name, np.array(labels, object), tolerance, np.array(limit)
        self.size = len(labels)


class _AL:
    def __init__(self, constraints):
        self.constraints, self.lam, self.V = constraints, [np.ones(c.size) for c in constraints], 1.0


def _raise(name, label, amount):
    return Raise(name, label, amount, 1.0, 1.0, 1.0, 1, "", 1.0)


def test_a_later_certificate_replaces_the_first_only_where_no_column_is_worse_beyond_its_tolerance():
    """`kept_certificate` on hand-made certificates: a later one that raises a column more than its tolerance above
    the first's (slide at l_toe 0.795 m against 0.022 m, tolerance 2 mm) gives way to the first, whose limits are
    set again (the multipliers of the pairs they raise from 0, the others as they were) and reported; one within
    every column's tolerance of it (or with nothing raised, or with no first) is kept, the limits as it left them."""
    posed = [np.zeros(2), np.zeros(2)]
    first_limits = [np.array([0.0, 0.135]), np.array([0.0, 0.022])]

    def setup():
        al = _AL([_Pairs("acceleration", ["r_hip", "r_shoulder"], np.array([1.0, 2.0]), [0.0057, 0.0]),
                  _Pairs("slide", ["l_heel", "l_toe"], 2e-3, [0.0, 0.795])])
        return al, Certificate((_raise("acceleration", "r_shoulder", 0.135), _raise("slide", "l_toe", 0.022)), "first")

    al, first = setup()
    later = Certificate((_raise("acceleration", "r_hip", 0.0057), _raise("slide", "l_toe", 0.795)), "later", 7)
    said = []
    kept = kept_certificate(al, later, (first, first_limits), posed, lambda kind, info: said.append((kind, info)))
    assert kept.frames == "first" and kept.raises == first.raises and kept.n_evals == 7
    for c, limit in zip(al.constraints, first_limits):
        np.testing.assert_array_equal(c.limit, limit)
    np.testing.assert_array_equal(al.lam[0], [1.0, 0.0])  # r_shoulder raised again: its multiplier from 0
    np.testing.assert_array_equal(al.lam[1], [1.0, 0.0])
    assert np.inf == al.V and said == [("kept", {"worse": {"slide at l_toe": 0.795}})]

    al, first = setup()
    within = Certificate((_raise("acceleration", "r_shoulder", 0.135 + 1.9), _raise("slide", "l_toe", 0.022 + 1.9e-3)),
                         "within")
    assert kept_certificate(al, within, (first, first_limits), posed, None) is within
    np.testing.assert_array_equal(al.constraints[1].limit, [0.0, 0.795])  # as the later search left them
    for cert, prior in ((Certificate((), "met"), (first, first_limits)), (later, None)):
        assert kept_certificate(al, cert, prior, posed, None) is cert
