"""Contact-schedule terms (docs/contacts.md "The contact terms"): planted, clearance, friction cone. Gradients against central
finite differences (Y, Y', Y''), values against hand-built cases on the toy figure of conftest.py.

Toy figure at identity rotations with the root at (x, y, z): l_heel at (x - .05, y + .1, z - .95),
l_toe at (x + .15, y + .1, z - .95), r_* at y - .1. Floor plane z = 0, box "step" with top z = .2 over
x in [1.1, 1.9]."""
from dataclasses import replace

import mujoco
import numpy as np
import pytest

from solver.contacts import Contact
from solver.errors import InputError
from solver.layout import StateLayout
from solver.path_context import PathContext
from solver.terms.clearance import FLIGHT_LIFT, Clearance
from solver.terms.contact import Planted, contact_window, flights, smoothstep, swings
from solver.terms.contact_wrench import FrictionCone, cone_metrics

from conftest import fd_gradient, random_qpos

FOOT = 0.95  # root height minus site height at identity rotations



@pytest.fixture(scope="module")
def layout(toy_model):
    return StateLayout.from_model(toy_model)


def standing(layout, n, root=(0.0, 0.0, FOOT)):
    """(n, nq) identity pose with the root at `root`."""
    Y = np.zeros((n, layout.nq))
    Y[:, :3] = root
    Y[:, layout.quat_slots[:, 0]] = 1.0
    return Y


def midpoints(t0, t1, n):
    """Midpoint-rule nodes and step."""
    h = (t1 - t0) / n
    return t0 + h * (np.arange(n) + 0.5), h


def check_gradient(term, t, Y, Y1, Y2, rtol=1e-6):
    """Largest |analytic - central FD| relative to the largest gradient entry, per argument."""
    ev = term.evaluate(t, Y, Y1, Y2, grad=True)
    errs = []
    for k, (X, g) in enumerate(((Y, ev.dY), (Y1, ev.dY1), (Y2, ev.dY2))):
        if k not in term.needs:
            assert g is None or not np.any(g)
            continue

        def f(Z, k=k):
            args = [Y, Y1, Y2]
            args[k] = Z
            return term.evaluate(t, *args, grad=False).f.sum()

        G = fd_gradient(f, X)
        assert np.abs(G).max() > 0, f"d/dY{k} is zero: the check checks nothing"
        err = np.abs(g - G).max() / np.abs(G).max()
        assert err < rtol, f"d/dY{k}: relative error {err:.3g}"
        errs.append(err)
    return errs


# ---------------------------------------------------------------------------------------------------
# schedule helpers


def test_windows_swings_and_flights():
    t = np.array([0.0, 0.05, 0.1, 0.5, 0.9, 0.95, 1.0, 1.1])
    np.testing.assert_allclose(contact_window(t, 0.0, 1.0, 0.0), [1, 1, 1, 1, 1, 1, 1, 0])
    w = contact_window(t, 0.0, 1.0, 0.1)
    np.testing.assert_allclose(w, [0, 0.5, 1, 1, 1, 0.5, 0, 0])
    run = [Contact("l_toe", 0.0, 0.3), Contact("r_toe", 0.4, 0.7), Contact("l_toe", 0.8, 1.1)]
    assert flights(run) == [(0.3, 0.4), (0.7, 0.8)]
    assert swings(run, "l_toe") == [(0.3, 0.8)]
    assert swings(run, "r_toe") == []
    walk = [Contact("l_heel", 0.0, 0.6), Contact("r_heel", 0.5, 1.1), Contact("l_heel", 1.0, 1.6)]
    assert flights(walk) == []


def test_bad_contacts_are_input_errors(toy_model):
    with pytest.raises(InputError, match=r"^contact 0: 'site' is 'nose'; the figure's contact sites are l_heel"):
        Planted(toy_model, [Contact("nose", 0, 1)])
    with pytest.raises(InputError, match=r"^contact 1: 'end' 0.5 is not after 'start' 1; swap them$"):
        Planted(toy_model, [Contact("l_toe", 0, 1), Contact("l_toe", 1, 0.5)])
    with pytest.raises(InputError, match=r"^contact 0: 'surface' is 'moon', which the scene does not have; its "
                                         r"surfaces are floor"):
        Clearance(toy_model, [Contact("l_toe", 0, 1, "moon")])


# ---------------------------------------------------------------------------------------------------
# planted


def test_planted_gradient(toy_model, layout):
    rng = np.random.default_rng(3)
    n = 7
    Y = random_qpos(rng, layout, n)
    Y1, Y2 = rng.normal(size=Y.shape), rng.normal(size=Y.shape)
    t = np.linspace(0, 1, n)
    contacts = [Contact("l_heel", 0.1, 0.7), Contact("r_toe", 0.0, 0.4, "step"), Contact("l_toe", 0.5, 1.0)]
    check_gradient(Planted(toy_model, contacts, ramp=0.15), t, Y, Y1, Y2)


