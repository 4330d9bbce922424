"""Issue 11, the objective side: the contact terms are registered, chosen by name where a contact
schedule is known, refused without one, and share the inverse-dynamics engine (site velocities)."""
import mujoco
import numpy as np
import pytest

from solver.contacts import Contact
from solver.errors import InputError
from solver.inverse_dynamics import InverseDynamics
from solver.layout import CONTACT_SITES, StateLayout
from solver.problem import (
    CONTACT_TERMS_BY_DEFAULT,
    DEFAULT_CONTACT_TERMS,
    DEFAULT_TERMS,
    default_limits,
    figure_objective,
    keyframe_conflicts,
    parse_terms,
    term_names,
)

from conftest import TOY_SCENE, random_qpos

SCHEDULE = (Contact("l_heel", 0.0, 0.4), Contact("l_toe", 0.0, 0.5), Contact("r_toe", 0.6, 1.0))


@pytest.fixture(scope="module")
def toy():
    return mujoco.MjModel.from_xml_string(TOY_SCENE)


def test_contact_terms_are_on_by_default_with_a_schedule_and_can_be_switched_off():
    assert CONTACT_TERMS_BY_DEFAULT
    assert {"planted", "clearance", "cone"} <= set(term_names())
    assert tuple(parse_terms(None)) == DEFAULT_TERMS
    assert tuple(parse_terms(None, contacts=SCHEDULE)) == (*DEFAULT_TERMS, *DEFAULT_CONTACT_TERMS)
    assert DEFAULT_CONTACT_TERMS == ("planted", "clearance", "near_sites")
    assert not {"planted", "clearance", "cone"} & set(parse_terms("all"))
    assert {"planted", "clearance", "cone"} <= set(parse_terms("all", contacts=SCHEDULE))
    assert tuple(parse_terms(",".join(DEFAULT_TERMS), contacts=SCHEDULE)) == DEFAULT_TERMS  # --terms: off
    chosen = parse_terms("penetration,unit,bending,smooth,planted,clearance,cone", contacts=SCHEDULE)
    assert {"planted", "clearance", "cone"} <= set(chosen)
    lim = dict(default_limits(chosen))
    assert lim["planted"] > 0 and lim["clearance"] > 0


@pytest.mark.parametrize("spec, weights", [("planted", None), ("penetration,cone", None), (None, {"clearance": 2})])
def test_a_contact_term_without_a_schedule_is_an_input_error(spec, weights):
    with pytest.raises(InputError, match="contact schedule"):
        parse_terms(spec, weights)


def test_figure_objective_builds_the_contact_terms_on_one_engine(toy):
    w = parse_terms("penetration,torque,root,planted,clearance,cone", contacts=SCHEDULE)  # toy: no elbows
    obj = figure_objective(toy, w, 0.0, 1.0, rate=50, contacts=SCHEDULE)
    engines = {id(t.engine) for t in obj.terms if getattr(t, "engine", None) is not None}
    assert {"planted", "clearance", "cone", "torque", "root", "penetration"} <= set(obj.names)
    assert len(engines) == 1
    geometric = figure_objective(toy, parse_terms("penetration,planted,clearance", contacts=SCHEDULE), 0.0, 1.0,
                                 rate=50, contacts=SCHEDULE)
    kin = {type(t.engine).__name__ for t in geometric.terms if getattr(t, "engine", None) is not None}
    assert kin == {"SiteKinematics"}  # no term reads the forces: the kinematics-only engine, no qacc
    assert all(2 not in t.needs for t in geometric.terms if getattr(t, "engine", None) is not None)
    with pytest.raises(InputError, match="contact schedule"):
        figure_objective(toy, {"planted": 1.0}, 0.0, 1.0)


