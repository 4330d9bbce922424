"""runner.jolts on hand-built motions of the figure with known answers: a pelvis on a sine, a ball joint at
constant angular acceleration under a turning root, a figure standing still (torques against statics and
MuJoCo's own inverse dynamics), the capture's 6 Hz low-pass filter against the Butterworth response."""
import copy
from pathlib import Path

import mujoco
import numpy as np
import pytest
from shipped_sites import SITES

from runner.capture.scene_fit import FittedScene, scene_mjcf
from runner.jolts import filter_capture, jolt_figures, worst_joint_ratio
from runner.motion_metrics import motion_metrics
from solver.contacts import Contact
from solver.errors import InputError
from solver.layout import StateLayout
from solver.peak_bounds import CUTOFF_HZ, TWO_PASS_CORRECTION

ROOT = Path(__file__).resolve().parents[2]
FPS = 120.0


@pytest.fixture(scope="module")
def model():
    return mujoco.MjModel.from_xml_string(scene_mjcf(FittedScene(0.0), ROOT / "models" / "humanoid39.xml"))


def standing(model, n):
    """(n, nq): the identity pose with the pelvis at 1 m."""
    q = np.tile(model.qpos0, (n, 1))
    q[:, :3] = (0.0, 0.0, 1.0)
    return q


def axis_angle(axis, angle):
    """(n, 4) unit quaternions (w, x, y, z) of rotations by angle (n,) [rad] about the unit axis (3,)."""
    return np.column_stack([np.cos(angle / 2), np.outer(np.sin(angle / 2), axis)])


def ball_joints(model):
    return {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j): j for j in range(model.njnt)
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL}


def test_a_pelvis_on_a_sine_peaks_at_a_w2(model):
    # x = A sin(w t), 1 Hz, frames on both peaks (t = 0.25 s and 0.75 s). The central second difference of a
    # sine is the sine's second derivative times (sin(w/2fps) / (w/2fps))^2: 2.3e-4 low at 120 Hz
    n, amp, w = 121, 0.1, 2 * np.pi
    q = standing(model, n)
    q[:, 0] += amp * np.sin(w * np.arange(n) / FPS)
    f = jolt_figures(model, q, FPS)
    assert f["peak_pelvis_acceleration_m_s2"] == pytest.approx(amp * w**2, rel=3e-4)
    x = w / (2 * FPS)
    assert f["peak_pelvis_acceleration_m_s2"] == pytest.approx(amp * w**2 * (np.sin(x) / x) ** 2, rel=1e-9)
    assert f["peak_pelvis_acceleration_t_s"] in (pytest.approx(0.25), pytest.approx(0.75))
    assert f["peak_angular_acceleration_max_rad_s2"] == pytest.approx(0.0, abs=1e-9)  # no joint turns


def test_a_ball_joint_at_constant_angular_acceleration_under_a_turning_root(model):
    # the left knee turns about a fixed oblique axis with theta = 0.2 + 0.5 t + 3 t^2 / 2: 3 rad/s^2 at every
    # frame (the half-step rates of a quadratic angle are exact, so is their difference); the root yaws at a
    # constant 2 rad/s and glides at 1 m/s: it turns the knee's parent, not the knee's relative rotation
    n, alpha = 121, 3.0
    t = np.arange(n) / FPS
    q = standing(model, n)
    q[:, 0] += 1.0 * t
    q[:, 3:7] = axis_angle(np.array([0.0, 0.0, 1.0]), 2.0 * t)
    knee = ball_joints(model)["l_knee"]
    adr = model.jnt_qposadr[knee]
    q[:, adr:adr + 4] = axis_angle(np.array([2.0, -1.0, 2.0]) / 3.0, 0.2 + 0.5 * t + alpha * t**2 / 2)
    f = jolt_figures(model, q, FPS)
    peaks = f["peak_angular_acceleration_rad_s2"]
    assert set(peaks) == set(ball_joints(model))
    assert peaks["l_knee"] == pytest.approx(alpha, rel=1e-6)
    assert max(v for j, v in peaks.items() if j != "l_knee") == pytest.approx(0.0, abs=1e-6)
    assert f["peak_angular_acceleration_max_rad_s2"] == peaks["l_knee"]
    assert f["peak_angular_acceleration_joint"] == "l_knee"
    assert f["peak_pelvis_acceleration_m_s2"] == pytest.approx(0.0, abs=1e-9)


