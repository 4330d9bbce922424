"""The figure (models/humanoid39.xml) and the scene (models/run_and_step.xml), checked against physical
expectations: a 1.75 m, 70 kg human standing on the floor facing +x, joint conventions by motion."""
from pathlib import Path

import mujoco
import numpy as np
import pytest

MODELS = Path(__file__).resolve().parents[2] / "models"
BODIES = ["pelvis", "torso", "l_thigh", "l_shin", "l_foot", "r_thigh", "r_shin", "r_foot",
          "l_upper_arm", "l_forearm", "r_upper_arm", "r_forearm"]
BALLS = ["torso", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle",
         "l_shoulder", "l_elbow", "r_shoulder", "r_elbow"]
SITES = ["l_heel", "l_toe", "r_heel", "r_toe"]


@pytest.fixture(scope="module")
def figure():
    return mujoco.MjModel.from_xml_path(str(MODELS / "humanoid39.xml"))


@pytest.fixture(scope="module")
def scene():
    return mujoco.MjModel.from_xml_path(str(MODELS / "run_and_step.xml"))


def pose(model, **joints):
    """MjData after kinematics at the identity pose, root at (0, 0, 1.0), with some joint quaternions set."""
    d = mujoco.MjData(model)
    d.qpos[:] = 0
    d.qpos[:7] = [0, 0, 1.0, 1, 0, 0, 0]
    for name, q in joints.items():
        j = model.joint(name)
        d.qpos[j.qposadr[0]: j.qposadr[0] + 4] = q
    for name in BALLS:
        j = model.joint(name)
        if name not in joints:
            d.qpos[j.qposadr[0]: j.qposadr[0] + 4] = [1, 0, 0, 0]
    mujoco.mj_kinematics(model, d)
    return d


def axis_angle(axis, deg):
    a = np.radians(deg) / 2
    return np.r_[np.cos(a), np.sin(a) * np.asarray(axis, float)]


def geom_extent_z(model, d, body_filter):
    """(lowest, highest) z of the geoms of the selected bodies, from each geom's bounding box."""
    lo, hi = np.inf, -np.inf
    for g in range(model.ngeom):
        if not body_filter(model.geom_bodyid[g]):
            continue
        center_local, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
        R = d.geom_xmat[g].reshape(3, 3)
        cz = d.geom_xpos[g, 2] + R[2] @ center_local
        ext = np.abs(R[2]) @ half
        lo, hi = min(lo, cz - ext), max(hi, cz + ext)
    return lo, hi


def test_structure(figure):
    assert figure.nq == 51 and figure.nv == 39
    assert [figure.body(i).name for i in range(1, figure.nbody)] == [
        "pelvis", "l_thigh", "l_shin", "l_foot", "r_thigh", "r_shin", "r_foot",
        "torso", "l_upper_arm", "l_forearm", "r_upper_arm", "r_forearm"]
    assert sorted(figure.body(i).name for i in range(1, figure.nbody)) == sorted(BODIES)
    names = [figure.joint(i).name for i in range(figure.njnt)]
    assert names[0] == "root" and figure.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert sorted(names[1:]) == sorted(BALLS)
    assert all(figure.jnt_type[i] == mujoco.mjtJoint.mjJNT_BALL for i in range(1, figure.njnt))
    for s in SITES + ["head"]:
        assert mujoco.mj_name2id(figure, mujoco.mjtObj.mjOBJ_SITE, s) >= 0, s
    assert figure.vis.global_.offwidth >= 1920 and figure.vis.global_.offheight >= 1080
    assert not figure.geom_contype.any() and not figure.geom_conaffinity.any()


def test_mass_and_height(figure):
    """About 70 kg and 1.75 m: the top of the geoms at the identity pose with the soles on z = 0."""
    assert figure.body_subtreemass[1] == pytest.approx(70.0, abs=3.0)
    d = pose(figure)
    lo, hi = geom_extent_z(figure, d, lambda b: b > 0)
    assert lo == pytest.approx(0.0, abs=0.01)
    assert hi - lo == pytest.approx(1.75, abs=0.03)
    # proportions: legs about half the height, the heaviest segment the trunk
    knee = d.xpos[figure.body("l_shin").id, 2]
    assert 0.45 < knee < 0.55
    assert figure.body_mass[figure.body("torso").id] > figure.body_mass[figure.body("l_thigh").id]


