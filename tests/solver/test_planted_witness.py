"""A planted foot's limits from a known path through the keyframes (solver.constraint_set). Where a keyframe
holds a foot up inside its contact, the planted limit becomes the mean height over the contact of the
capture the keyframes came from (else the plain spline), less the tolerance: checked against heights from
MuJoCo's forward kinematics of that path and the surface under each contact point. A site's slide
allowance beyond what the keyframes force is 1 cm, or the plain spline's or the capture's own slide
beyond it where that is less: checked on paths gliding at a known speed, whose slide has a closed form."""
from dataclasses import replace

import mujoco
import numpy as np
import pytest

import solver
from solver.constraint_set import TOLERANCES
from solver.contacts import contact_radii
from solver.foot_bounds import FLOAT_LIMIT
from solver.least_change import build_least_change
from solver.spline import interpolate
from solver.spline_basis import SplineBasis
from solver.surfaces import StaticSurfaces

LIFT = 0.03  # [m] how far the keyframe holds the figure up


@pytest.fixture(scope="module")
def lifted():
    """The shipped keyframes with the figure held LIFT up at the keyframe inside the left toe's contact
    (0.58-0.74 s), and a capture through those keyframes that is the plain spline of the originals except
    for a narrow bump (+-80 ms) up to the lifted keyframe: it floats less over the contact than the plain
    spline through the lifted keyframes."""
    model = solver.load_model(solver.shipped("run_and_step.xml"))
    keyframes, info = solver.read_keyframes(solver.shipped("run_and_step.keyframes.json"), model)
    k = int(np.argmin(np.abs(keyframes.times - 0.725)))
    assert keyframes.mask[k].all()  # a full keyframe: it pins the sites
    values = keyframes.values.copy()
    values[k, 2] += LIFT
    lifted = replace(keyframes, values=values)
    plain = build_least_change(model, keyframes).plain  # the originals, the partial one completed
    times = np.arange(keyframes.times[0], keyframes.times[-1] + 1e-9, 1.0 / 120.0)
    qpos = interpolate(plain.times, plain.values, times)
    qpos[:, 2] += LIFT * np.clip(1.0 - np.abs(times - keyframes.times[k]) / 0.08, 0.0, None)
    return model, lifted, info, (times, qpos), k


def _expected_limits(model, planted, path_times, path_qpos, t):
    """Each foot contact's limit from a path: its support sites' heights above the surface under them,
    by MuJoCo's kinematics at the quadrature points t, averaged over the contact, less the tolerance."""
    return np.maximum(FLOAT_LIMIT, _means(model, planted, path_times, path_qpos, t) - TOLERANCES["planted"])


def _means(model, planted, path_times, path_qpos, t):
    """(p,) [m] each planted pair's mean height of a path: its sites' heights above the surface under them, by
    MuJoCo's kinematics at the quadrature points t, averaged over the pair's contact by its weights."""
    Y = interpolate(path_times, path_qpos, t)
    data = mujoco.MjData(model)
    surfaces = StaticSurfaces.from_model(model)
    sites = solver.Figure.from_model(model).contact_sites
    ids = [model.site(s).id for s in sites]
    radii = contact_radii(model, sites)
    h = np.empty(len(planted.points))
    for j, (i, col) in enumerate(zip(planted.points, planted.cols)):
        data.qpos[:] = Y[i]
        mujoco.mj_kinematics(model, data)
        p = data.site_xpos[ids[col]].copy()
        p[2] -= radii[col]
        h[j] = surfaces.height_above(p)
    return np.bincount(planted.pair, planted.w * h) / planted.span


def test_each_site_in_contact_is_held_no_higher_than_the_known_paths_hold_it(lifted):
    """With a capture, each site contact has a planted pair of its own (solver.foot_bounds): its site's mean
    height over the contact at most the higher of the plain spline's and the capture's there (FLOAT_LIMIT where
    lower), each by MuJoCo's kinematics: a foot is not lowered onto its support site by lifting its other.
    Without a capture, nothing witnesses where a site other than the support rests: no such pair."""
    model, keyframes, info, capture, _ = lifted
    feet = list(solver.Figure.from_model(model).feet)
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights, capture=capture)
    planted = next(c for c in lc.al.constraints if c.name == "planted")
    own = ~np.isin(planted.labels, feet)
    assert list(planted.labels[own]) == [c.site for c in info.contacts]
    known = [_means(model, planted, lc.plain.times, lc.plain.values, lc.al.t), _means(model, planted, *capture, lc.al.t)]
    np.testing.assert_allclose(planted.limit[own], np.maximum(FLOAT_LIMIT, np.max(known, axis=0))[own], atol=1e-9)
    assert np.any(planted.limit[own] > FLOAT_LIMIT)  # a site the known paths hold above 2 mm on average
    assert np.any(known[1][own] > known[0][own] + 1e-4) and np.any(known[0][own] > known[1][own] + 1e-4)  # both count
    alone = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights)
    assert set(next(c for c in alone.al.constraints if c.name == "planted").labels) <= set(feet)


