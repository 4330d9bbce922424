"""The least violation and its certificate (solver.feasibility, solver.least_change): the contract, on
problems whose answers are known by hand.

The figure stands still on the floor through its keyframes (the plain spline: no change), and the only
constraints are bounds on the pelvis height z at one instant t* (`PelvisHeight`, a user-defined
`Constraint`): z(t*) <= top (the contact schedule's priority) and z(t*) >= bottom (a limit of the body's
priority). Each is met or not by a known amount:

* bottom <= top, both off the still path: feasible; nothing is raised, the status is CONVERGED, and the
  least change ends on the bound it had to move to (an active bound holds with equality within its
  tolerance, and the other is not touched);
* bottom > top: no path meets both; the lower priority gives by exactly bottom - top, the body's limit
  holds, the status is INFEASIBLE;
* t* a keyframe that holds z above top: the certificate is the keyed excess, nothing more, and no finer
  frames beat it.
"""
from dataclasses import replace

import numpy as np
import pytest

import solver
from solver.constraints.base import LIMIT, SCHEDULE, Constraint
from solver.feasibility import RAISED_AT, least_violation, with_frames
from solver.lagrangian import AugmentedLagrangian
from solver.layout import StateLayout
from solver.least_change import LeastChangeOptions, _start_frames, build_least_change, solve_least_change
from solver.optimize import Status
from solver.spline_basis import SplineBasis

from conftest import shipped_standing

#: [m] the bounds' tolerance: 1 mm, the penetration constraint's
TOL = 1e-3
#: [s] the instant the bounds hold at, between the keyframes at 0 and 0.8 s, on the middle one: a
#: quadrature point (200 per second, midpoints of 5 ms intervals from 0)
T_STAR = 0.4025


class PelvisHeight(Constraint):
    """A user-defined bound: the pelvis height z (qpos[2]) at the quadrature point nearest `t` (and every
    point within `half` [s] of it), sign +1: z <= limit, sign -1: z >= -limit (measure -z <= limit). Unit m,
    tolerance `TOL`."""

    unit, scale, tolerance = "m", 1.0, TOL

    def __init__(self, name, t_points, t, sign, limit, priority, half=0.0):
        self.name, self.sign, self.priority = name, float(sign), priority
        near = np.abs(t_points - t)
        self.rows = np.flatnonzero(near <= max(half, near.min()))
        self.labels = np.full(len(self.rows), "pelvis", object)
        self.limit = np.full(len(self.rows), float(limit))

    def measure(self, state):
        return self.sign * state.Y[self.rows, 2]

    def pull(self, state, g):
        np.add.at(state.gY[:, 2], self.rows, self.sign * g)


@pytest.fixture(scope="module")
def standing():
    """(model, still keyframes at 0, T_STAR, 0.8 s, the standing pelvis height [m])."""
    model, keyframes, _, _, q = shipped_standing()
    still = replace(keyframes, times=np.array([0.0, T_STAR, 0.8]), values=np.tile(q, (3, 1)),
                    mask=np.ones((3, model.nq), bool))
    return model, still, float(q[2])


def _problem(standing, top, bottom, keyed=True, half=0.0):
    """The least change of the still figure under z(t*) <= top (SCHEDULE) and z(t*) >= bottom (LIMIT),
    each over the points within `half` [s] of t*; without `keyed` the middle keyframe leaves the pelvis
    height free (a partial keyframe)."""
    model, still, _ = standing
    if not keyed:
        mask = still.mask.copy()
        mask[1, 2] = False
        still = replace(still, mask=mask)
    lc = build_least_change(model, still, rate=200.0)
    old = lc.al
    t = old.t
    cons = [PelvisHeight("top", t, T_STAR, +1, top, SCHEDULE, half),
            PelvisHeight("bottom", t, T_STAR, -1, -bottom, LIMIT, half)]
    return replace(lc, al=AugmentedLagrangian(old.change, cons, old.tmap, old.engine, old.d0))