def test_engine_site_velocities_and_their_gradient(toy):
    layout = StateLayout.from_model(toy)
    rng = np.random.default_rng(3)
    qpos = random_qpos(rng, layout, 3)
    qvel, qacc = rng.normal(size=(3, toy.nv)), rng.normal(size=(3, toy.nv))
    e = InverseDynamics(toy, CONTACT_SITES)
    res = e.forward(qpos, qvel, qacc)
    d, v6 = mujoco.MjData(toy), np.zeros(6)
    for i in range(3):
        d.qpos[:], d.qvel[:] = qpos[i], qvel[i]
        mujoco.mj_forward(toy, d)
        for k, s in enumerate(e.site_ids):
            mujoco.mj_objectVelocity(toy, d, mujoco.mjtObj.mjOBJ_SITE, int(s), v6, 0)
            np.testing.assert_allclose(e.site_velocities(res)[i, k], v6[3:], atol=1e-10)
    g = rng.normal(size=res.sites.shape)
    _, gv, _ = e.vjp(res, np.zeros_like(res.tau), None, g)

    def phi(v):
        e._cache = None
        return float((e.site_velocities(e.forward(qpos, v, qacc)) * g).sum())

    h = 1e-6
    fd = np.array([[(phi(qvel + h * np.eye(toy.nv)[j] * (np.arange(3) == i)[:, None])
                     - phi(qvel - h * np.eye(toy.nv)[j] * (np.arange(3) == i)[:, None])) / (2 * h)
                    for j in range(toy.nv)] for i in range(3)])
    np.testing.assert_allclose(gv, fd, atol=1e-6)


