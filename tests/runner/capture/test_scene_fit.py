"""runner.capture.scene_fit: floor and boxes from where the feet rest; the MJCF loads from where it is saved.

The independent check: 127_33 retargeted onto a FLOOR-ONLY scene (so the hand-made box cannot leak
into the reference through the root-height correction) must give back the step of
models/run_and_step.xml: top within 3 cm; the edges the contacts bound lie between the last box
contact and the first floor contact, where the hand-made edges also lie.
"""
from pathlib import Path

import mujoco
import numpy as np
import pytest
from shipped_sites import FEET, SITES

from runner.capture.scene_fit import LEVEL_TOL, MARGIN, MAX_SLOPE, FittedScene, fit_contacts, fit_scene, scene_mjcf
from solver.contacts import Contact, site_positions
from solver.errors import InputError
from solver.surfaces import StaticSurfaces

ROOT = Path(__file__).resolve().parents[3]
FIGURE = ROOT / "models" / "humanoid39.xml"


def stances(spec, fps=100.0):
    """Hand-built site paths: spec = [(site, t0, t1, x, y, z)], planted sites; others far up."""
    n = int(round(max(s[2] for s in spec) * fps)) + 1
    times = np.arange(n) / fps
    pos = np.zeros((n, 4, 3))
    pos[..., 2] = 1.0
    contacts = []
    for site, t0, t1, x, y, z in spec:
        k = SITES.index(site)
        rows = (times >= t0 - 1e-9) & (times <= t1 + 1e-9)
        pos[rows, k] = (x, y, z)
        contacts.append(Contact(site, t0, t1))
    return times, pos, contacts


def test_floor_and_one_box_with_known_answer():
    times, pos, cs = stances([
        ("l_toe", 0.0, 0.2, 0.0, 0.1, 0.01),
        ("r_toe", 0.3, 0.5, 1.2, -0.1, 0.31),   # on the box
        ("l_toe", 0.6, 0.8, 1.8, 0.1, 0.29),    # on the box, 2 cm lower
        ("r_toe", 0.9, 1.1, 3.0, -0.1, 0.01),
    ])
    f = fit_scene(times, pos, cs, FEET)
    assert f.floor_z == pytest.approx(0.01)
    assert len(f.boxes) == 1
    c, h = f.boxes[0]
    assert f.box_tops()[0] == pytest.approx(0.30)
    assert c[2] - h[2] == pytest.approx(0.01)                     # stands on the floor
    np.testing.assert_allclose(c[:2] - h[:2], [1.2 - MARGIN, -0.1 - MARGIN])
    np.testing.assert_allclose(c[:2] + h[:2], [1.8 + MARGIN, 0.1 + MARGIN])


def test_padding_stops_halfway_to_a_floor_contact():
    times, pos, cs = stances([
        ("l_toe", 0.0, 0.2, 1.0, 0.0, 0.0),
        ("r_toe", 0.3, 0.5, 1.2, 0.0, 0.3),
        ("l_toe", 0.6, 0.8, 1.5, 0.0, 0.3),
    ])
    (c, h), = fit_scene(times, pos, cs, FEET).boxes
    assert c[0] - h[0] == pytest.approx(1.1)   # halfway between the floor toe (1.0) and the box (1.2)
    assert c[0] + h[0] == pytest.approx(1.5 + MARGIN)


def test_a_rest_held_over_a_spot_a_foot_stood_on_is_no_box():
    """A foot held still 10 cm up within a footprint the other foot stood on at floor height: no prop stood
    there, so no box (a box cut back to halfway into its own footprint had a negative size: the scene did not
    load); a raised rest apart from every floor footprint still gets its box."""
    times, pos, cs = stances([
        ("l_toe", 0.0, 0.2, 0.0, 0.0, 0.0),
        ("r_toe", 0.3, 0.5, 0.0, 0.0, 0.10),  # over the floor toe's spot
        ("l_toe", 0.6, 0.8, 1.0, 0.0, 0.0),
        ("r_toe", 0.9, 1.1, 3.0, 0.0, 0.30),  # a step far from both
    ])
    f = fit_scene(times, pos, cs, FEET)
    assert len(f.boxes) == 1 and f.box_tops()[0] == pytest.approx(0.30)
    assert all((h > 0).all() for _, h in f.boxes)