def top_limit(lc):
    """(p,) [m] the limits of the bound z <= top as posed (a solve raises them on its own copy)."""
    return lc.al.constraints[0].limit


def _z(sol):
    return float(sol.frames.path(np.array([T_STAR]))[0, 2])


def test_a_feasible_problem_raises_nothing_and_ends_on_its_active_bound(standing):
    z0 = standing[2]
    lc = _problem(standing, top=z0 - 0.05, bottom=z0 - 0.20, keyed=False)
    sol = solve_least_change(lc, LeastChangeOptions())
    assert sol.status is Status.CONVERGED and sol.certificate == () and sol.unmet == {}
    assert z0 - 0.05 - TOL <= _z(sol) <= z0 - 0.05 + TOL  # active: on the bound, within its tolerance
    assert _z(sol) >= z0 - 0.20  # the other untouched


def test_a_reference_within_every_tolerance_is_the_least_change_unchanged(standing):
    """The still figure's pelvis is 0.6 mm above `top`, within its 1 mm tolerance: the plain spline meets every
    constraint, D >= 0 is 0 on it, so it is the least change; the solve returns it as it is (the method of
    multipliers alone aims at the limit itself and moved the pelvis down to it)."""
    z0 = standing[2]
    lc = _problem(standing, top=z0 - 0.0006, bottom=z0 - 0.20, keyed=False)
    sol = solve_least_change(lc, LeastChangeOptions())
    assert sol.status is Status.CONVERGED and sol.certificate == () and sol.unmet == {}
    t = lc.al.t
    assert np.max(np.abs(sol.frames.path(t) - lc.plain.path(t))) <= 1e-12  # [m, 1] the plain spline, to round-off
    assert sol.E_final == pytest.approx(0.0, abs=1e-15) and sol.estimate_kind == "reference"


def test_conflicting_bounds_give_the_lower_priority_exactly_what_the_higher_needs(standing):
    z0 = standing[2]
    top, bottom = z0 - 0.10, z0 - 0.04  # no z is both <= top and >= bottom: the schedule's wish gives 6 cm
    lc = _problem(standing, top=top, bottom=bottom, keyed=False)
    sol = solve_least_change(lc, LeastChangeOptions())
    assert sol.status is Status.INFEASIBLE
    assert [r.constraint for r in sol.certificate] == ["top"]
    (raised,) = sol.certificate
    assert raised.amount == pytest.approx(bottom - top, abs=TOL)  # the least violation, no more
    assert raised.time == pytest.approx(T_STAR, abs=0.005) and raised.label == "pelvis"
    assert _z(sol) >= bottom - TOL  # the body's limit holds
    assert sol.unmet == {"top": raised.amount}


def test_of_two_bounds_of_one_level_only_the_cheaper_gives(standing):
    """z <= top and z >= bottom, 6 cm apart, both wishes of the schedule (one level), bottom's tolerance 4x
    top's: a millimetre of bottom's violation costs a quarter of top's in tolerances, so the least violation,
    a sum of the violations (SNOPT's elastic objective), puts all 6 cm on bottom and leaves top within its
    tolerance. A sum of squares would raise both (top by 6 cm / 17 = 3.5 mm: (x/tol)^2 + (y/4tol)^2 is least
    at y = 16x)."""
    z0 = standing[2]
    top, bottom = z0 - 0.10, z0 - 0.04
    lc = _problem(standing, top=top, bottom=bottom, keyed=False)
    lo = PelvisHeight("bottom", lc.al.t, T_STAR, -1, -bottom, SCHEDULE)
    lo.tolerance = 4 * TOL
    old = lc.al
    lc = replace(lc, al=AugmentedLagrangian(old.change, [old.constraints[0], lo], old.tmap, old.engine, old.d0))
    sol = solve_least_change(lc, LeastChangeOptions())
    assert [r.constraint for r in sol.certificate] == ["bottom"]
    (raised,) = sol.certificate
    assert raised.amount == pytest.approx(bottom - top, abs=4 * TOL)  # the whole gap, within bottom's tolerance
    assert _z(sol) <= top + TOL  # top met as posed