@pytest.mark.parametrize("kind", ["inverse dynamics", "kinematics only"])
def test_planted_and_clearance_with_the_engine_match_the_mujoco_loop(toy, kind):
    from solver.kinematic_tree import SiteKinematics
    from solver.terms.clearance import Clearance
    from solver.terms.contact import Planted
    from solver.terms.dynamics import make_engine

    layout = StateLayout.from_model(toy)
    rng = np.random.default_rng(5)
    t = np.linspace(0, 1, 40)
    Y, Y1, Y2 = random_qpos(rng, layout, 40, spread=0.2, scale=(1, 1)), rng.normal(size=(40, toy.nq)), None
    Y[:, 2] = 0.95
    Y2 = rng.normal(size=(40, toy.nq))
    engine = make_engine(toy) if kind == "inverse dynamics" else SiteKinematics(toy, CONTACT_SITES)
    for cls in (Planted, Clearance):
        a, b = cls(toy, SCHEDULE), cls(toy, SCHEDULE, engine=engine)
        ea, eb = a.evaluate(t, Y, Y1, Y2), b.evaluate(t, Y, Y1, Y2)
        np.testing.assert_allclose(eb.f, ea.f, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(eb.dY, ea.dY, rtol=1e-7, atol=1e-10)
        if ea.dY1 is not None:
            np.testing.assert_allclose(eb.dY1, ea.dY1, rtol=1e-7, atol=1e-10)


def test_keyframes_that_contradict_the_schedule_are_found_and_excused(toy):
    w = parse_terms("penetration,planted,clearance", contacts=SCHEDULE)
    obj = figure_objective(toy, w, 0.0, 1.0, rate=50, contacts=SCHEDULE)
    q = np.tile(toy.qpos0, (3, 1))
    q[:, 2] = 1.0  # sites at 5 cm above the floor: heel planted at t=0.2 is too high, r_toe swinging ok
    got = keyframe_conflicts(obj, np.array([0.0, 0.2, 1.0]), q)
    assert ("planted", 1, "l_heel", pytest.approx(0.05 - 0.002, abs=1e-6)) in got.found
    assert Contact("l_heel", 0.0, 0.4) in got.planted
    planted = obj.terms[obj.names.index("planted")]
    assert not planted.excused  # a query: the objective's terms are not changed
    excused = figure_objective(toy, w, 0.0, 1.0, rate=50, contacts=SCHEDULE, conflicts=got)
    assert 0 in excused.terms[excused.names.index("planted")].excused  # l_heel (0, 0.4): the first contact


def test_keyframes_that_slide_a_planted_site_are_found_and_excused(toy):
    """Two keyframes inside one contact 3 cm apart along the ground: the site must slide (no path can
    hold it still), so that contact leaves `violation`; 5 mm apart is within the 1 cm tolerance."""
    sched = (Contact("l_toe", 0.0, 0.6), Contact("r_toe", 0.0, 0.6))
    w = parse_terms("planted", contacts=sched)
    times = np.array([0.0, 0.1, 0.3, 1.0])  # 0.1 and 0.3 inside both contacts (0 is where they start)
    q = np.tile(toy.qpos0, (4, 1))
    q[:, 2] = 0.952  # sites near the floor (2 mm up: the planted rest height)
    q[2, 0] += 0.03  # the whole figure 3 cm along x at t = 0.3: both toes slide 3 cm
    obj = figure_objective(toy, w, 0.0, 1.0, rate=50, contacts=sched)
    got = keyframe_conflicts(obj, times, q)
    found = [c for c in got.found if c[0] == "sliding"]
    assert sorted(found) == [("sliding", 2, "l_toe", pytest.approx(0.03, abs=1e-9)),
                             ("sliding", 2, "r_toe", pytest.approx(0.03, abs=1e-9))]
    assert got.planted == set(sched)
    assert figure_objective(toy, w, 0.0, 1.0, rate=50, contacts=sched, conflicts=got).terms[0].excused == {0, 1}
    q[2, 0] -= 0.025  # 5 mm
    obj = figure_objective(toy, w, 0.0, 1.0, rate=50, contacts=sched)
    got = keyframe_conflicts(obj, times, q)
    assert not [c for c in got.found if c[0] == "sliding"] and not got.planted


def test_a_swing_the_path_next_to_a_keyframe_keeps_on_the_floor_is_excused(toy):
    """With the plain path given, the clearance term is also checked 5 and 10 ms from each keyframe:
    a keyframe whose neighbourhood holds a swinging site on the floor (more than half the bound inside
    the 2 cm band) is reported, its swing excused; the keyframe alone (site 5 cm up) is not."""
    sched = (Contact("l_toe", 0.0, 0.3), Contact("l_toe", 0.7, 1.0), Contact("r_toe", 0.0, 1.0))  # l_toe swings, no flight
    w = parse_terms("clearance", contacts=sched)
    times = np.array([0.0, 0.5, 1.0])
    q = np.tile(toy.qpos0, (3, 1))
    q[:, 2] = 1.0  # sites 5 cm up at the keyframes

    def path(t):  # the plain spline dips to 2 mm right next to the middle keyframe
        Y = np.tile(toy.qpos0, (len(t), 1))
        Y[:, 2] = np.where(np.abs(np.asarray(t) - 0.5) < 0.011, 0.952, 1.0)
        return Y

    obj = figure_objective(toy, w, 0.0, 1.0, rate=50, contacts=sched)
    assert not keyframe_conflicts(obj, times, q).found
    got = keyframe_conflicts(obj, times, q, path=path)
    assert list(got.found) == [("clearance", 1, "l_toe", pytest.approx(0.02 - 0.002, abs=1e-6))]
    assert ("l_toe", 0.3, 0.7) in got.swings
    built = figure_objective(toy, w, 0.0, 1.0, rate=50, contacts=sched, conflicts=got)
    assert (1, 0.3, 0.7) in built.terms[0].excused  # l_toe is column 1 (l_heel, l_toe, r_heel, r_toe)


@pytest.mark.slow
def test_summary_prints_the_feet_rows_and_the_cone_with_a_schedule():
    from runner.console import summary_table
    from runner.mocap.reference import load_bvh_reference
    from runner.paths import MODELS
    from runner.problem_file import RUN_AND_STEP_KEYFRAMES, load_problem
    from runner.run import contact_summary_rows
    from solver.contacts import reference_contacts
    from solver.frames import FrameSet
    from solver.metrics import path_metrics
    from solver.solve import SolveOptions, solve

    keyframes, _info, model, layout, _ = load_problem(RUN_AND_STEP_KEYFRAMES, None)
    ref = load_bvh_reference(MODELS / "cmu" / "127_33.bvh", model, root_scale=1.0, rest_pose=True)  # as the file's keyframes
    contacts = tuple(reference_contacts(model, ref.qpos, ref.frame_time))
    weights = parse_terms("penetration,unit,bending,smooth,torque,root,cone", contacts=contacts)
    obj = figure_objective(model, weights, keyframes.times[0], keyframes.times[-1], rate=100.0, contacts=contacts)
    sol = solve(obj, FrameSet.from_keyframes(keyframes, layout.quat_slots),
                SolveOptions(subdivision="none", max_evals=3))
    from runner.run import reference_motion_metrics

    motion = reference_motion_metrics(model, sol, ref, contacts)
    rows = contact_summary_rows(motion, obj, sol)
    plain = path_metrics(model, sol.initial.times, sol.initial.values, keyframes, rate=200.0)
    opt = path_metrics(model, sol.frames.times, sol.frames.values, keyframes, rate=200.0)
    text = summary_table(plain, opt, sol, weights, contact_rows=rows)
    import re

    # the capture's figures are printed with the row (their values are the motion metrics' own: not pinned here)
    assert re.search(r"float in contact \[mm\] \(capture \d+\.\d+", text), text
    assert re.search(r"flight time \[s\] \(capture 0\.\d{3}\)", text), text
    for row in ("skate in contact [mm/frame]", "skating ratio (contacts)", "flight phase error vs capture [s]",
                "RMS friction-cone residual [N]", "peak friction-cone residual [N]",
                "float in capture stance [mm]", "flight in capture stance [s] (capture 0.000)"):
        assert row in text
    assert text.index("float in contact") < text.index("max |1 - |q||")


def mujoco_planted(model, term, t, Y, Y1):
    """The reference for `Planted`: f and its gradient from MuJoCo point by point (`SiteMotion`:
    `mj_kinematics` positions, `mj_jacSite` and `mj_jacDot` for velocities and their gradient), with
    the integrand written out contact by contact from the module docstring."""
    from solver.terms.contact_schedule import SiteMotion

    kin = SiteMotion(model, term.kin.names)
    S, W = term.height_windows(t), term.windows(t)
    p, v, J, Jd = kin.motion(Y, Y1)
    f = np.zeros(len(Y))
    g_p, g_v = np.zeros(p.shape), np.zeros(v.shape)
    t2 = term.tau**2
    for c, contact in enumerate(term.contacts):
        k = term.kin.names.index(contact.site)
        on = S[:, c] > 0
        h, nrm = term.support.height(p[on, k], term.support.index(contact.surface))
        h = h - term.rest_height
        vt = v[on, k] - np.einsum("mi,mi->m", v[on, k], nrm)[:, None] * nrm
        f[on] += S[on, c] * h * h + W[on, c] * t2 * (vt * vt).sum(-1)
        g_p[on, k] += (2.0 * S[on, c] * h)[:, None] * nrm
        g_v[on, k] += (2.0 * t2 * W[on, c])[:, None] * vt
    dY, dY1 = kin.pullback(Y, Y1, J, Jd, g_p, g_v)
    return f, dY, dY1


def test_planted_matches_mujoco_point_by_point(toy):
    """`Planted` (its engine's vectorized pass through a `PathContext`, at the pairs of point and
    contact) against MuJoCo point by point (`mujoco_planted`): values to 1e-12 m^2, gradients to 1e-8
    of their largest entry. Contacts of one site that overlap, one on the step, one on whichever
    surface is under the site."""
    from solver.kinematic_tree import SiteKinematics
    from solver.terms.contact import Planted

    layout = StateLayout.from_model(toy)
    rng = np.random.default_rng(11)
    n = 60
    t = np.linspace(0, 1, n)
    Y, Y1 = random_qpos(rng, layout, n, spread=0.2, scale=(1, 1)), rng.normal(size=(n, toy.nq))
    Y[:, 2] = 0.95
    sched = (Contact("l_heel", 0.1, 0.6), Contact("l_heel", 0.5, 0.8), Contact("r_toe", 0.0, 0.4, "step"),
             Contact("l_toe", 0.3, 1.0), Contact("r_heel", 0.7, 0.9, "floor"))
    term = Planted(toy, sched, ramp=0.1, engine=SiteKinematics(toy, CONTACT_SITES))
    ev = term.evaluate(t, Y, Y1, None)
    f, dY, dY1 = mujoco_planted(toy, term, t, Y, Y1)
    assert np.any(f > 0) and np.any(dY1 != 0)
    np.testing.assert_allclose(ev.f, f, rtol=0, atol=1e-12)
    np.testing.assert_allclose(term.evaluate(t, Y, Y1, None, grad=False).f, f, rtol=0, atol=1e-12)
    for got, ref in ((ev.dY, dY), (ev.dY1, dY1)):
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-8 * np.abs(ref).max())


