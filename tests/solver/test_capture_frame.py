"""solver.capture_frame: the rigid transform that levels a fitted capture floor, and its record in the
scene MJCF. Independent references: points built on a known plane, MuJoCo's forward kinematics and geom
poses, Rodrigues' angle of the plane's normal."""
from pathlib import Path

import mujoco
import numpy as np
import pytest
from shipped_sites import FEET, SITES

from runner.capture.scene_fit import FittedScene, fit_scene, scene_mjcf
from solver.capture_frame import CAPTURE_FRAME, CaptureFrame
from solver.contacts import Contact
from solver.errors import InputError
from solver.surfaces import StaticSurfaces

ROOT = Path(__file__).resolve().parents[2]
FIGURE = ROOT / "models" / "humanoid39.xml"
SLOPE = (0.02, -0.01)


@pytest.mark.parametrize("z0, slope", [(0.03, SLOPE), (-0.05, (0.0, 0.04)), (0.02, (0.0, 0.0))])
def test_levelling_puts_the_plane_at_z0_by_the_shortest_rotation(z0, slope):
    t = CaptureFrame.levelling(z0, slope)
    rng = np.random.default_rng(1)
    xy = rng.uniform(-3, 3, (50, 2))
    on_plane = np.c_[xy, z0 + xy @ np.array(slope)]
    np.testing.assert_allclose(t.points(on_plane)[:, 2], 0.0, atol=1e-12)
    r = t.matrix()
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-12)
    n = np.array([-slope[0], -slope[1], 1.0]) / np.hypot(1.0, np.hypot(*slope))
    np.testing.assert_allclose(r @ n, [0, 0, 1], atol=1e-12)
    # the shortest such rotation: its angle is the angle between n and z, its axis horizontal
    angle = 2 * np.arccos(min(1.0, abs(t.quat[0])))
    assert angle == pytest.approx(np.arctan(np.hypot(*slope)), abs=1e-12)
    assert abs(t.quat[3]) < 1e-15
    # the inverse undoes it
    np.testing.assert_allclose(t.inverse().points(t.points(on_plane)), on_plane, atol=1e-12)


def test_root_moves_the_whole_figure_rigidly():
    """MuJoCo's forward kinematics of T.root(qpos): every body and site at T applied to where it was."""
    model = mujoco.MjModel.from_xml_path(str(FIGURE))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(2)
    t = CaptureFrame.levelling(0.07, SLOPE)
    for _ in range(3):
        q = rng.normal(size=model.nq)
        q[:3] = rng.uniform(-2, 2, 3)
        for a in range(3, model.nq, 4):
            q[a:a + 4] /= np.linalg.norm(q[a:a + 4])
        before = []
        for qpos in (q, t.root(q)):
            data.qpos[:] = qpos
            mujoco.mj_kinematics(model, data)
            before.append((data.xpos[1:].copy(), data.site_xpos.copy(), data.xmat[1:].reshape(-1, 3, 3).copy()))
        (xp, sp, xm), (xp2, sp2, xm2) = before
        np.testing.assert_allclose(xp2, t.points(xp), atol=1e-9)
        np.testing.assert_allclose(sp2, t.points(sp), atol=1e-9)
        np.testing.assert_allclose(xm2, t.matrix() @ xm, atol=1e-9)
        np.testing.assert_allclose(t.inverse().root(t.root(q)), q, atol=1e-12)
    both = np.stack([q, q])
    np.testing.assert_allclose(t.root(both)[1], t.root(q), atol=1e-15)  # (n, nq) rows alike


def tilted_stances():
    """Rests on the floor z = 0.03 + SLOPE . (x, y) along 4.2 m of walk, two lanes; a 0.25 m box (along
    the vertical) under the rests at -0.5 <= x <= 0.5 of the first lane."""
    spec = []
    for lane, y0 in enumerate((0.0, 1.5)):
        for i in range(8):
            x, y = -2.0 + 0.6 * i, y0 + (0.1 if i % 2 else -0.1)
            z = 0.03 + SLOPE[0] * x + SLOPE[1] * y + (0.25 if -0.5 <= x <= 0.5 and lane == 0 else 0.0)
            t = 0.25 * (i + 8 * lane)
            spec.append(("l_toe" if i % 2 else "r_toe", t, t + 0.2, x, y, z))
    times = np.arange(int(round(spec[-1][2] * 100)) + 1) / 100.0
    pos = np.zeros((len(times), 4, 3))
    pos[..., 2] = 1.0
    contacts = []
    for site, t0, t1, x, y, z in spec:
        rows = (times >= t0 - 1e-9) & (times <= t1 + 1e-9)
        pos[rows, SITES.index(site)] = (x, y, z)
        contacts.append(Contact(site, t0, t1))
    rests = np.array([s[3:] for s in spec])
    return times, pos, contacts, rests


def test_the_levelled_scene_is_level_at_z0_with_every_rest_on_its_surface():
    times, pos, contacts, rests = tilted_stances()
    capture = fit_scene(times, pos, contacts, FEET)
    assert not capture.level
    t, level = capture.levelling(), capture.levelled()
    assert level.level and level.floor_z == 0.0
    text = scene_mjcf(level, FIGURE, capture=t)
    assert "quat=" not in text  # floor and box square to the world axes
    model = mujoco.MjModel.from_xml_string(text)
    s = StaticSurfaces.from_model(model)
    np.testing.assert_allclose(s.plane_normal[0], [0, 0, 1], atol=1e-12)
    # every rest, moved by T, on the surface under it: the floor's at z = 0, the box's on its top
    moved = t.points(rests)
    np.testing.assert_allclose(s.height_above(moved), 0.0, atol=1e-6)
    on_box = rests[:, 2] > 0.15
    assert on_box.sum() == 2
    np.testing.assert_allclose(moved[on_box, 2], capture.box_heights()[0], atol=1e-6)
    # the transform read back from the model
    back = CaptureFrame.from_model(model)
    np.testing.assert_allclose(back.quat, t.quat, atol=1e-12)
    np.testing.assert_allclose(back.shift, t.shift, atol=1e-12)


def test_a_scene_without_the_record_is_the_identity_and_a_bad_record_is_one_line():
    model = mujoco.MjModel.from_xml_string(scene_mjcf(FittedScene(0.0), FIGURE))
    t = CaptureFrame.from_model(model)
    assert t.is_identity and not CaptureFrame.levelling(0.01).is_identity
    for data in ("1 0 0 0 0 0", "2 0 0 0 0 0 0"):
        bad = scene_mjcf(FittedScene(0.0), FIGURE).replace(
            "</mujoco>", f'<custom><numeric name="{CAPTURE_FRAME}" data="{data}"/></custom></mujoco>')
        with pytest.raises(InputError) as e:
            CaptureFrame.from_model(mujoco.MjModel.from_xml_string(bad))
        assert "\n" not in str(e.value) and CAPTURE_FRAME in str(e.value) and "w x y z tx ty tz" in str(e.value)