def test_the_search_reports_its_evaluations_as_it_goes(standing):
    """A solve that seeks the least violation says so ("search"), reports the search's evaluations with its F
    while it runs ("eval"), then what it raised ("certify"), with the evaluations counted on from the
    subproblems' and the search's own total at the end."""
    z0 = standing[2]
    lc = _problem(standing, top=z0 - 0.10, bottom=z0 - 0.04, keyed=False)
    events = []
    solve_least_change(lc, LeastChangeOptions(), progress=lambda e, info: events.append((e, dict(info))))
    names = [e for e, _ in events]
    s, c = names.index("search"), names.index("certify")
    during = [info for e, info in events[s + 1:c] if e == "eval"]
    assert during and all("F" in info and info["F"] >= 0 for info in during)
    counts = [info["evals"] for info in during]
    base = events[c][1]["evals"] - events[c][1]["spent"]  # the subproblems' evaluations before the search
    assert max(info["evals"] for e, info in events[:s] if e == "eval") <= base
    assert counts == sorted(counts) and base < counts[0] and counts[-1] <= events[c][1]["evals"]


def test_a_keyed_pose_beyond_a_bound_is_certified_by_its_own_excess(standing):
    z0 = standing[2]
    # the key at t* holds z 5 mm above top, which holds over the 20 ms either side of it too
    lc = _problem(standing, top=z0 - 0.005, bottom=z0 - 0.5, half=0.02)
    sol = solve_least_change(lc, LeastChangeOptions())
    (raised,) = sol.certificate
    assert raised.constraint == "top" and 0.005 - TOL <= raised.amount <= 0.005 + 1e-9  # the keyed 5 mm, no more
    assert raised.time == pytest.approx(T_STAR, abs=1e-9)  # at the key
    assert sol.status is Status.INFEASIBLE and _z(sol) == pytest.approx(z0, abs=1e-12)
    z = sol.frames.path(lc.al.t[lc.al.constraints[0].rows])[:, 2]
    assert np.all(z - (top_limit(lc) + raised.amount) <= TOL + 1e-9)  # every pair within the certified raise


def test_a_raised_limit_puts_the_least_violation_in_the_middle_of_its_tolerance(standing):
    """No z meets both bounds: the search raises `top` so that the path reaching the least violation holds it at
    half its tolerance (c/tol = 1/2 on the raised limit), leaving the least change that follows half a tolerance
    either way; that change ends within half a tolerance of the least violation, not a whole one beyond it."""
    z0 = standing[2]
    top, bottom = z0 - 0.10, z0 - 0.04
    lc = _problem(standing, top=top, bottom=bottom, keyed=False)
    al = lc.al.posed()
    frames = _start_frames(replace(lc, al=al), LeastChangeOptions().min_gap)
    cert = least_violation(al, frames, lc.layout.quat_slots, min_gap=0.01, ftol_rel=1e-3, per_level=8)
    (raised,) = cert.raises
    state = al.state(SplineBasis(cert.frames.times, al.t), cert.frames.values)
    assert al.constraints[0].values(state).max() / TOL == pytest.approx(0.5, abs=1e-9)
    z = float(cert.frames.path(np.array([T_STAR]))[0, 2])
    assert raised.amount == pytest.approx(z - top, abs=1e-12)  # the least violation, from the limit as posed
    sol = solve_least_change(lc, LeastChangeOptions())
    assert sol.status is Status.INFEASIBLE
    assert _z(sol) - top <= sol.unmet["top"] + TOL / 2 + 1e-9