def test_identity_pose_stands_on_floor_facing_x(figure):
    d = pose(figure)
    z = {s: d.site(s).xpos[2] for s in SITES}
    for s in SITES:
        assert z[s] == pytest.approx(0.0, abs=1e-9), s
    for side in "lr":
        heel, toe = d.site(f"{side}_heel").xpos, d.site(f"{side}_toe").xpos
        assert toe[0] > heel[0] + 0.15  # feet point along +x, about a foot long
        assert heel[2] == pytest.approx(toe[2])  # flat
    assert d.site("l_toe").xpos[1] > 0 > d.site("r_toe").xpos[1]  # left is +y
    # arms hang down at the sides
    for side in "lr":
        shoulder = d.xpos[figure.body(f"{side}_upper_arm").id]
        elbow = d.xpos[figure.body(f"{side}_forearm").id]
        assert elbow[2] < shoulder[2] - 0.25 and abs(elbow[0] - shoulder[0]) < 1e-9
    # the head is on top
    assert d.site("head").xpos[2] == pytest.approx(1.75, abs=0.03)


@pytest.mark.parametrize("side", "lr")
def test_knee_flexion_swings_the_foot_back(figure, side):
    """Knee flexion = positive rotation about local +y: the foot goes toward -x (behind)."""
    d0 = pose(figure)
    d1 = pose(figure, **{f"{side}_knee": axis_angle([0, 1, 0], 60)})
    foot = figure.body(f"{side}_foot").id
    shin = figure.body(f"{side}_shin").id
    dx = d1.xpos[foot, 0] - d0.xpos[foot, 0]
    assert dx == pytest.approx(-0.42 * np.sin(np.radians(60)), abs=1e-6)
    assert d1.xpos[shin] == pytest.approx(d0.xpos[shin])


@pytest.mark.parametrize("side", "lr")
def test_elbow_flexion_swings_the_forearm_forward(figure, side):
    """Elbow flexion = positive rotation about local -y: the hanging forearm goes toward +x."""
    d0 = pose(figure)
    d1 = pose(figure, **{f"{side}_elbow": axis_angle([0, -1, 0], 90)})
    g = figure.geom(f"{side}_hand").id
    elbow = d0.xpos[figure.body(f"{side}_forearm").id]
    assert d1.geom_xpos[g, 0] - elbow[0] > 0.25  # hand in front of the elbow
    assert d1.geom_xpos[g, 2] == pytest.approx(elbow[2], abs=1e-6)  # at elbow height
    assert d0.geom_xpos[g, 2] < elbow[2] - 0.25


def test_scene_includes_figure_and_surfaces(scene, figure):
    assert scene.nq == figure.nq and scene.nv == figure.nv
    assert scene.body_subtreemass[scene.body("pelvis").id] == pytest.approx(figure.body_subtreemass[1])
    d = mujoco.MjData(scene)
    mujoco.mj_kinematics(scene, d)
    world = [g for g in range(scene.ngeom) if scene.geom_bodyid[g] == 0]
    kinds = sorted(int(scene.geom_type[g]) for g in world)
    assert kinds == sorted([int(mujoco.mjtGeom.mjGEOM_PLANE), int(mujoco.mjtGeom.mjGEOM_BOX)])
    floor = scene.geom("floor").id
    assert d.geom_xpos[floor, 2] == pytest.approx(0.0)
    box = scene.geom("step").id
    top = d.geom_xpos[box, 2] + scene.geom_size[box, 2]
    bottom = d.geom_xpos[box, 2] - scene.geom_size[box, 2]
    assert top == pytest.approx(0.23, abs=0.02)  # the clip's platform, cmu README: about 4 units
    assert bottom == pytest.approx(0.0, abs=1e-9)
    # the runner crosses x = 0.3 on the box, and lands on the floor at x = -1.0 and x = 1.7 (clip FK)
    lo = d.geom_xpos[box, 0] - scene.geom_size[box, 0]
    hi = d.geom_xpos[box, 0] + scene.geom_size[box, 0]
    assert lo < 0.3 < hi and lo > -0.8 and hi < 1.5
