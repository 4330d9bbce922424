"""The footplant clean-up (runner.capture.foot_plant) and the leg inverse kinematics under it (runner.capture.leg_ik),
on the shipped figure on its floor scene, checked with MuJoCo's own forward kinematics:

* `knee_angle` solves its distance equation (against rotating the shin by the returned angle) and picks the
  root nearest 0 (against a fine scan of the angle);
* `move_foot` moves a foot exactly by dz along the vertical, keeps its orientation, its place along the floor,
  the pelvis, and the knee's rotation off its hinge; a straight knee cannot extend: the foot stays and the
  returned dz says 0; a straight knee lifts its foot by flexing, whichever side of straight round-off leaves it;
* `plant_feet` on a standing figure whose right foot the capture holds up: with a bent right knee the leg
  puts it down alone; with both knees straight (the pelvis tilted) the root goes down and the left knee
  bends to keep the left foot on the floor. Every resting foot ends `CONTACT_CLEARANCE` above the floor,
  nothing below it, the feet where they were along the floor; a frame's report names the foot and the root
  lowered there. A foot coming down or lifting off slowly
  (resting by the thresholds) keeps its shape near its touchdown and still lands or lifts; one that drifts
  while it rests (an inertial capture's) goes down onto the floor.
"""
import mujoco
import numpy as np
import pytest

import solver
from runner.capture.clearance import CONTACT_CLEARANCE, SMOOTH_S, ContactClearance
from runner.capture.foot_plant import LANDING_S, plant_feet
from runner.capture.leg_ik import knee_angle, leg_chain, move_foot
from solver.figure import FIGURE_FILE
from solver.quaternion import mul, swing_angle, twist_angle

FPS = 120.0


@pytest.fixture(scope="module")
def scene():
    model = solver.load_model(solver.shipped("floor.xml"))
    return model, solver.Figure.from_model(model)


def _about(axis, deg):
    h = np.radians(deg) / 2
    return np.r_[np.cos(h), np.sin(h) * np.asarray(axis, float)]


def _bodies(model, qpos, names):
    """World positions (n, b, 3) and orientations (n, b, 4) of the named bodies, by mj_kinematics."""
    data = mujoco.MjData(model)
    ids = [model.body(n).id for n in names]
    pos, quat = np.empty((len(qpos), len(ids), 3)), np.empty((len(qpos), len(ids), 4))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        pos[i], quat[i] = data.xpos[ids], data.xquat[ids]
    return pos, quat


def _standing(model, figure, right_knee_deg=0.0, roll_deg=0.0):
    """A still pose: upright (qpos0), the right knee flexed, the pelvis rolled about the forward axis, and the
    root height that puts the lowest contact point CONTACT_CLEARANCE above the floor."""
    q = model.qpos0.copy()
    knee = figure.joint("r_knee").qpos_slice
    q[knee] = _about(figure.flexion_axes["r_knee"], right_knee_deg)
    q[3:7] = _about([1.0, 0.0, 0.0], roll_deg)
    kin = ContactClearance(model)
    q[2] += CONTACT_CLEARANCE - kin.clearance(kin.positions(q[None]))[0].min()
    return q


def test_knee_angle_solves_its_equation_and_takes_the_root_nearest_zero():
    rng = np.random.default_rng(3)
    n = 40
    hip = rng.normal(size=(n, 3))
    knee = hip + rng.normal(size=(n, 3)) * 0.4
    ankle = knee + rng.normal(size=(n, 3)) * 0.4
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    grid = np.linspace(-np.pi, np.pi, 20001)

    def dist(i, th):
        v, a = ankle[i] - knee[i], axis[i]
        rv = v * np.cos(th)[:, None] + np.cross(a, v) * np.sin(th)[:, None] + np.outer(1 - np.cos(th), a) * (a @ v)
        return np.linalg.norm(knee[i] + rv - hip[i], axis=1)

    lo = np.array([dist(i, grid).min() for i in range(n)])
    hi = np.array([dist(i, grid).max() for i in range(n)])
    target = lo + rng.uniform(0.05, 0.95, n) * (hi - lo)  # reachable distances
    theta = knee_angle(hip, knee, ankle, axis, target)
    for i in range(n):
        assert dist(i, np.array([theta[i]]))[0] == pytest.approx(target[i], abs=1e-9)
        roots = grid[np.flatnonzero(np.diff(np.sign(dist(i, grid) - target[i])))]
        assert abs(theta[i]) <= np.abs(roots).min() + 1e-3  # the nearest root to 0 (grid step 3e-4 rad)