def test_a_solve_leaves_its_problem_as_posed(standing):
    """The solve raises limits and updates multipliers on its own copy: the problem's limits are unchanged
    after it, and the same problem solved again gives the same path."""
    z0 = standing[2]
    lc = _problem(standing, top=z0 - 0.005, bottom=z0 - 0.5, half=0.02)  # a keyed excess: a limit is raised
    posed = [c.limit.copy() for c in lc.al.constraints]
    first = solve_least_change(lc, LeastChangeOptions())
    assert first.certificate  # something was raised
    for c, limit in zip(lc.al.constraints, posed):
        np.testing.assert_array_equal(c.limit, limit)
    assert all(not np.any(lam) for lam in lc.al.lam)
    again = solve_least_change(lc, LeastChangeOptions())
    np.testing.assert_allclose(again.frames.path(lc.al.t), first.frames.path(lc.al.t), rtol=0, atol=1e-12)


def test_finer_frames_do_not_beat_the_certificate(standing):
    """The least violation on the start frames with a frame every min_gap around t* is no smaller."""
    z0 = standing[2]
    top, bottom = z0 - 0.10, z0 - 0.04
    amounts = []
    for fine in (False, True):
        lc = _problem(standing, top=top, bottom=bottom, keyed=False)
        o = LeastChangeOptions()
        frames = _start_frames(lc, o.min_gap)
        if fine:
            extra = np.arange(0.2, 0.6, o.min_gap / 2)
            frames = with_frames(frames, extra[np.min(np.abs(extra[:, None] - frames.times[None]), axis=1) >= o.min_gap],
                                 lc.layout.quat_slots)
        cert = least_violation(lc.al, frames, lc.layout.quat_slots, min_gap=o.min_gap, ftol_rel=o.ftol_rel,
                               per_level=o.per_level)
        amounts.append(cert.unmet["top"])
        state = lc.al.state(SplineBasis(cert.frames.times, lc.al.t), cert.frames.values)
        assert all(float((c.values(state) / c.tolerance).max()) <= 1.0 for c in lc.al.constraints)
    assert amounts[1] >= amounts[0] - TOL


def test_multipliers_are_nonnegative_and_complementary_at_the_solution(standing):
    """KKT at the least change's end: every multiplier >= 0 and zero on a pair well inside its bound."""
    z0 = standing[2]
    lc = _problem(standing, top=z0 - 0.05, bottom=z0 - 0.20, keyed=False)
    sol = solve_least_change(lc, LeastChangeOptions())
    assert sol.certificate == ()  # feasible: the limits as posed are the solve's
    state = lc.al.state(SplineBasis(sol.frames.times, lc.al.t), sol.frames.values)
    assert [name for name, _ in sol.multipliers] == [c.name for c in lc.al.constraints]
    for c, (_, lam) in zip(lc.al.constraints, sol.multipliers):
        ch = c.values(state) / c.tolerance
        assert np.all(lam >= 0.0)
        assert np.all(lam[ch < -1.0] == 0.0), c.name  # inactive beyond a tolerance: no multiplier
    assert dict(sol.multipliers)["top"][0] > 0.0  # the active bound bears the pull of D



def test_a_bound_of_your_own_through_the_public_api(standing):
    """`ProblemSpec.bounds` (docs/design.md "A constraint of your own"): the pelvis held 5 mm under its keyed
    height at the key is certified at those 5 mm by `solver.solve_problem`, beside the figure's own
    constraints, which the still figure meets; a make(t) that returns no Constraint is one clear error."""
    model, still, z0 = standing

    def under(t):
        return PelvisHeight("pelvis ceiling", t, T_STAR, +1, z0 - 0.005, LIMIT, half=0.02)

    problem = solver.build_problem(model, solver.ProblemSpec(still, bounds=(under,)))
    sol = solver.solve_problem(problem, LeastChangeOptions())
    assert [r.constraint for r in sol.certificate] == ["pelvis ceiling"]
    assert sol.certificate[0].amount == pytest.approx(0.005, abs=1e-9) and sol.status is Status.INFEASIBLE
    # checked at twice the rate (the search's segments halved): the keyed 5 mm there too, whichever is kept
    rate, _, other = sol.finer
    assert rate == 2 * LeastChangeOptions().rate
    assert [r.constraint for r in other] == ["pelvis ceiling"] and other[0].amount == pytest.approx(0.005, abs=1e-9)
    with pytest.raises(solver.InputError, match="not a solver.Constraint"):
        solver.solve_problem(solver.build_problem(model, solver.ProblemSpec(still, bounds=(lambda t: 3.0,))))


