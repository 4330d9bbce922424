"""BVH export: the file reads back with our own reader and reproduces the sampled qpos."""
import numpy as np
import pytest

from runner.export.bvh import EULER_ORDER, figure_qpos_from_bvh, figure_skeleton, write_bvh
from runner.export.sampling import WHICH, default_fps, sample_motion
from runner.mocap.bvh import read_bvh
from runner.saved_path import load_saved_path
from solver.errors import InputError
from solver.layout import StateLayout


def rotation_error(a, b, layout):
    """Largest angle [rad] between the rotations of a and b (q and -q are the same rotation)."""
    err = 0.0
    for idx in layout.quat_slots:
        dot = np.abs((a[:, idx] * b[:, idx]).sum(axis=1)) / (
            np.linalg.norm(a[:, idx], axis=1) * np.linalg.norm(b[:, idx], axis=1))
        err = max(err, float((2.0 * np.arccos(np.clip(dot, 0.0, 1.0))).max()))
    return err


@pytest.mark.parametrize("which", WHICH)
def test_round_trip_reproduces_sampled_qpos(tmp_path, saved_npz, scene_model, which):
    saved = load_saved_path(saved_npz)
    layout = StateLayout.from_model(scene_model)
    motion = sample_motion(saved, which, default_fps(saved), layout.quat_slots)
    out = tmp_path / "clip.bvh"
    write_bvh(out, scene_model, motion.qpos, motion.fps)
    clip = read_bvh(out)
    assert clip.local_quat.shape[:2] == (len(motion.times), 14)  # 12 bodies, the fixed neck and head
    assert clip.frame_time == pytest.approx(1.0 / motion.fps, rel=1e-6)
    back = figure_qpos_from_bvh(clip, scene_model)
    assert np.abs(back[:, :3] - motion.qpos[:, :3]).max() < 1e-6  # [m]
    assert rotation_error(back, motion.qpos, layout) < 1e-6  # [rad]


def test_gimbal_lock_and_large_angles_round_trip(tmp_path, scene_model):
    """Rotations of exactly 90 degrees about the middle Euler axis, and half turns, survive."""
    from scipy.spatial.transform import Rotation

    layout = StateLayout.from_model(scene_model)
    angles = [[0, 90, 0], [30, 90, -20], [179.9, -90, 45], [180, 0, 180], [-170, 45, 170]]
    q = np.zeros((len(angles), scene_model.nq))
    q[:, 2] = 1.0
    for k, (a, b, c) in enumerate(angles):  # BVH axes Y Z X = MuJoCo z x y
        r = Rotation.from_euler("zxy", [a, b, c], degrees=True).as_quat()[[3, 0, 1, 2]]
        for idx in layout.quat_slots:
            q[k, idx] = r
    out = tmp_path / "lock.bvh"
    write_bvh(out, scene_model, q, 30.0)
    back = figure_qpos_from_bvh(read_bvh(out), scene_model)
    assert rotation_error(back, q, layout) < 1e-6
    assert EULER_ORDER == "YZX"


def test_skeleton_is_upright_in_bvh_axes(tmp_path, scene_model):
    """Y up: the torso sits above the pelvis, the thighs below, left at +X (Blender imports it upright)."""
    identity = np.r_[0, 0, 1.0, 1, 0, 0, 0, [1, 0, 0, 0] * 11]
    write_bvh(tmp_path / "id.bvh", scene_model, np.stack([identity, identity]), 30.0)  # our reader wants >= 2
    clip = read_bvh(tmp_path / "id.bvh")
    off = dict(zip(clip.names, clip.offsets))
    assert off["torso"][1] > 0 and off["l_thigh"][1] < 0 and off["l_thigh"][0] > 0
    assert clip.local_pos[0, clip.index("pelvis")] == pytest.approx([0, 1.0, 0])  # root height on Y
    sk = figure_skeleton(scene_model)
    assert sk.names[0] == "pelvis" and sk.count == 14 and sk.names[-2:] == ("neck", "head")
    assert figure_skeleton(scene_model, head=False).count == 12


def test_clip_without_figure_joints_is_refused(scene_model):
    from runner.paths import MODELS

    clip = read_bvh(MODELS / "cmu" / "127_33.bvh")
    with pytest.raises(InputError, match="not on the figure's skeleton"):
        figure_qpos_from_bvh(clip, scene_model)