def test_index_run_is_a_slice_only_for_consecutive_indices():
    from solver.layout import index_run

    assert index_run([2, 3, 4]) == slice(2, 5)
    for idx in ([0, 2, 3], [3, 2], []):
        out = index_run(idx)
        assert isinstance(out, np.ndarray) and out.tolist() == idx
    a = np.arange(24.0).reshape(2, 6, 2)
    np.testing.assert_array_equal(a[:, index_run([1, 2, 3])], a[:, [1, 2, 3]])


def test_violations_from_the_vectorized_positions_match_mujocos(toy):
    """The limit checks read site positions from one vectorized pass (`SiteMotion.dense_positions`,
    `Penetration.depths` with an engine); MuJoCo's loop gives the same violations to rounding error."""
    from solver.kinematic_tree import SiteKinematics
    from solver.terms.clearance import Clearance
    from solver.terms.contact import Planted
    from solver.terms.penetration import Penetration

    layout = StateLayout.from_model(toy)
    rng = np.random.default_rng(21)
    Y = random_qpos(rng, layout, 200, spread=0.15, scale=(1, 1))
    Y[:, 2] = 0.97 + 0.02 * np.sin(np.linspace(0, 6, 200))
    t = np.linspace(0.0, 1.0, 200)
    engine = SiteKinematics(toy, CONTACT_SITES)
    sched = (Contact("l_heel", 0.0, 0.3), Contact("l_heel", 0.7, 1.0), Contact("l_toe", 0.0, 0.5),
             Contact("r_toe", 0.2, 1.0))  # l_heel swings from 0.3 to 0.7 s
    terms = [Planted(toy, sched, engine=engine), Clearance(toy, sched, clearance=0.1, engine=engine)]
    dense = [term.violation(Y, t) for term in terms]
    pen = Penetration(toy, margin=0.05, engine=engine)
    dense.append(float(pen.depths(Y, margin=0.05).max()))
    for term in terms:
        term.kin.dense_positions = term.kin.positions  # MuJoCo's loop
    pen._tree = None
    loop = [term.violation(Y, t) for term in terms] + [float(pen.depths(Y, margin=0.05).max())]
    assert all(v > 0 for v in loop), loop
    np.testing.assert_allclose(dense, loop, rtol=1e-12, atol=1e-15)