def test_a_certificate_a_finer_search_beats_is_not_proved_when_the_budget_ends(standing, monkeypatch):
    """Where the check at a finer spacing finds the limits can be met but its least change is cut by the budget,
    the coarse path comes back with the budget's status, not INFEASIBLE, and the summary does not call its
    raised limits certified (an unseen MediaPipe clip under --max-time printed 'out of reach' beside a finer
    search that raised nothing). The finer search and solve are stood in for: their answers are the case."""
    from types import SimpleNamespace

    import solver.least_change as least_change
    from runner.certificate_text import certificate_lines
    from solver.animate import _built, _checked_finer

    model, still, z0 = standing
    problem = solver.build_problem(model, solver.ProblemSpec(still, bounds=(
        lambda t: PelvisHeight("pelvis ceiling", t, T_STAR, +1, z0 - 0.005, LIMIT, half=0.02),)))
    options = LeastChangeOptions()
    coarse = least_change.solve_least_change(_built(problem, options.rate), options)
    assert coarse.status is Status.INFEASIBLE and coarse.certificate
    monkeypatch.setattr(least_change, "least_violation_of",
                        lambda *a, **k: SimpleNamespace(status=Status.CONVERGED, raises=(), n_evals=3))
    monkeypatch.setattr(least_change, "solve_least_change", lambda *a, **k: replace(
        coarse, status=Status.MAX_TIME, message="time limit of 1 s reached", certificate=(), n_evals=5))
    out = _checked_finer(problem, options, coarse, None, None)
    assert out.status is Status.MAX_TIME and "not proved out of reach" in out.message
    assert out.certificate == coarse.certificate and out.finer == (2 * options.rate, False, ())
    np.testing.assert_array_equal(out.frames.values, coarse.frames.values)
    said = " ".join(certificate_lines(out))
    assert "certified" not in said and "not proved out of reach" in said
    assert "certified" in " ".join(certificate_lines(coarse))


class TwoWells(Constraint):
    """A bound no path meets, with two local least violations: c(z) = min((z - za)^2 / S + ea, (z - zb)^2 / S
    + eb) <= 0 at t* (z the pelvis height [m], S = 1 cm): its violation is least, ea, at z = za and, less,
    eb at z = zb, with a ridge of 6 cm between (half the 10 cm between the wells, squared over S)."""

    unit, scale, tolerance, name, priority, S = "m", 1.0, TOL, "wells", LIMIT, 0.01

    def __init__(self, t_points, za, ea, zb, eb):
        self.rows = np.array([int(np.argmin(np.abs(t_points - T_STAR)))])
        self.labels, self.limit = np.array(["pelvis"], object), np.zeros(1)
        self.wells = ((za, ea), (zb, eb))

    def _each(self, state):
        z = state.Y[self.rows, 2]
        return np.stack([(z - w) ** 2 / self.S + e for w, e in self.wells])

    def measure(self, state):
        return self._each(state).min(axis=0)

    def pull(self, state, g):
        z, each = state.Y[self.rows, 2], self._each(state)
        w = np.array([w for w, _ in self.wells])[np.argmin(each, axis=0)]
        np.add.at(state.gY[:, 2], self.rows, g * 2.0 * (z - w) / self.S)