def test_two_heights_and_far_apart_make_separate_boxes():
    times, pos, cs = stances([
        ("l_toe", 0.0, 0.2, 0.0, 0.0, 0.0),
        ("r_toe", 0.3, 0.5, 1.0, 0.0, 0.3),
        ("l_toe", 0.6, 0.8, 1.5, 0.0, 0.6),     # 30 cm higher: another box
        ("r_toe", 0.9, 1.1, 5.0, 0.0, 0.3),     # same height as the first, 3.5 m away
    ])
    f = fit_scene(times, pos, cs, FEET)
    assert [round(t, 3) for t in f.box_tops()] == [0.3, 0.6, 0.3]


def _overlap(a, b):
    """Whether two fitted boxes (center, half) overlap in volume (touching faces do not count)."""
    (ca, ha), (cb, hb) = a, b
    return bool(np.all(np.abs(ca - cb) < ha + hb - 1e-9))


def test_two_steps_onto_a_platform_are_two_boxes_side_by_side():
    """A walk up two 18 cm steps (treads 0.3 m deep) onto a platform: the floor, step 1 and the
    step-2 platform become the floor and two boxes at the rest heights, neither inside the other, and
    every rest lies on the box fitted to it (not on a higher one padded over it)."""
    spec = [("r_toe", 0.0, 0.2, 0.00, -0.1, 0.00), ("r_heel", 0.0, 0.2, -0.20, -0.1, 0.00),  # floor
            ("l_toe", 0.3, 0.5, 0.55, 0.1, 0.18), ("l_heel", 0.3, 0.5, 0.38, 0.1, 0.18),    # step 1
            ("r_toe", 0.6, 0.8, 0.85, -0.1, 0.36), ("r_heel", 0.6, 0.8, 0.68, -0.1, 0.36),  # step 2
            ("l_toe", 0.9, 1.1, 0.87, 0.1, 0.37), ("l_heel", 0.9, 1.1, 0.70, 0.1, 0.37)]
    times, pos, cs = stances(spec)
    f = fit_scene(times, pos, cs, FEET)
    assert f.floor_z == pytest.approx(0.0)
    assert sorted(round(t, 3) for t in f.box_tops()) == [0.18, 0.365]
    assert not _overlap(*f.boxes)
    surfaces = f.surfaces()
    for site, t0, _, x, y, z in spec:   # each rest is on the surface at its own height
        assert abs(surfaces.height_above(np.array([x, y, z]))) <= 0.005 + 1e-9, (site, t0)   # top: the mean rest
    (c1, h1), (c2, h2) = sorted(f.boxes, key=lambda b: b[0][2])
    assert c1[0] + h1[0] == pytest.approx(c2[0] - h2[0])        # the steps meet halfway between the rests
    assert c1[0] + h1[0] == pytest.approx((0.55 + 0.68) / 2)
    assert c1[0] - h1[0] == pytest.approx(0.38 - MARGIN)        # padded where no other rest is near


def test_no_contacts_is_an_error():
    times, pos, _ = stances([("l_toe", 0.0, 0.2, 0, 0, 0)])
    with pytest.raises(InputError, match="no contacts"):
        fit_scene(times, pos, [], FEET)


def test_scene_mjcf_loads_from_where_it_is_saved(tmp_path, monkeypatch):
    fitted = FittedScene(0.0, ((np.array([1.0, 0.0, 0.1]), np.array([0.5, 0.4, 0.1])),))
    (tmp_path / "sub").mkdir()
    for rel in (None, tmp_path / "sub"):
        path = tmp_path / "sub" / "scene.xml"
        path.write_text(scene_mjcf(fitted, FIGURE, relative_to=rel))
        monkeypatch.chdir(tmp_path)  # not the scene's folder, not the repository
        model = mujoco.MjModel.from_xml_path(str(path))
        s = StaticSurfaces.from_model(model)
        assert s.names == ("floor", "box0")
        np.testing.assert_allclose(s.box_half[0], [0.5, 0.4, 0.1])
        assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "l_toe") >= 0
    with pytest.raises(InputError, match="figure_path"):
        scene_mjcf(fitted, tmp_path / "nope.xml")