def test_planted_held_height_integrates_to_h2_T(toy_model, layout):
    h, T = 0.03, 0.6
    t, dt = midpoints(0.0, 1.0, 1000)
    Y = standing(layout, len(t), (0.0, 0.0, FOOT + h))
    Z = np.zeros_like(Y)
    term = Planted(toy_model, [Contact("l_heel", 0.2, 0.2 + T)], ramp=0.0, rest_height=0.0)
    assert term.evaluate(t, Y, Z, Z).f.sum() * dt == pytest.approx(h * h * T, rel=1e-9)
    # the default rest height is the penetration margin, 5 mm: (h - 0.005)^2 T
    term = Planted(toy_model, [Contact("l_heel", 0.2, 0.2 + T)], ramp=0.0)
    assert term.evaluate(t, Y, Z, Z).f.sum() * dt == pytest.approx((h - 0.005) ** 2 * T, rel=1e-9)
    assert term.violation(Y, t) == pytest.approx(h - 0.005)
    # the ramps are the sliding window's only: the height counts over the whole contact, h^2 T
    term = Planted(toy_model, [Contact("l_heel", 0.2, 0.2 + T)], ramp=0.1, rest_height=0.0)
    assert term.evaluate(t, Y, Z, Z).f.sum() * dt == pytest.approx(h * h * T, rel=1e-9)
    assert term.violation(Y, t) == pytest.approx(h)


def test_planted_height_counts_at_the_contact_ends_sliding_is_ramped(toy_model, layout):
    """A foot up at touch-down and lift-off pays in full (the float metric counts every frame of a
    contact; before, the height shared the sliding window's 20 ms ramps and a foot 1-3 cm up at a
    contact's ends cost almost nothing), a foot sliding there pays on the ramp only."""
    h, u, T, r, tau = 0.02, 0.5, 0.4, 0.05, 0.1
    start, end = 0.3, 0.3 + T
    t = np.array([start, start + 0.25 * r, end - 0.5 * r, end, end + 0.01])
    Y = standing(layout, len(t), (0.0, 0.0, FOOT + h))  # l_heel h up
    Z = np.zeros_like(Y)
    term = Planted(toy_model, [Contact("l_heel", start, end)], velocity_time=tau, ramp=r, rest_height=0.0)
    assert term.evaluate(t, Y, Z, Z).f == pytest.approx([h * h] * 4 + [0.0], rel=1e-9)
    np.testing.assert_allclose(term.height_windows(t)[:, 0], [1, 1, 1, 1, 0])
    np.testing.assert_allclose(term.windows(t)[:, 0], [0, 0.15625, 0.5, 0, 0])  # smoothstep(1/4), (1/2)
    Y1 = np.zeros_like(Y)
    Y1[:, 0] = u  # sliding along x at u, on the floor
    Y[:, 2] = FOOT
    assert term.evaluate(t, Y, Y1, Z).f == pytest.approx(tau**2 * u**2 * np.array([0, 0.15625, 0.5, 0, 0]), abs=1e-15)


def test_planted_sliding_foot_costs_tau2_u2_T_and_normal_velocity_is_free(toy_model, layout):
    u, T, tau = 0.5, 0.4, 0.1
    t, dt = midpoints(0.0, 1.0, 1000)
    Y = standing(layout, len(t))
    Y1 = np.zeros_like(Y)
    Y1[:, 0] = u  # the whole figure slides along x at u
    Y[:, 0] = u * t
    term = Planted(toy_model, [Contact("r_toe", 0.3, 0.3 + T)], velocity_time=tau, ramp=0.0, rest_height=0.0)
    assert term.evaluate(t, Y, Y1, None).f.sum() * dt == pytest.approx(tau**2 * u**2 * T, rel=1e-9)
    # violation from finite differences of the positions alone: tau * u
    assert term.violation(Y, t) == pytest.approx(tau * u, rel=1e-6)
    Y1[:, 2] = 0.3  # moving along the normal: only the height term sees it
    assert term.evaluate(t, Y, Y1, None).f.sum() * dt == pytest.approx(tau**2 * u**2 * T, rel=1e-9)


