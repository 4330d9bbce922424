"""Postures the import reads right (runner/capture/body_frames.py), on hand-built clips (tests/posture_clips.py).

* A knee's flexion axis has the right sign in any posture (`_hinge_flipped`): a seated subject - thighs level
  the whole clip, knees bent 80-100 degrees, elbows 35-55, the arms down or overhead - reads as the flexion it
  is, not as hyperextension that the import's clean-up would clamp. The sign was once taken from the shin's
  swing against the pelvis's forward direction, which is zero when the thighs are level, and a seated
  capture's right knee came out bent backwards by 113 degrees, its foot 70 cm off on the way back.
* A foot's up axis is measured where it stands flat (`_flat`), not where a kneeling subject's foot lies on
  its top."""
import numpy as np
import pytest
from posture_clips import ELBOW, KNEE, STAND, SWING, kneeling_clip, rounded_arms_clip, seated_clip

#: [rad] a standing foot's up axis is this near the world's: the clip's feet stand flat, and the figure's foot
#: frame is a mean over the clip's (30 deg: far inside the 180 deg of a foot turned over)
UPRIGHT = float(np.radians(30.0))


@pytest.mark.parametrize("arms_up", [False, True], ids=["arms down", "arms overhead"])
@pytest.mark.parametrize("joint, bent", [("l_knee", KNEE), ("r_knee", KNEE), ("l_elbow", ELBOW), ("r_elbow", ELBOW)])
def test_a_seated_subjects_knees_and_elbows_read_as_flexed(tmp_path, joint, bent, arms_up):
    from runner.capture.reference_motion import load_bvh_reference
    from runner.paths import MODELS
    from solver.figure import Figure
    from solver.layout import StateLayout
    from solver.model import load_model
    from solver.quaternion import twist_angle

    model = load_model(MODELS / "run_and_step.xml")
    ref = load_bvh_reference(seated_clip(tmp_path / "seated.bvh", arms_up=arms_up), model)
    figure = Figure.from_model(model)
    axis = np.asarray(figure.flexion_axes[joint], float)
    flexion = np.degrees(twist_angle(ref.qpos[:, StateLayout.from_model(model).joint(joint).quat_index], axis / np.linalg.norm(axis)))
    clamped = (ref.clamped or {}).get(joint, np.zeros(1))
    assert np.max(clamped) == 0.0, f"{joint}: the import clamped {np.max(clamped):.1f} deg of hyperextension"
    # [deg] the figure's flexion is the clip's within 15 deg: the figure's bones are not the clip's, and its
    # flexion axis is the measured hinge's, so the angle differs by the bones' and axes' misfit
    assert np.all(np.abs(flexion - flexion.mean()) <= SWING + 15.0) and abs(flexion.mean() - bent) <= 15.0, \
        f"{joint}: flexion {flexion.min():.1f}..{flexion.max():.1f} deg, the clip bends it {bent} +- {SWING}"


def test_a_kneeling_subjects_feet_stand_upright_where_the_clip_stands(tmp_path):
    """A foot's up axis is measured where it stands flat (runner/capture/body_frames.py, `_flat`): kneeling
    with the feet on their tops puts the ankles lower than standing does, but those feet lie upside down, and
    taken for flat they turned the figure's feet over where the clip stands. There each figure foot's up axis is
    within UPRIGHT of the world's."""
    import mujoco

    from runner.capture.reference_motion import load_bvh_reference
    from runner.paths import MODELS
    from solver.model import load_model

    model = load_model(MODELS / "run_and_step.xml")
    ref = load_bvh_reference(kneeling_clip(tmp_path / "kneel.bvh"), model)
    data = mujoco.MjData(model)
    for i in range(int(0.9 * STAND * ref.count)):  # standing, before it kneels down
        data.qpos[:] = ref.qpos[i]
        mujoco.mj_kinematics(model, data)
        for foot in ("l_foot", "r_foot"):
            up = data.xmat[model.body(foot).id].reshape(3, 3)[:, 2]  # the body's z axis, in the world
            assert up[2] >= np.cos(UPRIGHT), f"frame {i}: {foot} {np.degrees(np.arccos(np.clip(up[2], -1, 1))):.0f} deg off upright"