def load_clip(name, model):
    from runner.capture.reference_motion import load_bvh_reference
    return load_bvh_reference(ROOT / "models" / "cmu" / f"{name}.bvh", model)


def test_127_33_step_from_a_floor_only_retarget():
    floor_only = mujoco.MjModel.from_xml_string(scene_mjcf(FittedScene(0.0), FIGURE))
    ref = load_clip("127_33", floor_only)
    pos = site_positions(floor_only, ref.qpos)
    cs = fit_contacts(ref.times, pos, FEET)
    f = fit_scene(ref.times, pos, cs, FEET)
    hand = StaticSurfaces.from_model(mujoco.MjModel.from_xml_path(str(ROOT / "models" / "run_and_step.xml")))
    hc, hh = hand.box_center[0], hand.box_half[0]
    (c, h), = f.boxes
    lo, hi = c - h, c + h
    print(f"floor {f.floor_z * 100:.1f} cm; fitted box x {lo[0]:.3f}..{hi[0]:.3f} y {lo[1]:.3f}..{hi[1]:.3f} "
          f"top {hi[2]:.3f}; hand-made x {hc[0] - hh[0]:.3f}..{hc[0] + hh[0]:.3f} "
          f"y {hc[1] - hh[1]:.3f}..{hc[1] + hh[1]:.3f} top {hc[2] + hh[2]:.3f}")
    assert abs(f.floor_z) < 0.01
    assert abs(hi[2] - (hc[2] + hh[2])) < 0.03                  # top within 3 cm
    assert abs(lo[0] - (hc[0] - hh[0])) < 0.04                  # near edge (the data bound it) ~3 cm
    # every contact on the box is inside the fitted box, every floor contact outside it
    for contact in cs:
        k = SITES.index(contact.site)
        rows = (ref.times >= contact.start - 1e-9) & (ref.times <= contact.end + 1e-9)
        p = pos[rows, k]
        inside = np.all((p[:, :2] >= lo[:2]) & (p[:, :2] <= hi[:2]), axis=1)
        if np.median(p[:, 2]) > 0.1:
            assert inside.all(), contact
        elif contact.site.endswith("toe"):
            assert not inside.any(), contact
    # the hand-made far edge is not bound by the data: it lies where the fit may put it, between
    # the last contact on the box and the first floor contact after it
    box_x = max(pos[(ref.times >= c_.start) & (ref.times <= c_.end), SITES.index(c_.site), 0].max()
                for c_ in cs if 0.8 < c_.start < 1.4)
    floor_x = min(pos[(ref.times >= c_.start) & (ref.times <= c_.end), SITES.index(c_.site), 0].min()
                  for c_ in cs if c_.start > 1.4)
    assert box_x < hi[0] < floor_x and box_x < hc[0] + hh[0] < floor_x


def test_fit_contacts_ignores_a_heel_hovering_over_a_planted_toe():
    n = 40
    times = np.arange(n) / 100.0
    pos = np.zeros((n, 4, 3))
    pos[:, 1] = (0.2, 0.1, 0.25)       # l_toe still, on a 25 cm box
    pos[:, 0] = (0.0, 0.1, 0.33)       # l_heel still, 8 cm above its toe: not resting
    pos[:, 2] = (0.0, -0.1, 0.30)      # right foot flat and still at 30 cm: both sites rest
    pos[:, 3] = (0.25, -0.1, 0.30)
    cs = fit_contacts(times, pos, FEET)
    assert sorted(c.site for c in cs) == ["l_toe", "r_heel", "r_toe"]
    pos[:, 3, 0] += 2.0 * times        # right toe swinging: fast, not resting
    assert sorted(c.site for c in fit_contacts(times, pos, FEET)) == ["l_toe", "r_heel"]