def test_planted_surface_under_the_site(toy_model, layout):
    h = 0.02
    t = np.array([0.5])
    Y = standing(layout, 1, (1.5 + 0.05, 0.0, 0.2 + FOOT + h))  # l_heel over the step's top
    Z = np.zeros_like(Y)
    auto = Planted(toy_model, [Contact("l_heel", 0.0, 1.0)], ramp=0.0, rest_height=0.0)
    assert auto.evaluate(t, Y, Z, Z).f[0] == pytest.approx(h * h)
    floor = Planted(toy_model, [Contact("l_heel", 0.0, 1.0, "floor")], ramp=0.0, rest_height=0.0)
    assert floor.evaluate(t, Y, Z, Z).f[0] == pytest.approx((0.2 + h) ** 2)
    Y[:, 0] = 0.5  # beside the step: the floor is under the site
    Y[:, 2] = FOOT + h
    assert auto.evaluate(t, Y, Z, Z).f[0] == pytest.approx(h * h)


def test_planted_is_zero_outside_contacts(toy_model, layout):
    rng = np.random.default_rng(4)
    Y = random_qpos(rng, layout, 3)
    t = np.array([0.0, 0.5, 2.0])
    ev = Planted(toy_model, [Contact("l_toe", 0.6, 1.9)]).evaluate(t, Y, rng.normal(size=Y.shape), None)
    assert not ev.f.any() and not ev.dY.any() and not ev.dY1.any()


# ---------------------------------------------------------------------------------------------------
# clearance

WALK = [Contact("l_toe", 0.0, 0.4), Contact("l_toe", 1.0, 1.4), Contact("r_toe", 0.3, 1.1)]


def test_clearance_gradient(toy_model, layout):
    rng = np.random.default_rng(5)
    n = 8
    Y = random_qpos(rng, layout, n)
    Y[:, 2] = rng.uniform(0.9, 1.2, n)  # sites within the 0.25 m band of the floor/step at some points
    Y[:, 0] = rng.uniform(0.8, 2.0, n)
    t = np.linspace(0.45, 0.95, n)
    term = Clearance(toy_model, WALK, clearance=0.25, core=0.4)
    check_gradient(term, t, Y, None, None)


def test_clearance_value_in_the_swing(toy_model, layout):
    c, z = 0.02, 0.005
    t = np.array([0.2, 0.4, 0.55, 0.7, 0.85, 1.0, 1.2, 1.6])
    Y = standing(layout, len(t), (0.0, 0.0, FOOT + z))
    term = Clearance(toy_model, WALK, clearance=c, core=0.5)
    f = term.evaluate(t, Y, None, None).f
    # l_toe's swing (0.4, 1.0): weight 1 on [0.55, 0.85], 0 at its ends; r_toe has no gap; no flights
    np.testing.assert_allclose(f, [0, 0, (c - z) ** 2, (c - z) ** 2, (c - z) ** 2, 0, 0, 0], atol=1e-15)
    assert term.violation(Y, t) == pytest.approx(c - z)
    Y[:, 2] = FOOT + 0.05  # clear
    assert not term.evaluate(t, Y, None, None).f.any()
    assert term.violation(Y, t) == 0.0


def test_a_keyframe_low_in_a_swing_lowers_that_swings_band(toy_model, layout):
    """A keyframe at t = 0.7 holds l_toe 5 mm up in the middle of its swing (0.4, 1.0): its band in that
    swing drops to 5 mm, in the objective too (a path through the keyframe that had to be 2 cm up
    around it would shoot the foot up between keyframes), and the swing leaves the bound."""
    c, z = 0.02, 0.005
    term = Clearance(toy_model, WALK, clearance=c, core=0.5)
    t = np.array([0.55, 0.7, 0.85])
    Y = standing(layout, len(t), (0.0, 0.0, FOOT + z))
    before = term.evaluate(t, Y, None, None).f
    np.testing.assert_allclose(before, (c - z) ** 2, atol=1e-15)
    got = term.conflicts(np.array([0.7]), standing(layout, 1, (0.0, 0.0, FOOT + z)))
    assert [(kind, i, s) for kind, i, s, _ in got.found] == [("clearance", 0, "l_toe")]
    assert got.found[0][3] == pytest.approx(c - z)
    assert got.swings == {("l_toe", 0.4, 1.0)} and dict(got.lowered) == {("l_toe", 0.4, 1.0): pytest.approx(z)}
    np.testing.assert_allclose(term.evaluate(t, Y, None, None).f, before, atol=1e-15)  # a query: unchanged
    excused = Clearance(toy_model, WALK, clearance=c, core=0.5, conflicts=got)  # built with what it found
    assert not excused.evaluate(t, Y, None, None).f.any()  # the path at the keyframe's height: no penalty
    Y[:, 2] = FOOT + 0.002  # lower than the keyframe: penalized against the lowered band
    np.testing.assert_allclose(excused.evaluate(t, Y, None, None).f, (z - 0.002) ** 2, atol=1e-15)
    assert excused.violation(Y, t) is None  # that swing is excused from the bound
    np.testing.assert_allclose(term.evaluate(t, Y, None, None).f, (c - 0.002) ** 2, atol=1e-15)  # 2 cm band
    assert term.violation(Y, t) == pytest.approx(c - 0.002)