def test_our_bvh_of_the_127_33_reference_reads_back_as_the_reference(tmp_path, scene_model):
    """The reference motion (CMU 127_33 retargeted) exported as BVH is a clip on the figure's own skeleton:
    the importer recognizes it and reads it without retargeting (every frame, same qpos)."""
    from runner.export.bvh import is_figure_clip
    from runner.mocap.reference import load_bvh_reference
    from runner.paths import MODELS

    ref = load_bvh_reference(MODELS / "cmu" / "127_33.bvh", scene_model)
    assert not is_figure_clip(read_bvh(MODELS / "cmu" / "127_33.bvh"), scene_model)
    out = tmp_path / "ref.bvh"
    write_bvh(out, scene_model, ref.qpos, 1.0 / ref.frame_time)
    assert is_figure_clip(read_bvh(out), scene_model)
    back = load_bvh_reference(out, scene_model)
    layout = StateLayout.from_model(scene_model)
    assert back.qpos.shape == ref.qpos.shape and back.frame_time == pytest.approx(ref.frame_time, rel=1e-9)
    assert np.abs(back.qpos[:, :3] - ref.qpos[:, :3]).max() < 1e-6  # [m]
    assert rotation_error(back.qpos, ref.qpos, layout) < 1e-6  # [rad]
    assert np.allclose(back.times, ref.times)


def rest_points(text):
    """{name: (3,) rest position} of every joint and End Site of a BVH file, from its OFFSETs alone (an
    independent reader of the HIERARCHY: the rest armature Blender builds), BVH axes."""
    points, stack, name, pending = {}, [], None, None
    for line in text.split("MOTION")[0].splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] in ("ROOT", "JOINT"):
            pending = words[1]
        elif words[0] == "End":
            pending = f"{stack[-1][0]}_end"
        elif words[0] == "{":
            stack.append((pending, None))
        elif words[0] == "OFFSET":
            base = stack[-2][1] if len(stack) > 1 else np.zeros(3)
            name = stack[-1][0]
            stack[-1] = (name, base + np.array(words[1:4], float))
            points[name] = stack[-1][1]
        elif words[0] == "}":
            stack.pop()
    return points


def test_rest_armature_spans_the_standing_height(tmp_path, scene_model):
    """The rest armature (OFFSETs only) reaches from the tip of the soles to the top of the head: the
    figure's standing height (1.75 m) within 2 cm; at the identity pose the head's End Site is that high
    above the floor."""
    from solver.figure import Figure

    height = Figure.from_model(scene_model).standing_height
    identity = np.r_[0, 0, 1.0, 1, 0, 0, 0, [1, 0, 0, 0] * 11]
    write_bvh(tmp_path / "id.bvh", scene_model, np.stack([identity, identity]), 30.0)
    points = rest_points((tmp_path / "id.bvh").read_text())
    y = np.array([p[1] for p in points.values()])
    assert y.max() - y.min() == pytest.approx(height, abs=0.02)
    assert y.max() == points["head_end"][1]
    assert 1.0 + points["head_end"][1] == pytest.approx(height, abs=0.02)  # root channel Y = 1.0 at rest
    clip = read_bvh(tmp_path / "id.bvh")
    assert list(clip.names[-2:]) == ["neck", "head"]
    np.testing.assert_allclose(clip.local_quat[:, clip.index("head")], [[1, 0, 0, 0]] * 2, atol=1e-12)


def test_another_figures_armature_has_its_height(tmp_path):
    """The BVH of a figure 10 % larger spans that figure's standing height (1.925 m): the skeleton comes
    from the model, not from the shipped figure's numbers."""
    import mujoco
    from tree_models import scaled_figure_xml

    from solver.figure import Figure

    model = mujoco.MjModel.from_xml_string(scaled_figure_xml(1.1))
    identity = np.r_[0, 0, 1.1, 1, 0, 0, 0, [1, 0, 0, 0] * 11]
    write_bvh(tmp_path / "big.bvh", model, np.stack([identity, identity]), 30.0)
    y = np.array([p[1] for p in rest_points((tmp_path / "big.bvh").read_text()).values()])
    assert y.max() - y.min() == pytest.approx(Figure.from_model(model).standing_height, abs=0.02)
    assert Figure.from_model(model).standing_height == pytest.approx(1.925, abs=1e-9)
