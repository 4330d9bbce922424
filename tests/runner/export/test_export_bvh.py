"""BVH export: the file reads back with our own reader and reproduces the sampled qpos; onto the source
skeleton, it reproduces the source clip (tests/bvh_fk.py: an independent reader)."""

import json

import numpy as np
import pytest
from bvh_edit import edit_bvh
from bvh_fk import UNIT, local_rotations, parse

from runner.capture.bvh import read_bvh
from runner.cli import main
from runner.export.bvh import EULER_ORDER, figure_qpos_from_bvh, figure_skeleton, write_bvh
from runner.export.sampling import WHICH, default_fps, sample_motion
from runner.paths import MODELS
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
    from runner.capture.reference_motion import load_bvh_reference
    from runner.export.bvh import is_figure_clip
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


# ---- onto the source skeleton -------------------------------------------------------------------------

SOURCE_CLIPS = sorted((MODELS / "cmu").glob("*.bvh"))  # the shipped CMU clips (models/cmu/README.md: source, licence)


def rotation_angles_deg(a, b):
    """(n, J) angle [deg] of R_a^T R_b for (n, J, 3, 3) rotation matrices."""
    cos = (np.einsum("njab,njab->nj", a, b) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def reference_path(tmp_path, src, seconds=0.5, capture=None):
    """A saved path whose frames are the reference on the subject's figure at every captured frame of the
    first `seconds` of `src` (its clip embedded), and the clip. `capture`: the scene's transform from the
    capture's coordinates (`solver.capture_frame.CaptureFrame`; None: none recorded, the identity)."""
    from runner.capture.bvh import read_bvh
    from runner.capture.reference_motion import load_bvh_reference
    from runner.capture.scene_fit import FittedScene, scene_mjcf
    from runner.capture.subject_figure import write_subject_figure
    from solver.model import load_model

    clip = edit_bvh(src, tmp_path / "c.bvh", seconds=seconds)
    figure = write_subject_figure(read_bvh(clip), tmp_path / "c.figure.xml")
    scene = tmp_path / "c.scene.xml"
    scene.write_text(scene_mjcf(FittedScene(0.0), figure, relative_to=tmp_path, capture=capture))
    ref = load_bvh_reference(clip, load_model(scene))
    npz = tmp_path / "ref.npz"
    ends = ref.qpos[[0, -1]]
    np.savez(npz, frame_times=ref.times, frames=ref.qpos, keyframe_times=ref.times[[0, -1]], keyframes=ends,
             plain_frame_times=ref.times[[0, -1]], plain_frames=ends, reference_times=ref.times,
             reference_qpos=ref.qpos, scene=np.array("c.scene.xml"), clip=np.array("c.bvh"),
             clip_text=np.array(clip.read_text()))
    return npz, clip


def glitch_frames(clip):
    """File frame indices (the rest frame first) that the import's glitch repair replaced
    (`runner.capture.glitches`), from the clip read on a floor-only scene of its own figure."""
    from runner.capture.bvh import read_bvh
    from runner.capture.reference_motion import load_bvh_reference
    from runner.capture.scene_fit import FittedScene, scene_mjcf
    from runner.capture.subject_figure import write_subject_figure
    from solver.model import load_model

    folder = clip.parent / "glitches"
    folder.mkdir(exist_ok=True)
    figure = write_subject_figure(read_bvh(clip), folder / "c.figure.xml")
    scene = folder / "c.scene.xml"
    scene.write_text(scene_mjcf(FittedScene(0.0), figure, relative_to=folder))
    ref = load_bvh_reference(clip, load_model(scene))
    rest = ref.skeleton.rest_frames
    return sorted({rest + i for g in ref.glitches for i in range(round(g.start / ref.frame_time),
                                                                round(g.end / ref.frame_time) + 1)})


def same_pose(src, out, frames_src, frames_out):
    """Worst joint rotation [deg] and root distance [m] between frames of two files on one skeleton
    (parsed and converted by tests/bvh_fk.py)."""
    a, b = parse(src), parse(out)
    ra, rb = local_rotations(a)[frames_src], local_rotations(b)[frames_out]
    root = [a.channels[0].index(c) for c in ("Xposition", "Yposition", "Zposition")]
    dist = np.linalg.norm(a.values[frames_src][:, root] - b.values[frames_out][:, root], axis=1) * UNIT
    return rotation_angles_deg(ra, rb).max(), dist.max()


def root_correction_m(npz, clip, capture=None):
    """(n, 3) [m] the reference's root minus the clip's own Hips path (tests/bvh_fk.py forward kinematics,
    MuJoCo axes) moved by the scene's transform `capture` (None: the identity)."""
    from bvh_fk import world

    from solver.capture_frame import CaptureFrame

    _, pw = world(parse(clip))
    return np.load(npz)["frames"][:, :3] - (capture or CaptureFrame.identity()).points(pw[1:, 0])


@pytest.mark.parametrize("src", SOURCE_CLIPS, ids=lambda p: p.stem)
def test_the_reference_exported_on_the_source_skeleton_is_the_source(tmp_path, src):
    """The reference's root is the Hips path raised or lowered per frame so that its feet stand on the
    scene's floor (here z = 0 of the capture, a few cm off the captured feet); the export takes that
    height correction off again: the source file, every joint within 0.01 degree, the root within 0.1 mm,
    but in the frames where the import repaired a tracking glitch (16_23's right shoulder at 0.025 s)."""
    npz, clip = reference_path(tmp_path, src)
    c = root_correction_m(npz, clip)
    assert np.abs(c[:, :2]).max() < 1e-6 and np.abs(c[:, 2]).max() > 0.002  # vertical (1 um), and there to undo
    out = tmp_path / "out.bvh"
    assert main(["export", str(npz), "--to", str(out), "--quiet"]) == 0
    text, source = out.read_text().splitlines(), clip.read_text().splitlines()
    m = source.index("MOTION")
    assert text[:m + 3] == source[:m + 3]  # hierarchy, names, offsets, channel order; frame count and time
    n = int(source[m + 1].split()[1])
    kept = np.setdiff1d(np.arange(n), glitch_frames(clip))  # the import repairs a capture's tracking glitches
    angle, dist = same_pose(clip, out, kept, kept)
    assert angle < 0.01 and dist < 1e-4, (angle, dist)


def test_a_levelled_reference_exports_back_into_the_sources_coordinates(tmp_path):
    """A scene recording a levelling transform (a capture floor tilted by 1.3 degrees, 4 cm up): the
    reference lives in the levelled frame (its root is the source's Hips moved by T, plus the vertical
    height correction that stands its feet on the floor), and the export takes the correction off and
    the root back by T^-1: the source file again, every joint within 0.01 degree, the root within 0.1 mm."""
    import mujoco
    from bvh_fk import AXES, UNIT

    from runner.capture.bvh import read_bvh
    from runner.saved_path import load_saved_path
    from solver.capture_frame import CaptureFrame

    t = CaptureFrame.levelling(0.04, (0.02, -0.01))
    npz, clip = reference_path(tmp_path, MODELS / "cmu" / "127_33.bvh", seconds=0.3, capture=t)
    assert load_saved_path(npz).has_reference  # the export finds there the correction to take off
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "c.scene.xml"))
    src = read_bvh(clip)
    hips = src.local_pos[1:, 0] @ AXES.T * UNIT  # the captured root, MuJoCo axes [m]
    c = root_correction_m(npz, clip, t)
    assert np.abs(c[:, :2]).max() < 1e-6 and np.abs(c[:, 2]).max() > 0.002  # a vertical correction to undo
    assert np.abs(t.points(hips) - hips).max() > 0.01  # the transform does move it (2 cm here)
    assert CaptureFrame.from_model(model).quat == pytest.approx(t.quat, abs=1e-12)
    out = tmp_path / "out.bvh"
    assert main(["export", str(npz), "--to", str(out), "--quiet"]) == 0
    n = len(src.local_quat)
    angle, dist = same_pose(clip, out, np.arange(n), np.arange(n))
    assert angle < 0.01 and dist < 1e-4, (angle, dist)