def test_clearance_keeps_flights(toy_model, layout):
    run = [Contact("l_toe", 0.0, 0.3), Contact("r_toe", 0.4, 0.7)]
    t = np.array([0.35])  # the middle of the flight: every site counts
    Y = standing(layout, 1, (0.0, 0.0, FOOT))
    term = Clearance(toy_model, run, clearance=0.02)
    # the flight lasts 0.1 s: a ballistic body rises g T^2 / 8 = 12.3 mm in it (c_f, < c = 2 cm), but
    # the feet of a run's short flight rise above the 3 cm flight height: the lift, 50 ms after take-off
    # and before landing, is FLIGHT_LIFT * min(1, 0.05 / 0.035, 0.05 / 0.05) = 3.5 cm
    cf = 9.81 * 0.1**2 / 8
    np.testing.assert_allclose(term.flight_bands, [cf], rtol=1e-12)
    lift = FLIGHT_LIFT
    assert term.evaluate(t, Y, None, None).f[0] == pytest.approx(4 * lift**2, rel=1e-12)
    short = Clearance(toy_model, run, clearance=0.02, flight_lift=None)  # no lift: the band is c_f
    assert short.evaluate(t, Y, None, None).f[0] == pytest.approx(4 * cf**2, rel=1e-12)
    long = Clearance(toy_model, [Contact("l_toe", 0.0, 0.3), Contact("r_toe", 0.6, 0.7)], clearance=0.02)
    np.testing.assert_allclose(long.flight_bands, [0.02])  # 0.3 s: g T^2 / 8 = 11 cm, capped at c
    # ... and lifted up to FLIGHT_LIFT in its middle
    assert long.evaluate(np.array([0.45]), Y, None, None).f[0] == pytest.approx(4 * FLIGHT_LIFT**2, rel=1e-12)
    unlifted = Clearance(toy_model, long.contacts, clearance=0.02, flight_lift=None)
    assert unlifted.evaluate(np.array([0.45]), Y, None, None).f[0] == pytest.approx(4 * 0.02**2, rel=1e-12)
    fixed = Clearance(toy_model, run, clearance=0.02, flight_clearance=0.02)
    assert fixed.evaluate(t, Y, None, None).f[0] == pytest.approx(4 * 0.02**2, rel=1e-12)
    nofl = Clearance(toy_model, run, clearance=0.02, flight=False)
    assert nofl.evaluate(t, Y, None, None).f[0] == 0.0


def test_a_flights_band_is_lifted(toy_model, layout):
    """A flight (0.3, 0.65) of 0.35 s (a hop): the band is max(c_f, FLIGHT_LIFT * min(1, (t - a) / 35 ms,
    (b - t) / 50 ms)), up to 3.5 cm (above the 3 cm of the flight metric): c_f (2 cm) just after take-off
    and just before landing, the linear ramps, and the ceiling in between."""
    hop = [Contact("l_toe", 0.0, 0.3), Contact("r_toe", 0.65, 0.9)]
    term = Clearance(toy_model, hop, clearance=0.02)
    a, b = 0.3, 0.65
    t = np.array([0.301, 0.31, 0.33, 0.34, 0.45, 0.615, 0.635, 0.645])
    Y = standing(layout, len(t), (0.0, 0.0, FOOT))
    _, Uf, Bf, _ = term.split_windows(t)
    ramp = np.clip(np.minimum(np.minimum((t - a) / 0.035, (b - t) / 0.05), 1.0), 0.0, None)
    expected = np.maximum(0.02, FLIGHT_LIFT * ramp)
    np.testing.assert_allclose(Bf, expected, rtol=1e-12)
    assert Bf[0] == Bf[1] == Bf[6] == Bf[7] == 0.02 and Bf[3] == Bf[4] == FLIGHT_LIFT
    assert 0.02 < Bf[2] < FLIGHT_LIFT and 0.02 < Bf[5] < FLIGHT_LIFT
    np.testing.assert_allclose(term.evaluate(t, Y, None, None).f, 4 * Uf * expected**2, rtol=1e-12)
    assert term.violation(Y, np.array([0.45])) == pytest.approx(FLIGHT_LIFT)
    # the lift is a target, not a conflict: a keyframe at the top of the flight 3 cm up is not reported,
    # but it lowers the ceiling to 3 cm (a path held above it around the keyframe would bulge)
    key = standing(layout, 1, (0.0, 0.0, FOOT + 0.03))
    assert not term.conflicts(np.array([0.45]), key).found
    np.testing.assert_allclose(term.split_windows(np.array([0.45]))[2], [FLIGHT_LIFT])
    lowered = term.lower_lifts(np.array([0.45]), key)
    assert dict(lowered.lifts) == {(a, b): pytest.approx(0.03, rel=1e-9)}
    np.testing.assert_allclose(term.split_windows(np.array([0.45]))[2], [FLIGHT_LIFT])  # a query: unchanged
    built = Clearance(toy_model, hop, clearance=0.02, conflicts=lowered)
    np.testing.assert_allclose(built.split_windows(np.array([0.45]))[2], [0.03], rtol=1e-9)
    # keyframes just after take-off (low in every flight: the lift is below its ceiling there) keep it
    early = term.lower_lifts(np.array([0.305]), standing(layout, 1, (0.0, 0.0, FOOT + 0.003)))
    assert not early.lifts and not early.excuses
    fresh = Clearance(toy_model, hop, clearance=0.02, conflicts=early)
    np.testing.assert_allclose(fresh.split_windows(np.array([0.45]))[2], [FLIGHT_LIFT])
    with pytest.raises(InputError, match="flight_lift"):
        Clearance(toy_model, hop, flight_lift=-0.01)


