"""The anatomical limits' geometry (what the hinge, hyperextension and rom constraints read): the
swing-twist helpers against scipy's rotations and central differences, the range-of-motion table's signs
against MuJoCo's forward kinematics of the shipped figure, and the anatomy figures of a hand-built motion."""
import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solver.figure import FIGURE_FILE, Figure
from solver.layout import StateLayout
from solver.path_context import PathContext
from solver.quaternion import (
    mul,
    swing_about,
    swing_about_grad,
    swing_angle,
    swing_angle_grad,
    swing_twist,
    twist_angle,
)
from solver.terms.anatomy_table import motion_angles, range_of_motion

from conftest import fd_gradient

X, Y_, Z = np.eye(3)


def quat(axis, deg):
    """Unit quaternion (w, x, y, z) of a rotation by `deg` about `axis`, from scipy."""
    x, y, z, w = Rotation.from_rotvec(np.radians(deg) * np.asarray(axis, float)).as_quat()
    return np.array([w, x, y, z])


@pytest.fixture(scope="module")
def figure_model():
    return mujoco.MjModel.from_xml_path(str(FIGURE_FILE))


@pytest.fixture(scope="module")
def figure(figure_model):
    return Figure.from_model(figure_model)


@pytest.fixture(scope="module")
def layout(figure_model):
    return StateLayout.from_model(figure_model)


def identity(layout, n=1):
    Y = np.zeros((n, layout.nq))
    Y[:, 2] = 1.0
    Y[:, layout.quat_slots[:, 0]] = 1.0
    return Y


# ------------------------------------------------------------------------------- quaternion helpers
def test_swing_twist_recomposes_and_splits_a_scipy_rotation():
    """q = Rz-swing(alpha) about x times a twist(beta) about y: the split gives back both angles (scipy
    builds q), q = s t exactly, t is about the axis and s about a normal to it."""
    q = mul(quat(X, 17.0), quat(Y_, 40.0))
    s, t = swing_twist(q, Y_)
    np.testing.assert_allclose(mul(s, t), q, atol=1e-15)
    np.testing.assert_allclose(t, quat(Y_, 40.0), atol=1e-15)
    np.testing.assert_allclose(s, quat(X, 17.0), atol=1e-15)
    assert np.degrees(swing_angle(q, Y_)) == pytest.approx(17.0, abs=1e-12)
    assert np.degrees(twist_angle(q, Y_)) == pytest.approx(40.0, abs=1e-12)
    assert np.degrees(swing_about(q, Y_, X)) == pytest.approx(17.0, abs=1e-12)
    assert np.degrees(swing_about(q, Y_, Z)) == pytest.approx(0.0, abs=1e-12)
    # a swing about a direction u between x and z: its angle is the geodesic one, its components the
    # goniometer's angles in the planes normal to x and z (exact along an axis, about phi cos for small phi)
    u = np.array([np.cos(0.3), 0.0, np.sin(0.3)])
    q = mul(quat(u, 5.0), quat(Y_, -30.0))
    assert np.degrees(swing_angle(3.0 * q, Y_)) == pytest.approx(5.0, abs=1e-12)  # scale-invariant
    assert np.degrees(swing_about(-q, Y_, X)) == pytest.approx(5.0 * np.cos(0.3), rel=1e-3)
    assert np.degrees(swing_about(q, Y_, Z)) == pytest.approx(5.0 * np.sin(0.3), rel=1e-3)