def test_source_skeleton_needs_a_clip(tmp_path, saved_npz, capsys):
    assert main(["export", str(saved_npz), "--to", str(tmp_path / "f.bvh"), "--quiet"]) == 0  # the figure's
    assert "JOINT l_thigh" in (tmp_path / "f.bvh").read_text()
    assert main(["export", str(saved_npz), "--to", str(tmp_path / "s.bvh"), "--skeleton", "source"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not made from a BVH clip" in err and "--skeleton figure" in err


def test_other_rates_resample_the_unmodelled_joints(tmp_path):
    """At 60 fps every other captured frame; at 40 fps the source's unmodelled joints are slerped."""
    npz, clip = reference_path(tmp_path, MODELS / "cmu" / "127_33.bvh", seconds=0.3)
    out = tmp_path / "o.bvh"
    assert main(["export", str(npz), "--to", str(out), "--fps", "60", "--quiet"]) == 0
    n = (len(parse(out).values) - 1)
    angle, dist = same_pose(clip, out, 1 + 2 * np.arange(n), 1 + np.arange(n))
    assert angle < 0.01 and dist < 1e-4 and "Frame Time: 0.016666667" in out.read_text()
    assert main(["export", str(npz), "--to", str(out), "--fps", "40", "--quiet"]) == 0
    b, a = parse(out), parse(clip)
    toe = a.index("LeftToeBase")
    ra, rb = local_rotations(a)[:, toe], local_rotations(b)[:, toe]
    # frame 1 + k at t = k / 40 s = 3 k captured frames: the captured toe rotation exactly
    assert rotation_angles_deg(ra[1::3][None], rb[1:][None][:, :len(ra[1::3])]).max() < 0.01


@pytest.mark.slow
def test_an_optimized_path_meets_the_source_at_its_keyframes(tmp_path):
    """mocap on a short clip, then export: at every keyframe time the exported pose is the source's, but for
    the legs of feet the footplant put on the floor, whose joints stay within what mocap reported of it."""
    from bvh_fk import world

    src = edit_bvh(MODELS / "cmu" / "127_33.bvh", tmp_path / "run.bvh", seconds=0.6)
    assert main(["mocap", str(src), "--out-dir", str(tmp_path / "o"), "--no-render", "--max-evals", "40", "--quiet", "--no-summary"]) == 0
    out = tmp_path / "opt.bvh"
    assert main(["export", str(tmp_path / "o" / "run.npz"), "--to", str(out), "--quiet"]) == 0
    saved = load_saved_path(tmp_path / "o" / "run.npz")
    k = np.rint(saved.keyframe_times * 120.0).astype(int)
    assert len(k) >= 3
    a, b = parse(src), parse(out)
    legs = [i for i, n in enumerate(a.names) if n.startswith(("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToe",
                                                               "RightUpLeg", "RightLeg", "RightFoot", "RightToe"))]
    others = np.setdiff1d(np.arange(len(a.names)), legs)
    angles = rotation_angles_deg(local_rotations(a)[1 + k], local_rotations(b)[1 + k])
    assert angles[:, others].max() < 0.01 and same_pose(src, out, 1 + k, 1 + k)[1] < 1e-4
    report = json.loads((tmp_path / "o" / "run.metrics.json").read_text())["keyframes_on_source"]
    moved = np.linalg.norm(world(a)[1][1 + k] - world(b)[1][1 + k], axis=-1) * 1000.0  # [mm] every joint
    assert moved.max() <= report["max_mm"] + 0.01
    # between the keyframes the path differs from the capture (it is not a copy)
    between = np.setdiff1d(np.arange(1, k[-1]), k)
    assert same_pose(src, out, 1 + between, 1 + between)[0] > 0.01
