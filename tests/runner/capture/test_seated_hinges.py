"""A knee's flexion axis has the right sign in any posture (runner/capture/body_frames.py, `_hinge_flipped`): a
hand-built clip of a seated subject - thighs level the whole clip, knees bent 80-100 degrees, elbows 35-55 -
reads as the flexion it is, not as hyperextension that the import's clean-up would clamp. The sign was once
taken from the shin's swing against the pelvis's forward direction, which is zero when the thighs are level,
and a seated capture's right knee came out bent backwards by 113 degrees, its foot 70 cm off on the way back."""
import numpy as np
import pytest
from seated_clip import ELBOW, KNEE, SWING, seated_clip


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