@pytest.mark.parametrize("T", [0.083, 0.1, 0.125, 0.2, 0.35])
def test_short_and_long_flights_keep_the_band_above_the_flight_height(toy_model, T):
    """Every flight's band is above the flight metric's 3 cm for T - (35 + 50 ms) * 3 / 3.5 (the time
    the captured feet of a run's flights are up: T - 58..92 ms), short hops included (a ballistic band
    never reached 3 cm under 0.156 s)."""
    from solver.contact_thresholds import FLIGHT_HEIGHT

    a = 0.3
    term = Clearance(toy_model, [Contact("l_toe", 0.0, a), Contact("r_toe", a + T, a + T + 0.2)], clearance=0.02)
    t = np.linspace(a, a + T, 20001)
    above = (term.split_windows(t)[2] > FLIGHT_HEIGHT).mean() * T
    assert above == pytest.approx(max(0.0, T - 0.085 * FLIGHT_HEIGHT / FLIGHT_LIFT), abs=2 * T / 20000)


def test_flight_clearance_is_its_own_band(toy_model, layout):
    """c_f: every site keeps c_f in a flight's core, the swing cores keep c; the violation is the
    intrusion into the band of the window that weighs the site most."""
    run = [Contact("l_toe", 0.0, 0.3), Contact("r_toe", 0.4, 0.7), Contact("l_toe", 0.8, 1.0)]
    t = np.array([0.35, 0.55])  # flight core; l_toe's swing core (0.3, 0.8): 0.55 is its middle
    z = 0.015
    Y = standing(layout, 2, (0.0, 0.0, FOOT + z))
    term = Clearance(toy_model, run, clearance=0.02, flight_clearance=0.01)
    f = term.evaluate(t, Y, None, None).f
    # 0.35: the flight (all four sites 1.5 cm up, band 1 cm: nothing) and l_toe's swing (0.35 is in the
    # outer ramp of (0.3, 0.8): weight smoothstep((0.35 - 0.3) / 0.125)); 0.55: l_toe alone, band 2 cm
    w = smoothstep(np.array([0.05 / 0.125]))[0]
    np.testing.assert_allclose(f, [w * (0.02 - z) ** 2, (0.02 - z) ** 2], rtol=1e-12)
    assert term.violation(Y, t) == pytest.approx(0.02 - z)
    Y[:, 2] = FOOT + 0.004  # 4 mm up: inside both bands
    f = term.evaluate(t, Y, None, None).f
    assert f[0] == pytest.approx(4 * (0.01 - 0.004) ** 2 + w * (0.02 - 0.004) ** 2, rel=1e-12)
    with pytest.raises(InputError, match="flight_clearance"):
        Clearance(toy_model, run, flight_clearance=0.0)


def test_clearance_gradient_with_a_flight_band(toy_model, layout):
    rng = np.random.default_rng(11)
    run = [Contact("l_toe", 0.0, 0.3), Contact("r_toe", 0.4, 0.7), Contact("l_toe", 0.8, 1.0)]
    n = 8
    Y = random_qpos(rng, layout, n)
    Y[:, 2] = rng.uniform(0.9, 1.2, n)
    Y[:, 0] = rng.uniform(0.8, 2.0, n)
    t = np.linspace(0.31, 0.79, n)
    check_gradient(Clearance(toy_model, run, clearance=0.25, flight_clearance=0.15, core=0.4), t, Y, None, None)