def test_fit_contacts_drops_the_top_of_a_hop():
    """Both feet flat on the floor, then a hop: the body (and the feet with it) on a parabola with
    gravity's acceleration, 12 cm at the top, the feet still horizontally. The feet are slow near the
    top (their vertical speed passes through 0) but falling: no rest there, and no box in the scene;
    a foot held still at that height (a box) is a rest."""
    g, rate = 9.81, 120.0
    times = np.arange(int(1.2 * rate)) / rate
    up = 2.0 * np.sqrt(2 * 0.12 / g)  # time in the air for a 12 cm hop
    s = times - 0.5
    z = np.where((s > 0) & (s < up), 0.5 * g * s * (up - s), 0.0)
    pos = np.zeros((len(times), 4, 3))
    for k, (x, y) in enumerate(((0.0, 0.1), (0.2, 0.1), (0.0, -0.1), (0.2, -0.1))):
        pos[:, k] = (x, y, 0.0)
        pos[:, k, 2] = z
    assert z.max() == pytest.approx(0.12, abs=1e-3)
    cs = fit_contacts(times, pos, FEET)
    assert cs and all(c.end <= 0.5 + 1e-9 or c.start >= 0.5 + up - 1e-9 for c in cs), cs
    assert fit_scene(times, pos, cs, FEET).boxes == ()
    held = pos.copy()  # the same, but the feet hop 0.6 m forward, stop at the top and stay there (on a box)
    top = s >= up / 2
    held[:, :, 0] += 0.6 * np.clip(s / (up / 2), 0.0, 1.0)[:, None]
    held[top, :, 2] = 0.12
    boxes = fit_scene(times, held, fit_contacts(times, held, FEET), FEET).boxes
    assert len(boxes) == 1 and boxes[0][0][2] + boxes[0][1][2] == pytest.approx(0.12, abs=1e-3)


def test_fit_contacts_drops_a_heel_that_rises_while_its_toe_falls():
    """The hop of the test above, but each heel rises on its own near the top (+14 m/s^2 relative to
    the toe, as in a push-off), so the heel alone does not fall faster than g/2 there while its toe
    does: the foot is in the air, and neither site's slow moment is a rest (a 12 cm hop of the run
    35_17 got a 12 cm box under the heel)."""

    g, rate = 9.81, 120.0
    times = np.arange(int(1.2 * rate)) / rate
    up = 2.0 * np.sqrt(2 * 0.12 / g)
    s = times - 0.5
    air = (s > 0) & (s < up)
    z = np.where(air, 0.5 * g * s * (up - s), 0.0)
    pos = np.zeros((len(times), 4, 3))
    xy = {"l_heel": (0.0, 0.1), "l_toe": (0.2, 0.1), "r_heel": (0.0, -0.1), "r_toe": (0.2, -0.1)}
    for k, site in enumerate(SITES):
        pos[:, k, :2] = xy[site]
        pos[:, k, 2] = z + (np.where(air, 7.0 * (s - up / 2) ** 2, 0.0) if site.endswith("heel") else 0.0)
    heel = [SITES.index("l_heel"), SITES.index("r_heel")]
    top = air & (np.abs(s - up / 2) < 0.04)
    assert np.polyfit(s[top], pos[top, heel[0], 2], 2)[0] * 2 > -0.5 * g  # the heel alone: no fall
    cs = fit_contacts(times, pos, FEET)
    assert all(c.end <= 0.5 + 1e-9 or c.start >= 0.5 + up - 1e-9 for c in cs), cs
    assert fit_scene(times, pos, cs, FEET).boxes == ()


# -- tilted floors ----------------------------------------------------------------------------------


def plane_stances(slope, z0=0.03, box=None, lr=0.0, back=False):
    """Hand-built walk: 8 stances of alternating feet along x (0.6 m apart, feet 0.2 m apart in y),
    the toe resting exactly on the plane z = z0 + slope . (x, y) (left feet `lr` higher), the heel 5 cm
    above it (a hovering heel: the toe is the rest). back: and 8 more walking back at y = 1.5 (the
    stances then spread in y too). box = (x0, x1, height): stances with x0 <= x <= x1 rest that far
    above the plane, along the vertical (the box is tilted with the floor)."""
    spec = []
    for lane, y0 in enumerate((0.0, 1.5) if back else (0.0,)):
        for i in range(8):
            x, y = -2.0 + 0.6 * i, y0 + (0.1 if i % 2 else -0.1)
            site = "l_toe" if i % 2 else "r_toe"
            z = z0 + slope[0] * x + slope[1] * y + (lr if i % 2 else 0.0)
            if box is not None and box[0] <= x <= box[1] and lane == 0:
                z += box[2]
            t = 0.25 * (i + 8 * lane)
            spec.append((site, t, t + 0.2, x, y, z))
    times, pos, cs = stances(spec)
    return times, pos, cs