def _gravity_torques_by_statics(model, qpos):
    """{ball joint: (3,) [N m]} the torque each ball joint must hold against gravity in a static pose, in its
    child's frame: -(c - p) x (M g), M and c the mass and centre of mass of the subtree it carries, p its
    anchor (no MuJoCo dynamics: positions from mj_kinematics and mj_comPos only)."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    out = {}
    for name, j in ball_joints(model).items():
        b = model.jnt_bodyid[j]
        moment = np.cross(data.subtree_com[b] - data.xanchor[j], model.body_subtreemass[b] * model.opt.gravity)
        out[name] = data.xmat[b].reshape(3, 3).T @ -moment
    return out


def test_a_figure_standing_still_holds_gravity_alone(model):
    # a bent pose held still for 13 frames: no acceleration, and every frame's joint torques are gravity's
    rng = np.random.default_rng(3)
    n = 13
    q = standing(model, n)
    for j in ball_joints(model).values():
        adr = model.jnt_qposadr[j]
        q[:, adr:adr + 4] = axis_angle(rng.normal(size=3) / np.sqrt(3), rng.uniform(0.2, 0.8))
    f = jolt_figures(model, q, FPS)
    assert f["peak_pelvis_acceleration_m_s2"] == pytest.approx(0.0, abs=1e-9)
    assert f["peak_angular_acceleration_max_rad_s2"] == pytest.approx(0.0, abs=1e-6)
    statics = _gravity_torques_by_statics(model, q[0])
    by_statics = np.sqrt(sum(v @ v for v in statics.values()))
    # MuJoCo's own inverse dynamics at rest, constraints (the floor's contacts) off: gravity alone
    m = copy.copy(model)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    data = mujoco.MjData(m)
    data.qpos[:], data.qvel[:], data.qacc[:] = q[0], 0.0, 0.0
    mujoco.mj_inverse(m, data)
    dofs = [m.jnt_dofadr[j] + k for j in ball_joints(m).values() for k in range(3)]
    by_mujoco = np.linalg.norm(data.qfrc_inverse[dofs])
    for name, j in ball_joints(m).items():
        adr = m.jnt_dofadr[j]
        np.testing.assert_allclose(data.qfrc_inverse[adr:adr + 3], statics[name], atol=1e-9)
    assert by_statics > 20.0  # the bent pose loads the joints (46 N m)
    assert f["rms_joint_torque_Nm"] == pytest.approx(by_mujoco, rel=1e-9)
    assert f["rms_joint_torque_Nm"] == pytest.approx(by_statics, rel=1e-9)


def _amplitude(x, f, t):
    """The amplitude and phase [rad] of x's component at f [Hz] over whole periods (least squares)."""
    basis = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
    (a, b), *_ = np.linalg.lstsq(basis, x, rcond=None)
    return np.hypot(a, b), np.arctan2(b, a)


@pytest.mark.parametrize("freq", [1.0, 20.0])
def test_the_capture_filter_keeps_1_hz_and_removes_20_hz(model, freq):
    # the digital Butterworth (bilinear, prewarped at the design frequency fd = 6 Hz / 0.802) run forward and
    # backward passes a sine at f with gain 1 / (1 + (tan(pi f / fs) / tan(pi fd / fs))^4), no phase shift:
    # 0.9997 at 1 Hz, 0.0137 at 20 Hz; read over 3 s in the middle of 5 s (the ends' transients die in ~0.1 s)
    n = 601
    t = np.arange(n) / FPS
    q = standing(model, n)
    q[:, 0] = np.sin(2 * np.pi * freq * t)
    out = filter_capture(t, q, StateLayout.from_model(model))
    mid = slice(120, 480)
    amp, phase = _amplitude(out[mid, 0], freq, t[mid])
    ratio = np.tan(np.pi * freq / FPS) / np.tan(np.pi * CUTOFF_HZ / TWO_PASS_CORRECTION / FPS)
    assert amp == pytest.approx(1.0 / (1.0 + ratio**4), abs=1e-4)
    assert phase == pytest.approx(0.0, abs=1e-3)  # zero lag
    assert (amp > 0.999) if freq == 1.0 else (amp < 0.02)
    np.testing.assert_allclose(out[:, 3:], q[:, 3:], atol=1e-12)  # still joints and root stay still


def test_the_reference_jolts_are_the_filtered_captures(model):
    # the capture: the pelvis on a 1 Hz, 10 cm sine with a 20 Hz, 1 mm tremor (raw peak about 3.9 + 15.8 m/s^2);
    # filtered at 6 Hz the tremor keeps 1.4 % of itself, so the peak is the sine's 3.95 to within 0.25 m/s^2
    n = 361
    t = np.arange(n) / FPS
    ref = standing(model, n)
    ref[:, 0] += 0.1 * np.sin(2 * np.pi * t) + 0.001 * np.sin(2 * np.pi * 20 * t)
    smooth = filter_capture(t, ref, StateLayout.from_model(model))
    contacts = [Contact(s, 0.0, (n - 1) / FPS) for s in SITES]
    m = motion_metrics(model, standing(model, n), FPS, ref, contacts, capture_filtered=smooth)
    assert m["reference"]["peak_pelvis_acceleration_m_s2"] == pytest.approx(0.1 * (2 * np.pi) ** 2, abs=0.25)
    assert m["path"]["peak_pelvis_acceleration_m_s2"] == pytest.approx(0.0, abs=1e-9)
    raw = motion_metrics(model, standing(model, n), FPS, ref, contacts)["reference"]
    assert raw["peak_pelvis_acceleration_m_s2"] > 15.0  # unfiltered: the tremor dominates
    with pytest.raises(InputError, match="capture_filtered"):
        motion_metrics(model, ref, FPS, ref, contacts, capture_filtered=smooth[:-1])


def test_the_worst_joint_ratio_is_against_the_larger_reference():
    path, plain, capture = {"a": 30.0, "b": 10.0}, {"a": 10.0, "b": 2.0}, {"a": 20.0, "b": 4.0}
    assert worst_joint_ratio(path, plain, capture) == ("b", 2.5)  # b: 10 / max(2, 4); a: 30 / 20 = 1.5
    assert worst_joint_ratio(path, plain) == ("b", 5.0)
    assert worst_joint_ratio({"a": 1.0}, {"a": 0.0}, {"a": 0.0})[1] == pytest.approx(1e3)  # still: finite
    assert worst_joint_ratio({"a": 1.0}, {"b": 1.0}) is None


def test_too_few_frames_is_a_clear_error(model):
    with pytest.raises(InputError, match="n >= 3"):
        jolt_figures(model, standing(model, 2), FPS)