def test_clearance_matches_mujoco_point_by_point(toy):
    """`Clearance` (its engine's vectorized pass through a `PathContext`) against MuJoCo point by point:
    heights from `mj_kinematics` positions (`SiteMotion.positions`), the gradient through `mj_jacSite`
    (`SiteMotion.jacobians`) and `TangentMap.pullback`; values to 1e-12 m^2, gradients to 1e-9 of their
    largest entry. Swings of two sites and a flight."""
    from solver.terms.clearance import Clearance
    from solver.terms.contact_schedule import SiteMotion

    layout = StateLayout.from_model(toy)
    rng = np.random.default_rng(5)
    n = 50
    t = np.linspace(0, 1, n)
    Y = random_qpos(rng, layout, n, spread=0.2, scale=(1, 1))
    Y[:, 2] = 0.90 + 0.03 * rng.normal(size=n)
    Y[::4, 0] = 1.5  # over the step box
    sched = (Contact("l_heel", 0.0, 0.1), Contact("l_heel", 0.9, 1.0), Contact("r_toe", 0.0, 0.3),
             Contact("r_toe", 0.5, 1.0))
    term = Clearance(toy, sched)
    ev = term.evaluate(t, Y, None, None)
    kin = SiteMotion(toy, term.kin.names)
    p, J = kin.jacobians(Y)
    h, nrm = term.below.height(p)
    Us, Uf, Bf, Bs = term.split_windows(t)
    f, g_p = np.zeros(n), np.zeros(p.shape)
    for U, band in ((Us, Bs), (np.broadcast_to(Uf[:, None], Us.shape), Bf[:, None])):
        depth = np.maximum(0.0, band - h)
        f += (U * depth * depth).sum(1)
        g_p -= (2.0 * U * depth)[..., None] * nrm
    dY = kin.tmap.pullback(Y, np.einsum("nkij,nki->nj", J, g_p))
    assert np.count_nonzero(f) >= 4 and np.any(dY != 0)
    np.testing.assert_allclose(ev.f, f, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ev.dY, dY, rtol=0, atol=1e-9 * np.abs(dY).max())