@pytest.mark.parametrize("dz", [-0.012, 0.02])
def test_move_foot_moves_it_exactly_vertically_and_keeps_the_knee_on_its_hinge(scene, dz):
    model, figure = scene
    q = _standing(model, figure, right_knee_deg=35.0)[None]
    leg = leg_chain(model, figure, "right")
    moved, reached = move_foot(model, leg, q, np.array([dz]))
    assert reached[0] == pytest.approx(dz, abs=1e-12)
    names = ["pelvis", "r_foot", "l_foot"]
    (p0, q0), (p1, q1) = _bodies(model, q, names), _bodies(model, moved, names)
    assert p1[0, 1] - p0[0, 1] == pytest.approx([0.0, 0.0, dz], abs=1e-9)  # the foot: straight down or up
    assert abs(abs(q1[0, 1] @ q0[0, 1]) - 1.0) < 1e-12  # ... not turned
    assert np.allclose(p1[0, [0, 2]], p0[0, [0, 2]], atol=1e-12) and np.allclose(q1[0, [0, 2]], q0[0, [0, 2]], atol=1e-12)
    knee, axis = figure.joint("r_knee").qpos_slice, figure.flexion_axes["r_knee"]
    assert swing_angle(moved[:, knee], axis)[0] == pytest.approx(swing_angle(q[:, knee], axis)[0], abs=1e-9)
    bent = np.degrees(twist_angle(moved[:, knee], axis)[0])
    assert (bent < 35.0) == (dz < 0)  # down: the knee extends; up: it flexes


def test_a_straight_knee_cannot_lower_its_foot(scene):
    model, figure = scene
    q = _standing(model, figure)[None]
    leg = leg_chain(model, figure, "right")
    moved, reached = move_foot(model, leg, q, np.array([-0.01]))
    assert reached[0] == pytest.approx(0.0, abs=1e-6)
    assert np.allclose(_bodies(model, moved, ["r_foot"])[0], _bodies(model, q, ["r_foot"])[0], atol=1e-6)
    assert twist_angle(moved[:, figure.joint("r_knee").qpos_slice], figure.flexion_axes["r_knee"])[0] >= -1e-9


@pytest.mark.parametrize("knee_rad", [0.0, 1e-4, -1e-4])
def test_a_straight_knee_lifts_its_foot_by_flexing(scene, knee_rad):
    # a straight knee shortens its leg by the same |theta| flexing or hyperextending, so which root is nearer 0
    # is round-off; the hyperextending one would be stopped at straight and the foot left where it was
    model, figure = scene
    knee, axis = figure.joint("r_knee").qpos_slice, figure.flexion_axes["r_knee"]
    q = _standing(model, figure)
    q[knee] = _about(axis, np.degrees(knee_rad))
    leg = leg_chain(model, figure, "right")
    moved, reached = move_foot(model, leg, q[None], np.array([0.011]))
    assert reached[0] == pytest.approx(0.011, abs=1e-9)
    assert _bodies(model, moved, ["r_foot"])[0][0, 0, 2] - _bodies(model, q[None], ["r_foot"])[0][0, 0, 2] == \
        pytest.approx(0.011, abs=1e-9)
    assert np.degrees(twist_angle(moved[:, knee], axis)[0]) > 10.0  # flexed (about 18.6 deg for 11 mm)