@pytest.mark.parametrize("joint", ["l_elbow", "r_elbow"])
def test_arms_rounded_in_front_read_as_flexed(tmp_path, joint):
    """An elbow's sign (`_hinge_flipped`): arms held rounded in front of the body (a dancer's first position)
    swing their forearms across the chest and a little back as the elbows flex, which the forearm's forward
    swing read as hyperextension, and the import straightened a pirouette's right elbow bent 24-88 degrees. An
    elbow bent further than elbows hyperextend (`ELBOW_HYPEREXTENSION`) in most frames is flexed: no clamp, and
    the figure's flexion is the clip's within 15 degrees (as the seated subject's)."""
    from runner.capture.reference_motion import load_bvh_reference
    from runner.paths import MODELS
    from solver.figure import Figure
    from solver.layout import StateLayout
    from solver.model import load_model
    from solver.quaternion import twist_angle

    model = load_model(MODELS / "run_and_step.xml")
    ref = load_bvh_reference(rounded_arms_clip(tmp_path / "rounded.bvh"), model)
    axis = np.asarray(Figure.from_model(model).flexion_axes[joint], float)
    flexion = np.degrees(twist_angle(ref.qpos[:, StateLayout.from_model(model).joint(joint).quat_index], axis / np.linalg.norm(axis)))
    clamped = (ref.clamped or {}).get(joint, np.zeros(1))
    assert np.max(clamped) == 0.0, f"{joint}: the import clamped {np.max(clamped):.1f} deg of hyperextension"
    assert abs(flexion.mean() - ELBOW) <= 15.0, f"{joint}: flexion {flexion.min():.1f}..{flexion.max():.1f} deg, the clip bends it {ELBOW}"


def test_a_knee_displaced_by_position_channels_still_points_the_shin(tmp_path):
    """A file that moves joints by position channels of their own (Perception Neuron "with displacement") no
    longer has the knee's rotation point the shin: here it is off by up to 15 deg, the foot's translation and
    rotation turned back so that the ankle and foot are where the clip without them has them (the known
    answer). The retarget turns each limb along its bone (`retarget._along_bones`): the knees' and ankles'
    flexion is the plain clip's within 0.5 deg (the body frames are measured on each file apart)."""
    from runner.capture.reference_motion import load_bvh_reference
    from runner.paths import MODELS
    from solver.figure import Figure
    from solver.layout import StateLayout
    from solver.model import load_model
    from solver.quaternion import twist_angle

    model = load_model(MODELS / "run_and_step.xml")
    figure, layout = Figure.from_model(model), StateLayout.from_model(model)
    plain = load_bvh_reference(seated_clip(tmp_path / "plain.bvh"), model)
    shifted = load_bvh_reference(seated_clip(tmp_path / "displaced.bvh", displaced=15.0), model)
    for joint in ("l_knee", "r_knee"):
        axis = np.asarray(figure.flexion_axes[joint], float)
        a, b = (np.degrees(twist_angle(r.qpos[:, layout.joint(joint).quat_index], axis / np.linalg.norm(axis))) for r in (plain, shifted))
        assert np.max(np.abs(a - b)) <= 0.5, f"{joint}: flexion {np.max(np.abs(a - b)):.2f} deg off the plain clip's"
    for side in "lr":  # the ankle's whole rotation (not a hinge): its angle from the plain clip's
        q = layout.joint(f"{side}_ankle").quat_index
        dot = np.abs(np.sum(plain.qpos[:, q] * shifted.qpos[:, q], axis=1))
        assert np.degrees(2 * np.arccos(np.clip(dot, 0, 1))).max() <= 0.5, f"{side}_ankle"


@pytest.mark.parametrize("flexion_deg", [28.0, -28.0])
def test_the_clamp_reads_a_knee_by_its_rotation_not_its_quaternions_sign(flexion_deg):
    """A knee flexed (or bent backwards) 28 degrees held as -q (w < 0, as a hemisphere-continuous series can
    reach): the hyperextension and its clamp are those of q. Read as 2 atan2(v.axis, w) the flexion was -332
    (or +332) degrees: a flexed knee reported hyperextended by 332 degrees and straightened."""
    import math

    import mujoco

    from runner.capture.retarget import clamp_hyperextension, hyperextension
    from solver.figure import FIGURE_FILE, Figure

    model = mujoco.MjModel.from_xml_path(str(FIGURE_FILE))
    figure = Figure.from_model(model)
    axis = np.asarray(figure.flexion_axes["l_knee"], float)
    half = math.radians(flexion_deg) / 2.0
    qpos = np.tile(model.qpos0, (2, 1))
    qpos[:, figure.joint("l_knee").qpos_slice] = [np.r_[math.cos(half), math.sin(half) * axis],
                                                   -np.r_[math.cos(half), math.sin(half) * axis]]
    backwards = max(0.0, -flexion_deg)
    np.testing.assert_allclose(hyperextension(qpos, figure)["l_knee"], [backwards, backwards], atol=1e-9)
    clamped, changed = clamp_hyperextension(qpos, figure)
    assert changed == (2 if backwards else 0)
    np.testing.assert_allclose(hyperextension(clamped, figure)["l_knee"], 0.0, atol=1e-9)