def test_tilted_floor_and_box_with_known_answer():
    slope = (0.02, -0.01)
    times, pos, cs = plane_stances(slope, box=(-0.5, 0.5, 0.25), back=True)
    f = fit_scene(times, pos, cs, FEET)
    np.testing.assert_allclose(f.floor_slope, slope, atol=1e-6)
    assert f.floor_z == pytest.approx(0.03, abs=1e-6)
    assert f.tilt_deg() == pytest.approx(np.degrees(np.arctan(np.hypot(*slope))), abs=1e-4)
    # the box is square to the floor; its top, 0.25 m above the floor along the vertical, is 0.25 cos(tilt)
    # along the floor's normal
    assert f.box_heights() == pytest.approx([0.25 / np.sqrt(1 + np.dot(slope, slope))], abs=1e-6)
    # every rest point lies on the surface under it in the written scene (MuJoCo's own geom poses)
    model = mujoco.MjModel.from_xml_string(scene_mjcf(f, FIGURE))
    s = StaticSurfaces.from_model(model)
    np.testing.assert_allclose(s.plane_normal[0], [-slope[0], -slope[1], 1] / np.sqrt(1 + np.dot(slope, slope)),
                               atol=1e-9)
    rests = np.array([pos[np.searchsorted(times, c.start), SITES.index(c.site)] for c in cs])
    np.testing.assert_allclose(s.height_above(rests), 0.0, atol=1e-6)


def test_a_straight_walk_gets_no_cross_slope():
    """Stances 0.2 m apart across the walk, the left feet 1 cm higher: no 5 % cross slope; the slope
    along the walk (the stances' principal direction, a little off x as the feet alternate) still found,
    to within what the offset does to it (the left feet stand 0.3 m further along x on average than the
    right ones: a 1 cm offset correlates with x)."""
    times, pos, cs = plane_stances((0.02, 0.0), lr=0.01)
    f = fit_scene(times, pos, cs, FEET)
    assert abs(f.floor_slope[1]) < 1e-3
    assert f.floor_slope[0] == pytest.approx(0.02, abs=2e-3)
    both = fit_scene(times, pos, cs, FEET, min_span=0.1, max_slope=1.0)  # a cross slope fitted anyway
    assert both.floor_slope[1] == pytest.approx(0.05, abs=5e-3)


def test_a_tilt_within_the_rest_scatter_is_written_level():
    """1 mm/m over the 4.2 m of the stances moves the floor 4.2 mm < LEVEL_TOL: level, no quat written."""
    assert LEVEL_TOL > 0.001 * 4.2
    times, pos, cs = plane_stances((0.001, 0.0))
    f = fit_scene(times, pos, cs, FEET)
    assert f.level and f.floor_slope == (0.0, 0.0)
    assert f.floor_z == pytest.approx(0.03, abs=2.2e-3)  # the middle of the ramp's 4.2 mm
    assert "quat" not in scene_mjcf(f, FIGURE)


def test_a_ramp_steeper_than_max_slope_is_not_a_tilt():
    times, pos, cs = plane_stances((2 * MAX_SLOPE, 0.0))
    f = fit_scene(times, pos, cs, FEET)
    assert f.level