# ---------------------------------------------------------------------------------------------------
# friction cone

STANCE = [Contact(s, 0.0, 1.0) for s in ("l_heel", "l_toe", "r_heel", "r_toe")]


def _mass_and_com(model, Y):
    d = mujoco.MjData(model)
    d.qpos[:] = Y
    mujoco.mj_kinematics(model, d)
    mujoco.mj_comPos(model, d)
    return float(model.body_mass.sum()), d.subtree_com[1].copy()


@pytest.mark.parametrize("mu", [0.8, 0.05])
def test_cone_gradient(toy_model, layout, mu):
    rng = np.random.default_rng(6)
    n = 6
    Y = random_qpos(rng, layout, n)
    Y1, Y2 = 0.3 * rng.normal(size=Y.shape), 0.3 * rng.normal(size=Y.shape)
    t = np.linspace(0, 1, n)
    contacts = [Contact("l_heel", 0.1, 0.7), Contact("l_toe", 0.1, 0.7), Contact("r_toe", 0.0, 0.3, "step"),
                Contact("l_heel", 0.9, 1.0)]
    term = FrictionCone(toy_model, contacts, mu=mu, ramp=0.2)
    check_gradient(term, t, Y, Y1, Y2)
    # the objective's form (the engine's part deferred to its shared reverse pass) gives the same gradient
    ev, dv = term.evaluate(t, Y, Y1, Y2), term.evaluate_in(PathContext(t, Y, Y1, Y2))
    pulled = dv.deferred.pullback()
    np.testing.assert_allclose(ev.dY, pulled[0] + dv.dY)
    np.testing.assert_allclose(ev.dY2, pulled[2])


def test_cone_standing_is_supported_and_one_toe_is_not(toy_model, layout):
    t = np.array([0.5])
    Y = standing(layout, 1)
    Z = np.zeros_like(Y)
    term = FrictionCone(toy_model, STANCE, min_radius=0.02, torque_arm=0.3)
    A, e = term.components(t, Y, Z, Z)
    assert A[0] == 1.0
    np.testing.assert_allclose(e, 0.0, atol=1e-9)  # the COM is over the support: nothing outside
    assert cone_metrics(term, t, Y, Z, Z)["cone_peak"] == pytest.approx(0.0, abs=1e-9)
    # on the right toe alone: the weight acts 0.18 m beside it (the COM is at x = y = 0), the support
    # radius is r0 = 0.02 m: e3 = m g (|d| - r0) / l, the rest zero
    toe = FrictionCone(toy_model, [Contact("r_toe", 0.0, 1.0)], min_radius=0.02, torque_arm=0.3)
    m, com = _mass_and_com(toy_model, Y[0])
    g = 9.81
    d = np.hypot(0.15 - com[0], -0.1 - com[1])
    _, e = toe.components(t, Y, Z, Z)
    np.testing.assert_allclose(e[0], [0, 0, m * g * (d - 0.02) / 0.3, 0], rtol=1e-9, atol=1e-9)
    assert term.violation(np.repeat(Y, 5, 0), np.linspace(0.4, 0.6, 5)) == pytest.approx(0.0, abs=1e-7)


def test_cone_sliding_push_and_pull(toy_model, layout):
    t = np.array([0.5])
    Y = standing(layout, 1)
    Z = np.zeros_like(Y)
    m, com = _mass_and_com(toy_model, Y[0])
    g = 9.81
    term = FrictionCone(toy_model, STANCE, mu=0.8, torque_arm=0.3)
    Y2 = np.zeros_like(Y)
    Y2[:, 0] = 1.0 * g  # accelerate along x at 1 g: the feet must push back with m g > 0.8 m g
    _, e = term.components(t, Y, Z, Y2)
    assert e[0, 0] == 0.0
    assert e[0, 1] == pytest.approx(m * g * (1.0 - 0.8), rel=1e-9)
    Y2[:, 0] = 0.0
    Y2[:, 2] = -2.0 * g  # falling faster than gravity: the ground would have to pull with m g
    _, e = term.components(t, Y, Z, Y2)
    assert e[0, 0] == pytest.approx(m * g, rel=1e-9)
    assert e[0, 1] == pytest.approx(0.8 * m * g, rel=1e-9)  # |F_t| - mu f_n with f_n = -m g
    f = term.evaluate(t, Y, Z, Y2).f[0]
    assert f == pytest.approx((e[0] ** 2).sum())
    off = FrictionCone(toy_model, [Contact("r_toe", 2.0, 3.0)])
    assert off.evaluate(t, Y, Z, Y2).f[0] == 0.0
    assert cone_metrics(off, t, Y, Z, Y2) == {"cone_rms": 0.0, "cone_peak": 0.0, "cone_samples": 0}