def _raised_right_foot(model, figure, pose, lift):
    """A still motion of 40 frames: `pose` with the right foot lifted by `lift` [m] by its leg."""
    leg = leg_chain(model, figure, "right")
    q, reached = move_foot(model, leg, pose[None], np.array([lift]))
    assert reached[0] == pytest.approx(lift, abs=1e-9)
    return np.repeat(q, 40, axis=0)


def _feet_lowest(model, qpos):
    kin = ContactClearance(model)
    clear = kin.clearance(kin.positions(qpos))
    return clear[:, :2].min(axis=1), clear[:, 2:].min(axis=1), kin.positions(qpos)


@pytest.mark.parametrize("case", ["bent knee", "straight knees"])
def test_plant_feet_puts_a_raised_resting_foot_on_the_floor(scene, case):
    model, figure = scene
    if case == "bent knee":  # the right foot lifted flat 15 mm by bending its knee: its leg can reach down
        qpos = _raised_right_foot(model, figure, _standing(model, figure), 0.015)
    else:  # both knees straight, the pelvis rolled: the right foot 15-20 mm up, its leg cannot reach
        qpos = np.repeat(_standing(model, figure, roll_deg=-5.0)[None], 40, axis=0)
    left0, right0, pos0 = _feet_lowest(model, qpos)
    assert right0.min() > CONTACT_CLEARANCE + 0.01 and left0.max() == pytest.approx(CONTACT_CLEARANCE, abs=1e-9)
    plant = plant_feet(qpos, model, 1.0 / FPS)
    left, right, pos = _feet_lowest(model, plant.qpos)
    assert np.allclose(left, CONTACT_CLEARANCE, atol=1e-6) and np.allclose(right, CONTACT_CLEARANCE, atol=1e-6)
    assert np.allclose(pos[..., :2], pos0[..., :2], atol=1e-9)  # the feet where they were along the floor
    assert plant.foot_dz[:, 1] == pytest.approx(CONTACT_CLEARANCE - right0, abs=1e-6)
    if case == "bent knee":
        assert np.all(plant.root_dz == 0.0) and np.all(plant.foot_dz[:, 0] == 0.0)
    else:  # the root went down by what the straight right leg could not reach; the left knee bent for it
        assert plant.root_dz == pytest.approx(CONTACT_CLEARANCE - right0, abs=1e-6)
        knee = figure.joint("l_knee").qpos_slice
        assert np.all(twist_angle(plant.qpos[:, knee], figure.flexion_axes["l_knee"]) > np.radians(1.0))
    assert plant.largest_mm()["right"] == pytest.approx(1000 * (right0.max() - CONTACT_CLEARANCE), abs=0.1)
    # what a key's report names there: the right foot lowered and, with straight knees, the root (the left
    # foot, lowered by the root and lifted back by its leg, did not move)
    drop = 1000 * (right0[0] - CONTACT_CLEARANCE)
    assert plant.moved_at(0) == pytest.approx({"right": drop} | ({"root": drop} if case == "straight knees" else {}), abs=0.06)


def _right_lowest(model, qpos):
    return _feet_lowest(model, qpos)[1] - CONTACT_CLEARANCE