def test_surface_below_matches_mujoco_rays_on_a_tilted_scene():
    """surface_below against MuJoCo's own ray casting (mj_ray straight down) on a scene with a floor
    tilted in x and y and a box tilted with it, at points around the box's edges (away from the figure).
    Points within 1 cm of the box's side walls are left out: a tilted box's wall leans out by up to
    its height times the tilt (5 mm here), and a ray there meets the wall, which is no surface to stand on."""
    slope = (0.03, -0.02)
    rot = FittedScene(0.0, (), slope).rotation()
    box = (np.array([2.0, 1.0, 0.0]) + rot @ np.array([0.0, 0.0, 0.15]), np.array([0.5, 0.3, 0.15]))
    f = FittedScene(0.05, ((box[0] + [0, 0, 0.05], box[1]),), slope)
    model = mujoco.MjModel.from_xml_string(scene_mjcf(f, FIGURE))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    s = StaticSurfaces.from_model(model, data)
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(1.3, 2.7, 400), rng.uniform(0.5, 1.5, 400), np.full(400, 1.0)]
    geom = np.zeros(1, np.int32)
    top = s.box_center[0, 2] + s.box_half[0, 2]
    local = np.abs((np.c_[pts[:, :2], np.full(len(pts), top)] - s.box_center[0]) @ s.box_rot[0])
    pts = pts[np.all(np.abs(local[:, :2] - s.box_half[0, :2]) > 0.01, axis=1)]
    assert len(pts) > 300
    for p in pts:
        dist = mujoco.mj_ray(model, data, p, np.array([0.0, 0.0, -1.0]), None, 1, -1, geom)
        assert s.surface_below(p) == pytest.approx(p[2] - dist, abs=1e-9)


def test_a_foot_passing_low_beside_a_box_pulls_its_side_back():
    # a box rested on at x 1.2..1.5, 0.3 m up; a heel swings by at x = 1.0, 0.1 m up, inside the padding and
    # more than RAISED below the top: the side facing it stops halfway (1.1), the far side keeps its margin
    times, pos, cs = stances([
        ("l_toe", 0.0, 0.2, 0.0, 0.0, 0.0),
        ("r_toe", 0.3, 0.5, 1.2, 0.0, 0.3),
        ("l_toe", 0.6, 0.8, 1.5, 0.0, 0.3),
    ])
    pos[(times >= 0.55) & (times <= 0.58), SITES.index("r_heel")] = (1.0, 0.0, 0.1)
    (c, h), = fit_scene(times, pos, cs, FEET).boxes
    assert c[0] - h[0] == pytest.approx(1.1)
    assert c[0] + h[0] == pytest.approx(1.5 + MARGIN)


def test_a_scene_whose_boxes_need_too_much_root_correction_falls_back_to_the_floor(tmp_path, monkeypatch):
    """`clip_scene` "auto": when the fitted boxes need a root correction beyond its bound, they are dropped
    and the clip is retargeted onto the fitted floor alone, with a note that says so; when even the floor
    needs more, the correction is made all the same, with a note (the clip is not refused)."""
    import runner.capture.scene as scene
    from runner.capture.bvh import read_bvh
    from runner.capture.root_height import RootCorrectionRefused
    from runner.capture.subject_figure import write_subject_figure

    clip = ROOT / "models" / "cmu" / "127_33.bvh"  # a run over a step: the fit has one box
    figure = write_subject_figure(read_bvh(clip), tmp_path / "c.figure.xml")
    real = scene.load_bvh_reference

    def refuse_boxes(clip, model, **kw):  # as if the fitted box were where no foot rests
        if kw.get("fitted") and StaticSurfaces.from_model(model).box_center.size:
            raise RootCorrectionRefused("the feet would need the root moved +99 mm")
        return real(clip, model, **kw)

    monkeypatch.setattr(scene, "load_bvh_reference", refuse_boxes)
    cs = scene.clip_scene(clip, "auto", figure, tmp_path / "c.scene.xml")
    assert cs.fitted.boxes == () and StaticSurfaces.from_model(cs.model).box_center.size == 0
    assert len(cs.notes) == 1 and "box(es) dropped" in cs.notes[0] and "+99 mm" in cs.notes[0]

    def refuse_all(clip, model, **kw):
        if kw.get("fitted"):
            raise RootCorrectionRefused("the feet would need the root moved +77 mm")
        return real(clip, model, **kw)

    monkeypatch.setattr(scene, "load_bvh_reference", refuse_all)
    cs = scene.clip_scene(clip, "auto", figure, tmp_path / "d.scene.xml")
    assert cs.fitted.boxes == () and len(cs.notes) == 2 and "+77 mm" in cs.notes[1]
    assert cs.reference.qpos.shape[0] > 0