def test_cone_moment_uses_the_root_torque_in_the_world_frame(toy_model, layout):
    """A static pose with the root turned and tilted and a hip bent, so the COM is not under the root:
    the wrench is the weight through the COM, so on one toe e3 = m g (|com - toe| along the floor - r0) / l."""
    t = np.array([0.5])
    Y = standing(layout, 1, (0.3, -0.2, 1.2))
    Y[0, 3:7] = [np.cos(0.3), 0.1, 0.15, np.sin(0.3)]  # unnormalized on purpose
    hip = layout.quat_slots[1]
    Y[0, hip] = [np.cos(0.4), 0.0, np.sin(0.4), 0.0]
    Z = np.zeros_like(Y)
    m, com = _mass_and_com(toy_model, Y[0])
    d = mujoco.MjData(toy_model)
    d.qpos[:] = Y[0]
    mujoco.mj_kinematics(toy_model, d)
    toe = d.site_xpos[mujoco.mj_name2id(toy_model, mujoco.mjtObj.mjOBJ_SITE, "r_toe")]
    term = FrictionCone(toy_model, [Contact("r_toe", 0.0, 1.0)], min_radius=0.02, torque_arm=0.3)
    _, e = term.components(t, Y, Z, Z)
    lever = np.hypot(*(com - toe)[:2])
    assert lever > 0.1
    np.testing.assert_allclose(e[0], [0, 0, m * 9.81 * (lever - 0.02) / 0.3, 0], rtol=1e-9, atol=1e-9)


def test_objective_gradient_with_a_shared_engine(toy_model, layout):
    """All three terms with the root residual in one Objective: the cone's deferred gradient is summed
    with the root term's (one engine) and its direct root-lever part added; dE/dP against FD."""
    from solver.objective import Objective
    from solver.terms.dynamics import RootResidual, make_engine

    rng = np.random.default_rng(7)
    knots = np.array([0.0, 0.4, 0.7, 1.0])
    P = random_qpos(rng, layout, len(knots), spread=0.3)
    P[:, 2] = [0.97, 1.0, 0.96, 0.99]
    contacts = [Contact("l_heel", 0.0, 0.45), Contact("l_toe", 0.05, 0.5), Contact("r_toe", 0.5, 1.0),
                Contact("l_toe", 0.85, 1.0)]
    engine = make_engine(toy_model)
    terms = [
        FrictionCone(toy_model, contacts, ramp=0.05, engine=engine),
        RootResidual(toy_model, engine=engine, flight="path"),
        Planted(toy_model, contacts),
        Clearance(toy_model, contacts, clearance=2.0),  # every site inside the band in its swing
    ]
    obj = Objective(terms, np.array([1e-4, 1e-4, 10.0, 10.0]), knots[0], knots[-1], rate=30)
    ev = obj.evaluate(knots, P)
    assert all(ev.integrals[n] > 0 for n in ("cone", "planted", "clearance")), ev.integrals
    G = fd_gradient(lambda X: obj.evaluate(knots, X, grad=False).E, P)
    assert np.abs(ev.grad - G).max() < 1e-6 * np.abs(G).max()


def test_planted_conflicts_count_keyframes_at_a_contacts_ends_and_change_nothing(toy_model, layout):
    """A keyframe at a contact's exact start (or end) is in it, as the height window (the closed
    contact) says: 3 cm up there is reported; 10 ms before the start it is not. The check is a query:
    the term keeps its violation until one is built with what it found."""
    term = Planted(toy_model, [Contact("l_toe", 0.2, 0.6)], rest_height=0.002)
    up = standing(layout, 1, (0.0, 0.0, FOOT + 0.032))
    for t, hit in ((0.2, True), (0.6, True), (0.19, False), (0.4, True)):
        got = term.conflicts(np.array([t]), up)
        assert [(k, i, s) for k, i, s, _ in got.found] == ([("planted", 0, "l_toe")] if hit else []), t
        if hit:
            assert got.found[0][3] == pytest.approx(0.03, abs=1e-9) and got.planted == {term.contacts[0]}
    t = np.linspace(0.0, 0.8, 81)
    Y = standing(layout, len(t), (0.0, 0.0, FOOT + 0.032))
    assert term.violation(Y, t) == pytest.approx(0.03, abs=1e-9)
    built = Planted(toy_model, term.contacts, rest_height=0.002, conflicts=term.conflicts(np.array([0.2]), up))
    assert built.violation(Y, t) is None  # the only contact excused