def test_the_capture_start_certifies_the_lower_of_two_local_least_violations(standing):
    """The least change's path stands in the well of 5 mm (z0), the capture the keys came from dips the
    pelvis into the well of 2 mm 10 cm lower at t*: the certificate is the capture's 2 mm, and the path
    returned reaches it; without the capture the search from the least change's path alone stays at 5 mm."""
    model, still, z0 = standing
    mask = still.mask.copy()
    mask[1, 2] = False  # the middle key leaves the pelvis height free
    lc = build_least_change(model, replace(still, mask=mask), rate=200.0)
    old = lc.al
    lc = replace(lc, al=AugmentedLagrangian(old.change, [TwoWells(old.t, z0, 0.005, z0 - 0.1, 0.002)], old.tmap,
                                           old.engine, old.d0))
    times = np.linspace(0.0, 0.8, 97)  # a 120 Hz capture through the keys: the pelvis 10 cm lower at t*
    qpos = np.tile(still.values[0], (len(times), 1))
    qpos[:, 2] -= 0.1 * np.sin(np.pi * times / 0.8) ** 2 / np.sin(np.pi * T_STAR / 0.8) ** 2
    amounts = {}
    for capture in (None, (times, qpos)):
        sol = solve_least_change(replace(lc, capture=capture), LeastChangeOptions())
        (raised,) = sol.certificate
        amounts[capture is None] = raised.amount
        assert sol.status is Status.INFEASIBLE and raised.constraint == "wells"
        state = lc.al.state(SplineBasis(sol.frames.times, lc.al.t), sol.frames.values)
        assert lc.al.constraints[0].values(state)[0] <= raised.amount + TOL  # the path reaches the certificate
    assert amounts[False] == pytest.approx(0.002, abs=TOL)  # the capture's well
    assert amounts[True] == pytest.approx(0.005, abs=TOL)  # the premise: one start alone stays in its well


def test_a_bound_at_a_keyframe_is_sought_there(standing):
    """A key at 0.4 s, between the midpoints (a quadrature point of weight 0, `quadrature_points`), leaves the
    pelvis height free, and a bound holds it 5 cm under the still height there: a path meets it, so the
    solve meets it and raises nothing (a pair of weight 0 would be checked but never priced, and raised)."""
    model, still, z0 = standing
    mask = still.mask.copy()
    mask[1, 2] = False
    lc = build_least_change(model, replace(still, times=np.array([0.0, 0.4, 0.8]), mask=mask), rate=200.0)
    old = lc.al
    assert np.min(np.abs(old.t - 0.4)) == 0.0  # the key is a point
    bound = PelvisHeight("top", old.t, 0.4, +1, z0 - 0.05, SCHEDULE)
    lc = replace(lc, al=AugmentedLagrangian(old.change, [bound], old.tmap, old.engine, old.d0))
    sol = solve_least_change(lc, LeastChangeOptions())
    assert sol.status is Status.CONVERGED and sol.certificate == ()
    assert float(sol.frames.path(np.array([0.4]))[0, 2]) <= z0 - 0.05 + TOL


def test_the_elastic_measures_count_a_pair_only_beyond_their_aims(standing):
    """solver.feasibility's two measures, v = max(0, c/tol - aim): the squares (1/2) sum (w_p/T) v^2 from
    aim = 1 - ftol_rel, and the sum sum (w_p/T) huber_d(v) from aim = 1/2, d = 1 - aim: v^2 / (2 d) up to the
    tolerance's edge, v - d/2 beyond. Nothing for a pair below the aim (against numpy on the pelvis's own
    height), and the gradient agrees with central differences in every part."""
    model, still, z0 = standing
    lc = build_least_change(model, still, rate=200.0)
    old = lc.al
    frames = with_frames(_start_frames(lc, 1 / 48), np.array([0.2, 0.6]), StateLayout.from_model(model).quat_slots)
    basis = SplineBasis(frames.times, old.t)
    # c/tol -0.5 (below both aims), 0.8 (met; beyond the sum's aim: its squared part), 3 (broken: the sum's linear part)
    for top, count in ((z0 + 0.5 * TOL, (False, False)), (z0 - 0.8 * TOL, (False, True)), (z0 - 3 * TOL, (True, True))):
        bound = PelvisHeight("top", old.t, T_STAR, +1, top, SCHEDULE, half=0.05)
        for elastic_sum, aim, beyond in ((False, 1.0 - 1e-3, count[0]), (True, RAISED_AT, count[1])):
            eal = AugmentedLagrangian(old.change, [], old.tmap, old.engine, old.d0, elastic=[bound], aim=aim,
                                      elastic_sum=elastic_sum)
            F, G, _ = eal.evaluate(basis, frames.values)
            z = frames.path(old.t[bound.rows])[:, 2]
            w = eal.w_elastic[0]
            v, d = np.maximum(0.0, (z - top) / TOL - aim), 1.0 - aim
            expected = float(w @ (np.where(v <= d, 0.5 * v * v / d, v - 0.5 * d) if elastic_sum else 0.5 * v * v))
            assert (expected > 0) == beyond
            np.testing.assert_allclose(F, expected, rtol=1e-10, atol=1e-18)  # two computations of the heights
            if beyond:
                free = np.flatnonzero(~frames.fixed[:, 2])
                h = 1e-6
                for i in free[:2]:
                    v = [frames.values.copy() for _ in range(2)]
                    v[0][i, 2] += h
                    v[1][i, 2] -= h
                    fd = (eal.evaluate(basis, v[0], grad=False)[0] - eal.evaluate(basis, v[1], grad=False)[0]) / (2 * h)
                    np.testing.assert_allclose(G[i, 2], fd, rtol=1e-5, atol=1e-9)