def test_torque_and_root_terms_match_the_mujoco_backend(toy):
    """The inverse-dynamics terms on their one path, with the vectorized engine and with MuJoCo's
    (`mj_inverse` values, `mjd_inverseFD` gradients: forward differences, ~1e-6 relative): values to
    1e-9 relative, gradients to 1e-4 of their largest entry."""
    from solver.terms.dynamics import JointTorque, RootResidual

    layout = StateLayout.from_model(toy)
    rng = np.random.default_rng(8)
    Y = random_qpos(rng, layout, 5, spread=0.3)
    Y[:, 2] = 0.97
    Y1, Y2 = rng.normal(size=Y.shape), rng.normal(size=Y.shape)
    for cls in (JointTorque, RootResidual):
        a, b = cls(toy).evaluate(None, Y, Y1, Y2), cls(toy, backend="mujoco").evaluate(None, Y, Y1, Y2)
        assert np.any(b.f > 0)
        np.testing.assert_allclose(a.f, b.f, rtol=1e-9, atol=0)
        for x, y in ((a.dY, b.dY), (a.dY1, b.dY1), (a.dY2, b.dY2)):
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-4 * np.abs(y).max())
def _standing_jump_file(tmp_path, shift: float, contact_start: float = 0.0):
    """A hand-written keyframe file of the figure on models/floor.xml: standing at t = 0 (heels 2 mm
    up), the whole figure `shift` m along x at 0.4 s and again at 1.0 s; both feet in contact from
    `contact_start` to 0.6 s (a contact written to start at the first keyframe)."""
    import json

    from runner.paths import MODELS
    from solver.contacts import site_positions

    model = mujoco.MjModel.from_xml_path(str(MODELS / "floor.xml"))
    q = model.qpos0.copy()
    q[2] -= site_positions(model, q)[0, :, 2].min() - 0.002  # the lowest site 2 mm above the floor
    root = [float(v) for v in q[:7]]
    frames = [{"time": t, "joints": {"root": [root[0] + dx, *root[1:]]}} for t, dx in ((0.0, 0.0), (0.4, shift),
                                                                                         (1.0, shift))]
    doc = {"format": "dynsplines.keyframes/1", "scene": str(MODELS / "floor.xml"), "keyframes": frames,
           "contacts": [{"foot": "left", "start": contact_start, "end": 0.6},
                        {"foot": "right", "start": contact_start, "end": 0.6}]}
    p = tmp_path / "jump.keyframes.json"
    p.write_text(json.dumps(doc))
    return model, p