def test_a_boosted_planted_term_keeps_its_excused_contacts_weight(toy_model, layout):
    """`Planted.for_boost(k)`: the integrand of the contacts `violation` measures as it was, the excused
    contacts' divided by k, so that the weight times k leaves their effective weight where it was. The
    reference: single-contact terms built apart."""
    rng = np.random.default_rng(5)
    n = 9
    Y = random_qpos(rng, layout, n)
    Y1, Y2 = rng.normal(size=Y.shape), rng.normal(size=Y.shape)
    t = np.linspace(0, 1, n)
    measured, held = Contact("l_heel", 0.0, 0.8), Contact("r_toe", 0.1, 1.0)
    plain = Planted(toy_model, [measured, held])
    # a keyframe holding r_toe 5 cm up inside its contact: that contact is excused
    conflicts = plain.conflicts(np.array([0.5]), standing(layout, 1, (0.0, 0.0, FOOT + 0.05)))
    conflicts = replace(conflicts, planted=frozenset(c for c in conflicts.planted if c.site == "r_toe"))
    assert len(conflicts.planted) == 1
    term = Planted(toy_model, [measured, held], conflicts=conflicts)
    boosted = term.for_boost(10.0)
    assert boosted is not term and np.all(term.gain == 1.0)  # the term itself is not changed
    f_measured = Planted(toy_model, [measured]).evaluate(t, Y, Y1, Y2, grad=False).f
    f_held = Planted(toy_model, [held]).evaluate(t, Y, Y1, Y2, grad=False).f
    assert np.abs(f_held).max() > 0 and np.abs(f_measured).max() > 0
    np.testing.assert_allclose(boosted.evaluate(t, Y, Y1, Y2, grad=False).f, f_measured + f_held / 10.0, rtol=1e-12)
    np.testing.assert_allclose(boosted.for_boost(10.0).evaluate(t, Y, Y1, Y2, grad=False).f,
                               f_measured + f_held / 100.0, rtol=1e-12)  # boosts compound
    check_gradient(boosted, t, Y, Y1, Y2)
    ctx = PathContext(t, Y, Y1, Y2)  # the residuals agree: f = |r|^2
    r = boosted.residual(ctx).r
    np.testing.assert_allclose((r * r).sum(axis=1), f_measured + f_held / 10.0, rtol=1e-10, atol=1e-15)
    assert Planted(toy_model, [measured, held]).for_boost(10.0).gain.tolist() == [1.0, 1.0]  # nothing excused


def test_a_keyframe_holding_a_site_up_ends_its_contacts_pull_where_the_path_last_rests(toy_model, layout):
    """A toe in contact from 0.2 to 0.8 s whose path rests at the plant height until 0.6 s and then
    rises 3 cm by 0.8 s, where a keyframe holds it (28 mm off, over the 10 mm tolerance): the pull
    ends where the path last rests within 10 mm, 0.6 + 0.2/3 s (to the 1/480 s sampling); the mirror
    case (a keyframe at the start holding it up, the path coming down by 0.4 s) starts it there. A
    keyframe within the tolerance changes nothing, and the term built with what was found has no
    height window after the end it was given."""
    h0 = 0.002
    contact = Contact("l_toe", 0.2, 0.8)
    term = Planted(toy_model, [contact], rest_height=h0)

    def path(rise):
        return lambda t: standing(layout, len(t)) + np.outer(h0 + rise(np.asarray(t)), np.eye(layout.nq)[2])

    up_late = path(lambda t: 0.03 * np.clip((t - 0.6) / 0.2, 0, 1))
    got = term.held(np.array([0.2, 0.8]), up_late(np.array([0.2, 0.8])), up_late)
    lo, hi = got.held[term.contacts[0]]
    assert lo == pytest.approx(0.2) and hi == pytest.approx(0.6 + 0.2 / 3, abs=1 / 480)
    built = Planted(toy_model, [contact], rest_height=h0, conflicts=got)
    t = np.array([0.3, 0.65, 0.7, 0.75])
    np.testing.assert_array_equal(built.height_windows(t)[:, 0], [1, 1, 0, 0])

    down_early = path(lambda t: 0.03 * np.clip((0.4 - t) / 0.2, 0, 1))
    lo, hi = term.held(np.array([0.2, 0.8]), down_early(np.array([0.2, 0.8])), down_early).held[term.contacts[0]]
    assert lo == pytest.approx(0.4 - 0.2 / 3, abs=1 / 480) and hi == pytest.approx(0.8)

    small = path(lambda t: 0.008 * np.clip((t - 0.6) / 0.2, 0, 1))
    assert not term.held(np.array([0.2, 0.8]), small(np.array([0.2, 0.8])), small).held