class WindowMean(Constraint):
    """An integral bound: the pelvis height's mean over the quadrature points within `half` [s] of t*, by their
    weights, <= limit [m] (one pair, the contact schedule's priority, like a planted foot's mean height)."""

    name, unit, scale, tolerance, priority = "window mean", "m", 1.0, TOL, SCHEDULE

    def __init__(self, t_points, weights, half, limit):
        self.points = np.flatnonzero(np.abs(t_points - T_STAR) <= half)
        self.w = weights[self.points] / weights[self.points].sum()
        self.rows, self.labels = np.array([self.points[len(self.points) // 2]]), np.array(["pelvis"], object)
        self.limit = np.array([float(limit)])

    def pair_weights(self, weights):
        return np.array([float(weights[self.points].sum())])

    def measure(self, state):
        return np.array([self.w @ state.Y[self.points, 2]])

    def pull(self, state, g):
        np.add.at(state.gY[:, 2], self.points, g[0] * self.w)


class VerticalAcceleration(Constraint):
    """|z''| <= A at every quadrature point [m/s^2] (the body's limit: the highest priority), tolerance 1 % of A."""

    name, unit, scale, priority = "vertical acceleration", "m/s^2", 1.0, LIMIT

    def __init__(self, n, A):
        self.rows, self.sign = np.r_[np.arange(n), np.arange(n)], np.r_[np.ones(n), -np.ones(n)]
        self.labels, self.limit, self.tolerance = np.full(2 * n, "pelvis", object), np.full(2 * n, float(A)), 0.01 * A

    def measure(self, state):
        return self.sign * state.Y2[self.rows, 2]

    def pull(self, state, g):
        np.add.at(state.gY2[:, 2], self.rows, self.sign * g)


def test_an_integral_bound_under_a_limit_is_certified_at_its_closed_form(standing):
    """The pelvis keyed at its standing height z0 at t*, its mean over t* +- w wished 5 cm lower (SCHEDULE) while
    |z''| <= A (LIMIT). Any path through the key has z(t) = z0 + z'(t*)(t - t*) + int_t*^t (t - s) z''(s) ds, whose
    mean over the window is least with z'' = -A throughout: z0 - A w^2 / 6. So the least violation is
    0.05 - A w^2 / 6 (4.33 cm at A = 4 m/s^2, w = 0.1 s), within what the limit's 1 % tolerance and the
    bound's own allow; the path returned reaches it and holds the limit; a start with a frame every two
    quadrature intervals does not beat it."""
    model, still, z0 = standing
    A, w = 4.0, 0.1
    lc = build_least_change(model, still, rate=200.0)
    old = lc.al
    cons = [WindowMean(old.t, old.change.ref.weights, w, z0 - 0.05), VerticalAcceleration(len(old.t), A)]
    lc = replace(lc, al=AugmentedLagrangian(old.change, cons, old.tmap, old.engine, old.d0))
    least = 0.05 - A * w * w / 6.0
    slack = 0.01 * A * w * w / 6.0 + TOL  # [m] the limit met within its tolerance, the bound within its own
    sol = solve_least_change(lc, LeastChangeOptions())
    (raised,) = sol.certificate
    assert raised.constraint == "window mean" and sol.status is Status.INFEASIBLE
    assert raised.amount == pytest.approx(least, abs=slack)
    state = lc.al.state(SplineBasis(sol.frames.times, lc.al.t), sol.frames.values)
    assert cons[0].values(state)[0] <= raised.amount + TOL
    assert np.abs(state.Y2[:, 2]).max() <= 1.01 * A
    o = LeastChangeOptions()
    frames = _start_frames(lc, o.min_gap)
    fine = np.arange(0.01, 0.8, 0.01)
    frames = with_frames(frames, fine[np.min(np.abs(fine[:, None] - frames.times[None]), axis=1) > 0.005],
                         lc.layout.quat_slots)
    cert = least_violation(lc.al.posed(), frames, lc.layout.quat_slots, min_gap=2.0 / 200.0, ftol_rel=o.ftol_rel,
                           per_level=o.per_level)
    assert cert.unmet["window mean"] >= least - slack


def test_a_finer_certificate_beats_only_one_it_raises_no_more_than_anywhere():
    """`solver.animate._beats`, on Raises built by hand: the finer spacing's certificate is kept where it raises
    nothing the coarse one does not, nothing by more, and is not the same."""
    from solver.animate import _beats
    from solver.feasibility import Raise

    def raised(name, label, amount):
        return Raise(name, label, amount, 1.0, 1.0, 1.0, 1)

    coarse = (raised("acceleration", "r_elbow", 1108.0), raised("flight", "r_toe", 0.0099))
    assert _beats((), coarse)  # nothing raised at the finer spacing
    assert _beats((raised("acceleration", "r_elbow", 584.0), coarse[1]), coarse)  # one raised by less
    assert _beats((coarse[1],), coarse)  # one fewer
    assert not _beats(coarse, coarse)  # the same: the coarse answer stands
    assert not _beats((raised("acceleration", "r_elbow", 3191.0),), coarse)  # more at one column
    assert not _beats((raised("acceleration", "l_elbow", 1.0),), coarse)  # a column the coarse did not raise
    assert not _beats((), ())


def test_the_elastic_solve_returns_a_path_that_meets_what_it_held(standing, monkeypatch):
    """A path refined after the last solve that met the held pairs moves between its old frames, and can break
    one; the elastic solve then returns the last path that met them (an unseen MediaPipe dance crashed when
    neither start met them at the next level). The refinement is stood in for: every new frame drops the pelvis
    5 cm, below `bottom` (held over 0.1 s about t*), and one solve per frame set (its penalty at rho = 1) does
    not bring it back before the next refinement."""
    import solver.feasibility as feasibility

    z0 = standing[2]
    top, bottom = z0 - 0.10, z0 - 0.04
    lc = _problem(standing, top=top, bottom=bottom, keyed=False, half=0.05)
    real = feasibility.with_frames

    def dropped(frames, times, quat_slots):
        out = real(frames, times, quat_slots)
        new = np.isin(out.times, times)
        values = out.values.copy()
        values[new, 2] -= 0.05
        return replace(out, values=values)

    monkeypatch.setattr(feasibility, "with_frames", dropped)
    al = lc.al
    start = _start_frames(lc, 0.01)
    held, objective = [al.constraints[1]], [al.constraints[0]]
    got = feasibility._elastic_solve(al, objective, held, start, lc.layout.quat_slots, feasibility._Budget(0, 0.0, None),
                                     min_gap=0.01, ftol_rel=1e-6, per_level=1, pairs=None)
    assert feasibility._meets(al, held, got)  # the held bound within its tolerance at every point it holds at