@pytest.mark.parametrize("contact_start", [0.0, 0.1])
def test_a_keyframe_at_a_contacts_start_counts_for_sliding(tmp_path, contact_start):
    """A standing jump written by hand: contacts from 0.0 to 0.6 s, keyframes at 0.0 and 0.4 s holding
    the feet 93.8 mm apart. The keyframe at the contact's exact start is in the contact, so the feet
    must slide 93.8 mm: every site is reported and excused (with the contact starting at 0.1 s, after
    the first keyframe, nothing slides). Before, only keyframes strictly inside the sliding window
    counted, and this case got no warning (then missed the planted bound after thousands of
    evaluations)."""
    from solver.keyframe_file import read_keyframes
    from solver.problem import figure_problem

    model, path = _standing_jump_file(tmp_path, 0.0938, contact_start)
    keyframes, info = read_keyframes(path, model)
    weights = parse_terms(None, contacts=info.contacts)
    objective, _, got = figure_problem(model, weights, keyframes, rate=50.0, contacts=info.contacts)
    sliding = sorted(c for c in got.found if c[0] == "sliding")
    if contact_start > 0:
        assert sliding == [] and not got.planted
        return
    assert sliding == [("sliding", 1, site, pytest.approx(0.0938, abs=1e-6)) for site in sorted(CONTACT_SITES)]
    assert got.planted == set(info.contacts)
    planted = objective.terms[objective.names.index("planted")]
    assert planted.excused == set(range(4))  # the objective is built with what the keyframes excuse


def test_the_shipped_example_contradicts_none_of_its_contacts():
    """`dynsplines run-and-step` opens without a keyframe-conflict warning. The file's contacts are the
    clip's as its recorded command detects them (`reference_contacts`), less the one its hand edit
    removed: a heel that the capture holds 28.8 mm or more above the step all through its "contact"
    (it hovers over the planted toe; the planted term would pull it to 2 mm against keyframe 5, which
    holds it 30 mm up). No keyframe holds a site off the remaining schedule."""
    from runner.problem_file import RUN_AND_STEP_KEYFRAMES, find_reference, load_problem
    from solver.contacts import SITES, reference_contacts, site_heights, site_positions
    from solver.problem import figure_problem

    keyframes, info, model, _, _ = load_problem(RUN_AND_STEP_KEYFRAMES, None)
    assert "--root-scale 1" in info.source["command"] and "l_heel" in info.source["hand_edits"]
    ref = find_reference(info, model, quiet=True)  # the clip as the file was made from it (docs/mocap.md)
    detected = reference_contacts(model, ref.qpos, ref.frame_time)
    kept = [c for c in detected if any(c.site == f.site and abs(c.start - f.start) < 2e-6 for f in info.contacts)]
    assert [(c.site, c.start, c.end) for c in info.contacts] == [
        (c.site, pytest.approx(c.start, abs=2e-6), pytest.approx(c.end, abs=2e-6)) for c in kept]
    (removed,) = [c for c in detected if c not in kept]
    h = site_heights(model, site_positions(model, ref.qpos))[:, SITES.index(removed.site)]
    during = (ref.times >= removed.start - 1e-9) & (ref.times <= removed.end + 1e-9)
    assert removed.site == "l_heel" and h[during].min() > 0.025  # never touched: 28.8 mm at its lowest
    weights = parse_terms(None, contacts=info.contacts)
    assert {"planted", "clearance"} <= set(weights)
    _, _, got = figure_problem(model, weights, keyframes, contacts=info.contacts)
    assert got.found == () and not got.excuses
    _, _, before = figure_problem(model, weights, keyframes, contacts=detected)  # the heel kept: reported
    assert [(k, i, s) for k, i, s, _ in before.found] == [("planted", 5, "l_heel")]