@pytest.mark.parametrize("way", ["lifts off", "lands"])
def test_a_slow_lift_off_or_landing_is_kept_near_its_touchdown_and_not_pulled_down(scene, way):
    """The right foot rests on the floor, then rises 24 mm at 0.1 m/s (still 'resting' by the stance's 3 cm
    and 0.5 m/s, slower than a step through them); or the same played backward, a landing. Within
    LANDING_S of the touchdown the capture's heights are kept; further away the foot is held v LANDING_S
    (6 mm) over the floor, never lower, never above the capture's, rising (falling) all the way."""
    model, figure = scene
    qpos = np.repeat(_standing(model, figure)[None], 60, axis=0)
    leg = leg_chain(model, figure, "right")
    v = 0.1  # [m/s]
    rise = np.clip((np.arange(60) - 30) / FPS * v, 0.0, None)
    qpos, _ = move_foot(model, leg, qpos, rise if way == "lifts off" else rise[::-1])
    h0 = _right_lowest(model, qpos)
    h = _right_lowest(model, plant_feet(qpos, model, 1.0 / FPS).qpos)
    order = slice(None) if way == "lifts off" else slice(None, None, -1)  # as a lift-off, from the touchdown on
    h0, h = h0[order], h[order]
    near = int(LANDING_S * FPS) - int(SMOOTH_S * FPS) // 2  # frames after the touchdown no smoothing reaches
    assert np.allclose(h[: 30 + near], h0[: 30 + near], atol=1e-9)
    assert np.all(h >= -1e-9) and np.all(h <= h0 + 1e-9) and np.all(np.diff(h[30:]) >= -1e-9)
    held = v * (LANDING_S - 0.5 / FPS)  # the window is LANDING_S to the nearest frame
    assert np.all(h[30 + int((LANDING_S + SMOOTH_S) * FPS):] >= held - 1e-6)  # not pulled down onto the floor


def test_a_foot_drifting_while_it_rests_goes_down_onto_the_floor(scene):
    """An inertial capture's resting foot drifts: the right foot rests on the floor, rises 20 mm at 2 cm/s
    and stays there, still (all of it 'resting'). It is planted: on the floor where it stays, and during
    the drift within v LANDING_S (1.2 mm) of it; the capture's foot floats up to 20 mm."""
    model, figure = scene
    n, v = 240, 0.02  # frames, [m/s]
    qpos = np.repeat(_standing(model, figure)[None], n, axis=0)
    leg = leg_chain(model, figure, "right")
    drift = np.clip((np.arange(n) - 30) / FPS * v, 0.0, 0.02)
    qpos, _ = move_foot(model, leg, qpos, drift)
    assert _right_lowest(model, qpos).max() == pytest.approx(0.02, abs=1e-6)
    h = _right_lowest(model, plant_feet(qpos, model, 1.0 / FPS).qpos)
    assert np.all(h <= v * LANDING_S + 1e-6) and np.all(h >= -1e-6)
    settled = np.flatnonzero(drift >= 0.02)[0] + int(LANDING_S * FPS) + int(SMOOTH_S * FPS)
    assert np.allclose(h[settled:], 0.0, atol=1e-6)


def test_plant_feet_without_a_surface_changes_nothing():
    model = solver.load_model(FIGURE_FILE)  # the figure alone: no floor
    qpos = np.repeat(model.qpos0[None], 5, axis=0)
    plant = plant_feet(qpos, model, 1.0 / FPS)
    assert plant.qpos is qpos and not plant.root_dz.any()


def test_the_footplant_keeps_the_figure_pose_between_two_quaternion_conventions(scene):
    """The hip, knee and ankle quaternions it writes give back the world orientations it solved for: the
    thigh, shin and foot composed through their parents (body_quat included) by MuJoCo."""
    model, figure = scene
    q = _standing(model, figure, right_knee_deg=40.0)
    q[figure.joint("r_hip").qpos_slice] = mul(_about([0, 1, 0], -20.0), _about([1, 0, 0], 5.0))
    leg = leg_chain(model, figure, "right")
    moved, reached = move_foot(model, leg, q[None], np.array([-0.02]))
    (p0, q0), (p1, q1) = _bodies(model, q[None], ["r_foot"]), _bodies(model, moved, ["r_foot"])
    assert reached[0] == pytest.approx(-0.02, abs=1e-12)
    assert p1[0, 0] - p0[0, 0] == pytest.approx([0.0, 0.0, -0.02], abs=1e-9)
    assert abs(abs(q1[0, 0] @ q0[0, 0]) - 1.0) < 1e-12
