"""runner/clean_metrics.py: a cleaned clip's deviation from its capture on hand-built changes whose answers are
known: joint angles turned by scipy's rotations, and the whole figure shifted."""
import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import solver
from runner.clean_metrics import clean_figures
from solver.quaternion import mul

FPS = 30.0  # [Hz]
N = 20  # frames


def _rotate(q: np.ndarray, deg: float, axis) -> np.ndarray:
    """q (w, x, y, z) times a rotation of `deg` about `axis` (in q's own frame)."""
    r = Rotation.from_rotvec(np.radians(deg) * np.asarray(axis, float) / np.linalg.norm(axis)).as_quat()
    return mul(q, np.r_[r[3], r[:3]])


def _figure():
    return solver.load_model(solver.shipped("run_and_step.xml"))


def test_the_joint_angles_are_the_rotations_made():
    """The capture stands still; the clean turns the right knee 30 degrees at five frames and the root 10 degrees
    at one, and negates the left hip's quaternion at every frame (the same rotation): the angle's max is 30
    degrees, its mean (5 x 30 + 10) / (N x the rotations), a rotation being each ball joint and the free root
    (counted by MuJoCo's joint types)."""
    model = _figure()
    layout = solver.StateLayout.from_model(model)
    capture = np.tile(model.qpos0, (N, 1))
    clean = capture.copy()
    knee = layout.joint("r_knee").quat_index
    for i in range(5, 10):
        clean[i, knee] = _rotate(capture[i, knee], 30.0, [0.2, 1.0, 0.1])
    root = layout.quat_slots[0]
    clean[12, root] = _rotate(capture[12, root], 10.0, [0.0, 0.0, 1.0])
    hip = layout.joint("l_hip").quat_index
    clean[:, hip] = -capture[:, hip]
    f = clean_figures(model, clean, capture, FPS, capture)
    rotations = int(np.isin(model.jnt_type, (mujoco.mjtJoint.mjJNT_BALL, mujoco.mjtJoint.mjJNT_FREE)).sum())
    assert f["angle_max_deg"] == pytest.approx(30.0, abs=1e-5)  # acos near 0 keeps about half the digits
    assert f["angle_mean_deg"] == pytest.approx((5 * 30.0 + 10.0) / (N * rotations), abs=1e-6)


def test_a_figure_shifted_whole_deviates_by_the_shift_and_turns_no_joint():
    """The clean is the capture 2 cm higher at every frame: every body's origin is 2 cm from its place (mean and max),
    and no joint turns."""
    model = _figure()
    capture = np.tile(model.qpos0, (N, 1))
    clean = capture.copy()
    clean[:, 2] += 0.02  # the free root's height [m]
    f = clean_figures(model, clean, capture, FPS, capture)
    assert f["deviation_mean_cm"] == pytest.approx(2.0, abs=1e-9)
    assert f["deviation_max_cm"] == pytest.approx(2.0, abs=1e-9)
    assert f["angle_max_deg"] == pytest.approx(0.0, abs=1e-6)


def test_a_foot_rolled_onto_its_edge_is_the_depth_its_edge_goes_beyond_the_capture_s():
    """The capture stands on the floor; the clean turns the left foot 20 degrees about its long axis (x) at the ankle
    at one frame: its sole's inner edge at (x, y, z) in the foot's frame goes to the ankle's height plus
    y sin 20 + z cos 20 (a rotation by hand), which the soles' figure reports. With the capture rolled alike,
    nothing is beyond it."""
    model = _figure()
    capture = np.tile(model.qpos0, (N, 1))
    data = mujoco.MjData(model)
    data.qpos[:] = capture[0]
    mujoco.mj_kinematics(model, data)
    capture[:, 2] -= data.site_xpos[[model.site(s).id for s in ("l_heel", "l_toe", "r_heel", "r_toe")], 2].min()
    capture[:, 0] = -3.0  # away from the step
    data.qpos[:] = capture[0]
    mujoco.mj_kinematics(model, data)
    ankle = data.body("l_foot").xpos[2]
    clean = capture.copy()
    a = np.radians(20.0)
    slot = model.joint("l_ankle").qposadr[0]
    clean[7, slot:slot + 4] = [np.cos(a / 2), np.sin(a / 2), 0.0, 0.0]
    _, y, z = model.site("l_sole_in").pos
    f = clean_figures(model, clean, capture, FPS, capture)
    assert f["sole_mm"] == pytest.approx(-1000.0 * (ankle + y * np.sin(a) + z * np.cos(a)), abs=1e-6)
    assert clean_figures(model, clean, clean, FPS, clean)["sole_mm"] == 0.0