@pytest.mark.parametrize("with_capture", [True, False])
def test_a_keyframe_holding_a_foot_up_sets_its_contacts_limit_to_a_witness(lifted, with_capture):
    model, keyframes, info, capture, k = lifted
    lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights,
                            capture=capture if with_capture else None)
    planted = next(c for c in lc.al.constraints if c.name == "planted")
    foot = np.isin(planted.labels, list(solver.Figure.from_model(model).feet))  # the rest: each site's own pairs
    relaxed = foot & (planted.limit > FLOAT_LIMIT)
    assert relaxed.sum() == 1 and planted.labels[relaxed][0] == "left"
    assert any(r.constraint == "planted" and r.keyframe == k for r in lc.relaxations)
    if with_capture:
        witness = capture
    else:
        witness = (lc.plain.times, lc.plain.values)
    expected = _expected_limits(model, planted, *witness, lc.al.t)
    # heights by MuJoCo against the solver's own kinematic tree: the same to round-off
    np.testing.assert_allclose(planted.limit[relaxed], expected[relaxed], atol=1e-9)
    np.testing.assert_array_equal(planted.limit[foot & ~relaxed], FLOAT_LIMIT)


def test_the_capture_floats_less_than_the_plain_spline_so_its_limit_is_tighter(lifted):
    model, keyframes, info, capture, _ = lifted
    limits = []
    for cap in (capture, None):
        lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights, capture=cap)
        planted = next(c for c in lc.al.constraints if c.name == "planted")
        limits.append(planted.limit[np.isin(planted.labels, list(solver.Figure.from_model(model).feet))].max())
    assert FLOAT_LIMIT < limits[0] < limits[1]


def test_a_capture_that_slides_less_than_a_centimetre_tightens_the_slide_limit(lifted):
    # a capture of the figure in one pose gliding at 5 mm/s along x: every site slides at v = 5 mm/s,
    # under the Huber width b (1 cm/s), so its slide over a contact of length T is T v^2 / (2 b)
    from solver.foot_bounds import SLIDE_SHARE, SLIDE_SMOOTHING

    model, keyframes, info, _, _ = lifted
    plain = build_least_change(model, keyframes).plain
    v = 0.005
    times = np.arange(keyframes.times[0] - 0.2, keyframes.times[-1] + 0.2, 1.0 / 120.0)
    qpos = np.tile(plain.values[0], (len(times), 1))
    qpos[:, 0] += v * times
    slides = []
    for cap in (None, (times, qpos)):
        lc = build_least_change(model, keyframes, contacts=info.contacts, flights=info.flights, capture=cap)
        slides.append(next(c for c in lc.al.constraints if c.name == "slide"))
    forced = slides[0].forced
    np.testing.assert_array_equal(slides[1].forced, forced)  # the keyframes force the same either way
    plain_allowance = slides[0].limit - forced  # without a capture: half the plain spline's own excess
    assert (plain_allowance >= 0).all()
    captured = slides[1].span * v * v / (2 * SLIDE_SMOOTHING)
    captured_allowance = SLIDE_SHARE * np.maximum(0.0, captured - forced)  # the path halves the capture's excess
    expected = forced + np.minimum(plain_allowance, captured_allowance)
    np.testing.assert_allclose(slides[1].limit, expected, rtol=1e-9, atol=1e-12)
    tighter = captured_allowance < plain_allowance
    assert tighter.any() and (slides[1].limit[tighter] < slides[0].limit[tighter]).all()


@pytest.mark.parametrize("v", [0.005, 0.05])  # [m/s] under and over the Huber width b (1 cm/s)
def test_the_slide_keyframes_force_is_in_the_slides_own_measure(lifted, v):
    """Keyframes of the figure in one pose gliding at v along x: every site moves v dt between keys dt
    apart. In the slide's measure (the integral of huber_b(speed)) that forces at least dt huber_b(v) per
    key interval (Jensen), which the plain spline, linear in time here, meets with equality over the keyed
    span: huber_b(v) = v^2 / (2 b) under b, v - b/2 over it. Summed distances (v dt each) would overstate
    it 2b/v = 4 times at 5 mm/s."""
    from solver.foot_bounds import SLIDE_SHARE, SLIDE_SMOOTHING

    model, keyframes, info, _, _ = lifted
    pose = build_least_change(model, keyframes).plain.values[0]
    values = np.tile(pose, (len(keyframes.times), 1))
    values[:, 0] += v * keyframes.times
    gliding = replace(keyframes, values=values, mask=np.ones_like(keyframes.mask))
    lc = build_least_change(model, gliding, contacts=info.contacts, flights=info.flights)
    slide = next(c for c in lc.al.constraints if c.name == "slide")
    b = SLIDE_SMOOTHING
    huber_v = v * v / (2 * b) if v <= b else v - b / 2
    expected = []
    for c in info.contacts:
        if not ((lc.al.t >= c.start) & (lc.al.t <= c.end)).any():
            continue  # no quadrature point: no pair
        keyed = keyframes.times[(keyframes.times >= c.start - 1e-6) & (keyframes.times <= c.end + 1e-6)]
        expected.append((keyed[-1] - keyed[0]) * huber_v if len(keyed) > 1 else 0.0)
    np.testing.assert_allclose(slide.forced, expected, rtol=1e-6, atol=1e-12)
    # the plain spline through keys linear in time glides at v throughout: over a contact it slides
    # span huber_b(v), and the allowance beyond what the keys force is half that excess
    excess = slide.span * huber_v - np.array(expected)
    assert (excess > 0).all()  # the contacts reach past their first and last keys
    np.testing.assert_allclose(slide.limit, expected + SLIDE_SHARE * excess, rtol=1e-6, atol=1e-9)
    # a lower bound: the plain spline (a path through the keyframes) slides at least that much
    measured = slide.measure(lc.al.state(SplineBasis(lc.plain.times, lc.al.t), lc.plain.values))
    assert (measured >= np.array(expected) - 1e-9).all()