def test_swing_gradients_match_central_differences():
    """swing_angle_grad and swing_about_grad against central differences (step 1e-6, to 1e-7) on
    non-unit quaternions, with one axis and with an axis per quaternion (broadcast)."""
    rng = np.random.default_rng(1)
    q = rng.normal(size=(20, 4))
    axes = rng.normal(size=(20, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    es = np.cross(axes, rng.normal(size=(20, 3)))
    es /= np.linalg.norm(es, axis=1, keepdims=True)
    for f, g in ((lambda x: swing_angle(x, axes), swing_angle_grad(q, axes)),
                 (lambda x: swing_about(x, axes, es), swing_about_grad(q, axes, es)),
                 (lambda x: swing_about(x, Y_, X), swing_about_grad(q, Y_, X))):
        fd = np.stack([(f(q + 1e-6 * d) - f(q - 1e-6 * d)) / 2e-6 for d in np.eye(4)], axis=-1)
        assert np.abs(g).max() > 0.1
        np.testing.assert_allclose(g, fd, atol=1e-7)


# ------------------------------------------------------------------ the table's signs, by kinematics
def _pose(model, layout, joints: dict) -> mujoco.MjData:
    data = mujoco.MjData(model)
    data.qpos[:] = identity(layout)[0]
    for name, q in joints.items():
        data.qpos[layout.joint(name).quat_index] = q
    mujoco.mj_kinematics(model, data)
    return data


def _motion(motions, joint, motion):
    return next(m for m in motions if m.joint == joint and m.motion == motion)


# (joint, motion, what moves, world direction it moves in for a positive angle; a pose first, if any)
SIGNS = [
    ("l_hip", "flexion / extension", ("body", "l_shin"), -X, {}),
    ("l_hip", "adduction / abduction", ("body", "l_shin"), Y_, {}),
    ("r_hip", "adduction / abduction", ("body", "r_shin"), -Y_, {}),
    ("l_hip", "internal rotation / external rotation", ("site", "l_toe"), Y_, {}),
    ("r_hip", "internal rotation / external rotation", ("site", "r_toe"), -Y_, {}),
    ("l_knee", "hyperextension / flexion", ("site", "l_heel"), -X, {}),
    ("l_ankle", "dorsiflexion / plantarflexion", ("site", "l_toe"), -Z, {}),
    ("l_ankle", "adduction / abduction", ("site", "l_toe"), Y_, {}),
    ("r_ankle", "adduction / abduction", ("site", "r_toe"), -Y_, {}),
    ("l_ankle", "inversion / eversion", ("site", "l_toe"), Y_, {}),  # the sole swings out: faces laterally
    ("r_ankle", "inversion / eversion", ("site", "r_toe"), -Y_, {}),
    ("torso", "extension / flexion", ("site", "head"), X, {}),
    ("torso", "left lateral flexion / right lateral flexion", ("site", "head"), -Y_, {}),
    ("l_shoulder", "flexion / extension", ("site", "l_wrist"), -X, {}),
    ("l_shoulder", "adduction / abduction", ("site", "l_wrist"), Y_, {}),
    ("r_shoulder", "adduction / abduction", ("site", "r_wrist"), -Y_, {}),
    ("l_shoulder", "internal rotation / external rotation", ("site", "l_wrist"), Y_, {"l_elbow": (-Y_, 90.0)}),
    ("r_shoulder", "internal rotation / external rotation", ("site", "r_wrist"), -Y_, {"r_elbow": (-Y_, 90.0)}),
    ("l_elbow", "hyperextension / flexion", ("site", "l_wrist"), X, {}),
]


@pytest.mark.parametrize("joint,motion,thing,direction,before", SIGNS, ids=[f"{s[0]}:{s[1]}" for s in SIGNS])
def test_a_positive_angle_is_the_named_motion_in_mujocos_kinematics(figure_model, figure, layout, joint, motion,
                                                                      thing, direction, before):
    """A 20 degree rotation about the motion's own axis (its swing direction, or its twist axis) reads
    +20 degrees of that motion and 0 of the joint's others, and moves the body or site the way the
    motion's positive name says (MuJoCo's forward kinematics of the shipped figure): e.g. left hip
    abduction moves the left knee to the figure's left (+y), ankle plantarflexion the toe down."""
    motions = range_of_motion(figure)
    m = _motion(motions, joint, motion)
    q = quat(m.e if m.kind == "swing" else m.axis, 20.0)
    own = [k for k in motions if k.joint == joint]
    idx = np.array([layout.joint(joint).quat_index] * len(own))
    Y = identity(layout)
    Y[0, layout.joint(joint).quat_index] = q
    angles = np.degrees(motion_angles(Y, idx, own))[0]
    np.testing.assert_allclose(angles, [20.0 if k is m else 0.0 for k in own], atol=1e-9)
    pre = {name: quat(ax, deg) for name, (ax, deg) in before.items()}
    kind, name = thing

    def where(data):
        return (data.xpos[figure_model.body(name).id] if kind == "body" else data.site_xpos[figure_model.site(name).id]).copy()

    moved = where(_pose(figure_model, layout, {**pre, joint: q})) - where(_pose(figure_model, layout, pre))
    assert moved @ direction > 0.5 * np.linalg.norm(moved) > 0.005


def test_the_table_bounds_every_ball_joint_of_the_shipped_figure(figure, layout):
    """Every ball joint has a bounded motion; hips, ankles, trunk and shoulders three each (AAOS), the
    knees and elbows their flexion only (their off-hinge rotation is the hinge term's)."""
    motions = range_of_motion(figure)
    count = {j.name: sum(m.joint == j.name for m in motions) for j in layout.joints if j.kind == "ball"}
    assert count == {"l_hip": 3, "l_knee": 1, "l_ankle": 3, "r_hip": 3, "r_knee": 1, "r_ankle": 3, "torso": 3,
                     "l_shoulder": 3, "l_elbow": 1, "r_shoulder": 3, "r_elbow": 1}
    hip = _motion(motions, "l_hip", "flexion / extension")
    assert (np.degrees(hip.lo), np.degrees(hip.hi)) == pytest.approx((-120.0, 30.0))
    knee = _motion(motions, "r_knee", "hyperextension / flexion")
    assert knee.lo == -np.inf and np.degrees(knee.hi) == pytest.approx(135.0)


# ------------------------------------------------------------------------------------------ hinge
def _check_gradient_and_residual(term, layout, Y):
    """dY against central differences of sum f (to 1e-6 relative), f = |r|^2, and the residual blocks
    against central differences of r along a random direction."""
    t = np.zeros(len(Y))
    ev = term.evaluate(t, Y, None, None)
    assert ev.f.sum() > 0, "the term is zero on the test path: the check checks nothing"
    fd = fd_gradient(lambda Z_: term.evaluate(t, Z_, None, None, grad=False).f.sum(), Y)
    np.testing.assert_allclose(ev.dY, fd, atol=1e-6 * np.abs(fd).max())
    res = term.residual(PathContext(t, Y, None, None))
    np.testing.assert_allclose((res.r ** 2).sum(1), ev.f, rtol=1e-12)
    D = np.random.default_rng(5).normal(size=Y.shape)
    dr = (term.residual(PathContext(t, Y + 1e-6 * D, None, None)).r
          - term.residual(PathContext(t, Y - 1e-6 * D, None, None)).r) / 2e-6
    np.testing.assert_allclose(res.jvp(D), dr, atol=1e-6 * np.abs(dr).max())


def test_anatomy_figures_of_a_hand_built_motion(figure_model, layout):
    """Three poses: the left knee 10 degrees off its hinge, the right elbow 30 degrees off its hinge
    (flexed 60), the left hip flexed 130 degrees (10 past the table): the figures read those maxima,
    name the motion, and the summary rows show plain, optimized and the capture's own figure."""
    from runner.motion_metrics import anatomy_figures
    from runner.run import anatomy_summary_rows

    Y = identity(layout, 3)
    Y[0, layout.joint("l_knee").quat_index] = mul(quat(X, 10.0), quat(Y_, 20.0))
    Y[1, layout.joint("r_elbow").quat_index] = mul(quat(Z, 30.0), quat(-Y_, 60.0))
    Y[2, layout.joint("l_hip").quat_index] = quat(Y_, -130.0)
    got = anatomy_figures(figure_model, 2.0 * Y)
    assert got["off_hinge_knee_deg"] == pytest.approx(10.0) and got["off_hinge_elbow_deg"] == pytest.approx(30.0)
    assert got["off_hinge_deg"]["r_knee"] == pytest.approx(0.0, abs=1e-6)
    assert got["rom_excess_deg"] == pytest.approx(10.0) and got["rom_excess_motion"] == "l_hip flexion / extension"
    still = anatomy_figures(figure_model, identity(layout, 2))
    assert still["rom_excess_deg"] == 0.0 and still["rom_excess_motion"] == "" and still["off_hinge_knee_deg"] == 0.0
    motion = {"plain": {"path": still, "reference": got}, "optimized": {"path": got}}
    rows = anatomy_summary_rows(motion)
    assert [r[0] for r in rows] == ["knee rotation off the hinge [deg] (capture 10.0)",
                                    "elbow rotation off the hinge [deg] (capture 30.0)",
                                    "beyond range of motion [deg] (capture 10.0)"]
    assert [r[1:3] for r in rows] == [(0.0, pytest.approx(10.0)), (0.0, pytest.approx(30.0)), (0.0, pytest.approx(10.0))]


