"""BVH import and retargeting (runner/capture/), checked against physical expectations and
hand-computed rotations, plus every malformed-input error."""
import dataclasses
import json
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.interpolate import make_interp_spline

from runner.capture.capture_keys import keyframe_indices, keyframes_from_reference
from runner.capture.reference_motion import load_bvh_reference
from runner.capture.root_height import worst_contact_distance
from runner.commands.keyframes_from_bvh import keyframes_from_bvh_main
from solver.errors import InputError
from solver.keyframe_file import read_keyframes
from solver.layout import StateLayout

REPO = Path(__file__).resolve().parents[3]
MODELS = REPO / "models"
CLIP = MODELS / "cmu" / "127_33.bvh"
SITES = ["l_heel", "l_toe", "r_heel", "r_toe"]
ARMS = ["torso", "l_shoulder", "l_elbow", "r_shoulder", "r_elbow"]


@pytest.fixture(scope="module")
def scene():
    return mujoco.MjModel.from_xml_path(str(MODELS / "run_and_step.xml"))


@pytest.fixture(scope="module")
def layout(scene):
    return StateLayout.from_model(scene)


@pytest.fixture(scope="module")
def reference(scene):
    # as the shipped keyframe file was made (it records no root_scale and no skeleton): the root path as
    # captured, the figure's bodies on the CMU skeleton's rest pose
    return load_bvh_reference(CLIP, scene, root_scale=1.0, rest_pose=True)


# ---- independent helpers: forward kinematics and the box straight from MuJoCo --------------------


def site_positions(model, qpos):
    d = mujoco.MjData(model)
    out = np.empty((len(qpos), 4, 3))
    for i, q in enumerate(qpos):
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        out[i] = [d.site(s).xpos for s in SITES]
    return out


def clearance(model, pos):
    """Height above the floor, or above the box top where the point is over the box."""
    box = model.geom("step").id
    c, h = model.geom_pos[box], model.geom_size[box]
    over = (np.abs(pos[..., 0] - c[0]) <= h[0]) & (np.abs(pos[..., 1] - c[1]) <= h[1])
    return pos[..., 2] - np.where(over, c[2] + h[2], 0.0)


def flexion(q, axis):
    q = q * np.sign(q[..., :1] + 1e-300)
    return 2 * np.arctan2(q[..., 1:] @ np.asarray(axis, float), q[..., 0])


# ---- the real clip ---------------------------------------------------------------------------------


def test_reference_shape_and_time(reference, scene):
    assert reference.qpos.shape == (205, scene.nq)  # 206 frames minus the T-pose
    assert reference.frame_time == pytest.approx(1 / 120, rel=1e-4)
    assert reference.times[0] == 0.0 and reference.times[-1] == pytest.approx(204 / 120, rel=1e-4)
    assert reference.source == str(CLIP)


def test_a_capture_read_once_is_its_file(reference, scene):
    """The run's Capture (read once) holds the file's own text and gives the reference its file gives; the
    reference carries it, so later steps read nothing again."""
    from runner.capture.clip import as_capture, read_capture

    capture = read_capture(CLIP)
    assert capture.text == CLIP.read_text(encoding="utf-8") and capture.source == str(CLIP)
    assert as_capture(capture) is capture
    again = load_bvh_reference(capture, scene, root_scale=1.0, rest_pose=True)
    assert again.capture is capture and again.source == reference.source
    assert np.array_equal(again.qpos, reference.qpos) and np.array_equal(again.times, reference.times)


def test_one_retarget_serves_every_scene_of_the_figure(reference, scene):
    """The clip retargeted once onto the figure alone (as a fitted scene first reads it) gives, in a scene
    holding that figure, exactly the reference retargeted anew there; the retarget is read-only."""
    from runner.capture.clip import read_capture
    from runner.capture.reference_motion import retarget_capture
    from solver.figure import FIGURE_FILE

    capture = read_capture(CLIP)
    onto = retarget_capture(capture, mujoco.MjModel.from_xml_path(str(FIGURE_FILE)), root_scale=1.0, rest_pose=True)
    assert onto.qpos.shape == reference.qpos.shape and not onto.qpos.flags.writeable
    again = load_bvh_reference(capture, scene, root_scale=1.0, rest_pose=True, retargeted=onto)
    assert np.array_equal(again.qpos, reference.qpos)
    assert again.skeleton.skeleton_map().text() == reference.skeleton.skeleton_map().text()


def test_quaternions_unit_and_hemisphere_consistent(reference, layout):
    for slot in layout.quat_slots:
        q = reference.qpos[:, slot]
        assert np.linalg.norm(q, axis=1) == pytest.approx(1.0, abs=1e-9)
        assert (np.sum(q[1:] * q[:-1], axis=1) > 0).all()


def test_root_path_is_a_run_over_a_box(reference):
    x, y, z = reference.qpos[:, :3].T
    speed = (x[-1] - x[0]) / reference.duration
    assert speed == pytest.approx(3.0, abs=0.3)  # cmu README: about 5.1 m at about 3 m/s
    assert abs(y[-1] - y[0]) < 0.5  # straight along +x
    # the CMU hips start at 0.90 m; our figure's legs are ~5 cm shorter than the subject's (1.00 m
    # root-to-sole vs about 1.05), and the subject's stance foot sits a few cm high in the data.
    assert 0.82 < z[0] < 1.0
    start = z[reference.times < 0.25].mean()
    on_box = z[(x > -0.2) & (x < 0.8)].mean()  # the runner is over the box (x in -0.45 .. 1.15)
    assert 0.2 < on_box - start < 0.35  # box top 0.23 m


def test_feet_on_surfaces_in_contact(reference, scene):
    """The lowest site of a foot that stands still (< 0.5 m/s) is within 3 cm of the surface under it."""
    pos = site_positions(scene, reference.qpos)
    clear = clearance(scene, pos)
    speed = np.linalg.norm(np.gradient(pos, reference.frame_time, axis=0), axis=-1)
    n_contact = 0
    for foot in (slice(0, 2), slice(2, 4)):
        k = np.argmin(clear[:, foot], axis=1)
        rows = np.arange(len(k))
        low = clear[:, foot][rows, k]
        still = speed[:, foot][rows, k] < 0.5
        n_contact += still.sum()
        assert np.abs(low[still]).max() < 0.03
    assert n_contact > 0.4 * len(pos)  # running: each foot is down about a third of the time
    assert clear.min() >= 0.0  # no heel or toe ever under the floor or inside the box
    assert worst_contact_distance(reference, scene) <= 0.03


def test_no_hyperextension(reference, layout):
    for name, axis in [("l_knee", [0, 1, 0]), ("r_knee", [0, 1, 0]), ("l_elbow", [0, -1, 0]), ("r_elbow", [0, -1, 0])]:
        th = flexion(reference.qpos[:, layout.joint(name).qpos_slice], axis)
        assert th.min() >= -1e-9, name
    # a run: knees flex well past 60 degrees in the swing, elbows are bent
    knee = flexion(reference.qpos[:, layout.joint("l_knee").qpos_slice], [0, 1, 0])
    assert np.degrees(knee.max()) > 60
    elbow = flexion(reference.qpos[:, layout.joint("r_elbow").qpos_slice], [0, -1, 0])
    assert 45 < np.degrees(np.median(elbow)) < 135


def test_keyframes_from_reference(reference, scene, layout):
    kf = keyframes_from_reference(reference, scene, partial="middle",
                                  indices=keyframe_indices(reference, 0.25, extremes=False))
    assert kf.times[0] == 0.0 and kf.times[-1] == reference.times[-1]
    gaps = np.diff(kf.times)
    assert gaps.min() >= 0.2 and gaps.max() <= 0.3
    assert kf.is_partial.sum() == 1
    i = int(np.flatnonzero(kf.is_partial)[0])
    for name in ("root", "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle"):  # the legs
        assert kf.mask[i, layout.joint(name).qpos_slice].all(), name
    for name in ARMS:
        assert not kf.mask[i, layout.joint(name).qpos_slice].any(), name
    # hard constraints that can be met: no site under a surface, no hyperextension
    vals = kf.initial_values(layout.quat_slots)
    assert clearance(scene, site_positions(scene, vals)).min() >= 0.0
    for name, axis in [("l_knee", [0, 1, 0]), ("r_knee", [0, 1, 0]), ("l_elbow", [0, -1, 0]), ("r_elbow", [0, -1, 0])]:
        full = kf.mask[:, layout.joint(name).qpos_slice].all(axis=1)
        assert flexion(kf.values[full][:, layout.joint(name).qpos_slice], axis).min() >= -1e-9


def test_even_keys_keep_the_root_extremes(reference):
    """Issue 15: evenly spaced keys cut a jump's apex off the plain spline; the extremes are keys."""
    idx = keyframe_indices(reference, 0.25)
    z = reference.qpos[:, 2]
    assert int(np.argmax(z)) in idx
    assert int(np.argmin(z)) in idx or min(int(np.argmin(z)), reference.count - 1 - int(np.argmin(z))) < 4
    assert idx[0] == 0 and idx[-1] == reference.count - 1
    assert len(idx) == len(keyframe_indices(reference, 0.25, extremes=False))  # moved, not added
    even = keyframe_indices(reference, 0.25, extremes=False)
    assert int(np.argmax(z)) not in even  # the test means something on this clip


def test_keyframe_choices(reference, scene, layout):
    kf = keyframes_from_reference(reference, scene, every=0.2, partial={0: ["root"], 2: ["l_hip", "r_hip"]})
    assert kf.is_partial.tolist()[:3] == [True, False, True]
    assert kf.mask[0].sum() == 7 and kf.mask[2].sum() == 8
    assert not keyframes_from_reference(reference, scene, partial={}).is_partial.any()
    assert not keyframes_from_reference(reference, scene).is_partial.any()  # full keyframes by default
    with pytest.raises(InputError, match=r"partial keyframe index 99 is out of range; there are 8 keyframes"):
        keyframes_from_reference(reference, scene, partial={99: ["root"]})
    with pytest.raises(InputError, match=r"unknown joint 'l_foot'.*l_ankle"):
        keyframes_from_reference(reference, scene, partial={1: ["l_foot"]})
    for bad in (0, -0.1, math.nan, "0.25"):
        with pytest.raises(InputError, match="keyframe spacing"):
            keyframes_from_reference(reference, scene, every=bad)


def test_shipped_keyframes_match_the_clip_and_show_the_problem(reference, scene, layout):
    """The shipped file is what the importer makes, its keyframes are clean, and the plain natural
    cubic spline through them sinks a contact site several cm into the floor or the box."""
    kf, info = read_keyframes(MODELS / "run_and_step.keyframes.json", layout)
    assert info.scene == (MODELS / "run_and_step.xml").resolve()
    assert info.model == (MODELS / "humanoid39.xml").resolve()
    assert info.source["clip"] == "cmu/127_33.bvh" and "--out models/run_and_step.keyframes.json" in info.source["command"]
    # made before --partial and the root extremes: the command of models/README.md with
    # --partial --no-root-extremes; and before the footplant: keyed from the capture itself
    unplanted = dataclasses.replace(reference, plant=None)
    fresh = keyframes_from_reference(unplanted, scene, partial="middle",
                                     indices=keyframe_indices(unplanted, 0.25, extremes=False))
    assert np.array_equal(kf.mask, fresh.mask)
    assert kf.times == pytest.approx(fresh.times, abs=1e-6)
    # and before the root-height correction put only resting feet on the floor (docs/mocap.md, "The
    # reference"): the root height (column 2) moved by up to 3 mm at some keyframes, nothing else
    others = np.arange(kf.values.shape[1]) != 2
    assert np.nan_to_num(kf.values[:, others]) == pytest.approx(np.nan_to_num(fresh.values[:, others]), abs=2e-6)
    assert kf.values[:, 2] == pytest.approx(fresh.values[:, 2], abs=0.003)
    vals = kf.initial_values(layout.quat_slots)
    assert clearance(scene, site_positions(scene, vals)).min() > 0.0
    t = np.arange(kf.times[0], kf.times[-1], 1e-3)
    Y = make_interp_spline(kf.times, vals, k=3, bc_type="natural")(t)
    for slot in layout.quat_slots:
        Y[:, slot] /= np.linalg.norm(Y[:, slot], axis=1, keepdims=True)
    depth = -clearance(scene, site_positions(scene, Y)).min()
    assert depth > 0.04


def test_main_writes_a_keyframe_file(tmp_path, layout, capsys):
    out = tmp_path / "k.json"
    rc = keyframes_from_bvh_main([str(CLIP), "--out", str(out), "--every", "0.3", "--figure", "default",
                                  "--scene", str(MODELS / "run_and_step.xml")], prog="dynsplines keyframes-from-bvh")
    assert rc == 0
    kf, info = read_keyframes(out, layout)
    assert kf.count == 7 and info.scene == (MODELS / "run_and_step.xml").resolve()
    assert info.source["command"].startswith("dynsplines keyframes-from-bvh ")
    assert "7 keyframes" in capsys.readouterr().out
    # the subject's figure (the default) in a given scene: a copy of the scene beside the file includes it
    rc = keyframes_from_bvh_main([str(CLIP), "--out", str(out), "--every", "0.3",
                                  "--scene", str(MODELS / "run_and_step.xml")], prog="dynsplines keyframes-from-bvh")
    assert rc == 0
    kf, info = read_keyframes(out, layout)
    assert info.scene == (tmp_path / "k.scene.xml").resolve() and info.model == (tmp_path / "k.figure.xml").resolve()
    assert '"k.figure.xml"' in info.scene.read_text() and "step" in info.scene.read_text()
    capsys.readouterr()
    rc = keyframes_from_bvh_main([str(tmp_path / "nope.bvh"), "--out", str(out)])
    assert rc == 2
    assert "nope.bvh" in capsys.readouterr().err


# ---- a tiny hand-written clip with known rotations ---------------------------------------------------
# (its trunk joint is named LowerBack, a name only the CMU skeleton uses: the clip is read as CMU's, in
# CMU's length unit and with a synthetic T-pose first frame)

TINY_HIERARCHY = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT LeftUpLeg
  {
    OFFSET 1.5 -1.5 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    JOINT LeftLeg
    {
      OFFSET 0 -7.5 0
      CHANNELS 3 Zrotation Yrotation Xrotation
      JOINT LeftFoot
      {
        OFFSET 0 -7.5 0
        CHANNELS 3 Zrotation Yrotation Xrotation
        JOINT LeftToeBase
        {
          OFFSET 0 -0.8 2.3
          CHANNELS 3 Zrotation Yrotation Xrotation
          End Site
          {
            OFFSET 0 0 1
          }
        }
      }
    }
  }
  JOINT RightUpLeg
  {
    OFFSET -1.5 -1.5 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    JOINT RightLeg
    {
      OFFSET 0 -7.5 0
      CHANNELS 3 Zrotation Yrotation Xrotation
      JOINT RightFoot
      {
        OFFSET 0 -7.5 0
        CHANNELS 3 Zrotation Yrotation Xrotation
        JOINT RightToeBase
        {
          OFFSET 0 -0.8 2.3
          CHANNELS 3 Zrotation Yrotation Xrotation
          End Site
          {
            OFFSET 0 0 1
          }
        }
      }
    }
  }
  JOINT LowerBack
  {
    OFFSET 0 4 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    JOINT LeftArm
    {
      OFFSET 3 1.5 0
      CHANNELS 3 Zrotation Yrotation Xrotation
      JOINT LeftForeArm
      {
        OFFSET 5 0 0
        CHANNELS 3 Zrotation Yrotation Xrotation
        JOINT LeftHand
        {
          OFFSET 4.5 0 0
          CHANNELS 3 Zrotation Yrotation Xrotation
          End Site
          {
            OFFSET 1 0 0
          }
        }
      }
    }
    JOINT RightArm
    {
      OFFSET -3 1.5 0
      CHANNELS 3 Zrotation Yrotation Xrotation
      JOINT RightForeArm
      {
        OFFSET -5 0 0
        CHANNELS 3 Zrotation Yrotation Xrotation
        JOINT RightHand
        {
          OFFSET -4.5 0 0
          CHANNELS 3 Zrotation Yrotation Xrotation
          End Site
          {
            OFFSET -1 0 0
          }
        }
      }
    }
    JOINT Neck
    {
      OFFSET 0 2 0
      CHANNELS 3 Zrotation Yrotation Xrotation
      JOINT Head
      {
        OFFSET 0 1.5 0
        CHANNELS 3 Zrotation Yrotation Xrotation
        End Site
        {
          OFFSET 0 3 0
        }
      }
    }
  }
}
"""
# channel order: Hips (X Y Z position, Z Y X rotation), then Z Y X rotation of each joint in file order
TINY_JOINTS = ["LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RightUpLeg", "RightLeg", "RightFoot",
               "RightToeBase", "LowerBack", "LeftArm", "LeftForeArm", "LeftHand", "RightArm", "RightForeArm",
               "RightHand", "Neck", "Head"]


def tiny_frame(hips_pos=(1.0, 17.0, 10.0), hips_zyx=(0, 0, 0), **zyx):
    vals = list(hips_pos) + list(hips_zyx)
    for j in TINY_JOINTS:
        vals += list(zyx.get(j, (0, 0, 0)))
    return " ".join(f"{v:g}" for v in vals)


def tiny_bvh(frames):
    return TINY_HIERARCHY + f"MOTION\nFrames: {len(frames)}\nFrame Time: 0.1\n" + "\n".join(frames) + "\n"


def axis_angle(axis, deg):
    a = np.radians(deg) / 2
    return np.r_[np.cos(a), np.sin(a) * np.asarray(axis, float)]


def same_rotation(a, b, tol=1e-6):
    return abs(abs(float(np.dot(a, b))) - 1.0) < tol


def test_tiny_clip_known_rotations(tmp_path, scene, layout):
    frames = [
        tiny_frame(),  # the T-pose, dropped
        # knee flexed 30 deg (BVH +X rotation of the shin swings it back, toward -Z); body turned
        # 90 deg to its left (about BVH +Y, up)
        tiny_frame(hips_zyx=(0, 90, 0), LeftLeg=(0, 0, 30)),
        # left arm down from the T-pose (-90 about BVH Z, forward), elbow flexed 90 deg with the forearm
        # forward (-90 about the upper arm's BVH Y)
        tiny_frame(LeftArm=(-90, 0, 0), LeftForeArm=(0, -90, 0)),
    ]
    path = tmp_path / "tiny.bvh"
    path.write_text(tiny_bvh(frames))
    ref = load_bvh_reference(path, scene, root_scale=1.0)
    assert ref.qpos.shape == (2, 51) and ref.frame_time == 0.1
    q = lambda f, name: ref.qpos[f, layout.joint(name).qpos_slice]  # noqa: E731
    # frame 0: knee = 30 deg about +y (figure: shin back); root = 90 deg about +z (BVH up = MuJoCo z)
    assert same_rotation(q(0, "l_knee"), axis_angle([0, 1, 0], 30))
    assert same_rotation(q(0, "root")[3:], axis_angle([0, 0, 1], 90))
    assert same_rotation(q(0, "r_knee"), [1, 0, 0, 0])
    # root position: BVH (X, Y, Z) = (1, 17, 10) units -> MuJoCo (x, y) = (Z, X) * 0.05644 m
    assert ref.qpos[0, :2] == pytest.approx([10 * 0.05644, 1 * 0.05644], abs=1e-4)
    # frame 1: the arm hangs as in the figure's identity pose; the elbow is flexed 90 deg about -y
    assert same_rotation(q(1, "l_shoulder"), [1, 0, 0, 0])
    assert same_rotation(q(1, "l_elbow"), axis_angle([0, -1, 0], 90))
    # the right arm is still out sideways in the T-pose: 90 deg about -x from hanging (toward -y)
    assert same_rotation(q(1, "r_shoulder"), axis_angle([-1, 0, 0], 90))
    # legs straight and vertical in this skeleton: hips and knees at identity
    assert same_rotation(q(1, "l_hip"), [1, 0, 0, 0]) and same_rotation(q(1, "l_knee"), [1, 0, 0, 0])



def test_the_root_path_is_scaled_by_the_leg_lengths(tmp_path, scene, layout):
    """By default the root path is scaled by the figure's leg length over the subject's: the tiny
    skeleton's legs are 7.5 + 7.5 units (0.8466 m), the figure's 0.42 + 0.42 m (humanoid39.xml's shin
    and foot body offsets); the joint angles are unchanged."""
    path = tmp_path / "tiny.bvh"
    path.write_text(tiny_bvh([tiny_frame(), tiny_frame(), tiny_frame(hips_pos=(3.0, 16.0, 20.0))]))
    raw = load_bvh_reference(path, scene, root_scale=1.0)
    legs = load_bvh_reference(path, scene)
    ratio = 0.84 / (15 * 0.0254 / 0.45)
    assert legs.root_scale == pytest.approx(ratio, rel=1e-12) and raw.root_scale == 1.0
    # horizontal root path scaled about the capture's origin (the height is then corrected, as ever)
    assert legs.qpos[:, :2] == pytest.approx(ratio * raw.qpos[:, :2], rel=1e-12)
    assert np.array_equal(legs.qpos[:, 3:], raw.qpos[:, 3:])
    half = load_bvh_reference(path, scene, root_scale=0.5)
    assert half.qpos[:, :2] == pytest.approx(0.5 * raw.qpos[:, :2], rel=1e-12)
    for bad in (0, -1.0, "tall", float("nan")):
        with pytest.raises(InputError, match="root scale"):
            load_bvh_reference(path, scene, root_scale=bad)


def test_a_taller_subject_gives_the_same_reference(tmp_path, scene):
    """Every bone and the root path of 127_33 scaled by 1.1 (another subject, the same motion): with
    the root path scaled by the legs the reference is the original's; as captured it strides 10%
    further on the figure's legs."""
    from bvh_edit import edit_bvh

    clip = CLIP
    tall = edit_bvh(clip, tmp_path / "tall.bvh", scale=1.1)
    a, b = load_bvh_reference(clip, scene), load_bvh_reference(tall, scene)
    # (the edited file's numbers are rounded to 6 significant digits)
    assert b.root_scale == pytest.approx(a.root_scale / 1.1, rel=1e-6)
    assert np.abs(b.qpos - a.qpos).max() < 1e-5
    raw = load_bvh_reference(tall, scene, root_scale=1.0)
    stride = lambda r: np.linalg.norm(r.qpos[-1, :2] - r.qpos[0, :2])  # noqa: E731
    assert stride(raw) / stride(a) == pytest.approx(1.1 / a.root_scale, rel=1e-6)

def test_tiny_clip_hyperextension_is_clamped(tmp_path, scene, layout):
    frames = [tiny_frame(), tiny_frame(LeftLeg=(0, 0, -20), RightForeArm=(0, -30, 0)), tiny_frame()]
    path = tmp_path / "hyper.bvh"
    path.write_text(tiny_bvh(frames))
    ref = load_bvh_reference(path, scene)
    knee = ref.qpos[0, layout.joint("l_knee").qpos_slice]
    assert flexion(knee, [0, 1, 0]) == pytest.approx(0.0, abs=1e-9)  # was -20 deg
    # right forearm rotated -30 about BVH Y from the T-pose: backward, i.e. hyperextended
    elbow = ref.qpos[0, layout.joint("r_elbow").qpos_slice]
    assert flexion(elbow, [0, -1, 0]) == pytest.approx(0.0, abs=1e-9)


# ---- malformed input ---------------------------------------------------------------------------------


def write(tmp_path, text, name="bad.bvh"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_missing_file(tmp_path, scene):
    with pytest.raises(InputError, match=r"missing\.bvh: cannot read the BVH clip: no such file"):
        load_bvh_reference(tmp_path / "missing.bvh", scene)
    with pytest.raises(InputError, match="it is a folder"):
        load_bvh_reference(tmp_path, scene)


def test_a_clip_too_short_or_never_resting_is_named_with_the_fix(tmp_path):
    """A capture of fewer frames than its 6 Hz filter takes, or whose feet never rest (nothing to fit a scene to),
    is refused with the file, what is missing and the fix, before any retargeting or solve."""
    from runner.capture.scene import clip_scene
    from solver.figure import FIGURE_FILE
    from solver.peak_bounds import MIN_FRAMES

    # MIN_FRAMES frames in the file, the first CMU's rest frame (the tiny clip has CMU's names): one short
    short = write(tmp_path, tiny_bvh([tiny_frame()] * MIN_FRAMES), "short.bvh")
    for scene in ("auto", "floor"):
        with pytest.raises(InputError, match=rf"short\.bvh: {MIN_FRAMES - 1} frames of capture; it needs at least {MIN_FRAMES}.*give a longer clip"):
            clip_scene(short, scene, FIGURE_FILE, tmp_path / "s.scene.xml")
    # every frame 0.56 m further along (5.6 m/s, a run a body can make): no foot is ever still, so none rests
    flying = [tiny_frame(hips_pos=(10.0 * i, 17.0, 10.0)) for i in range(2 * MIN_FRAMES)]
    moving = write(tmp_path, tiny_bvh(flying), "moving.bvh")
    with pytest.raises(InputError, match=r"moving\.bvh: no foot rests in the clip.*--scene floor"):
        clip_scene(moving, "auto", FIGURE_FILE, tmp_path / "m.scene.xml")


def test_not_a_bvh(tmp_path, scene):
    p = write(tmp_path, "hello world\n")
    with pytest.raises(InputError, match=r"bad\.bvh: line 1: expected 'HIERARCHY', found 'hello world'"):
        load_bvh_reference(p, scene)
    p = write(tmp_path, "")
    with pytest.raises(InputError, match="the file is empty"):
        load_bvh_reference(p, scene)
    p = tmp_path / "bin.bvh"
    p.write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(InputError, match="not a text file"):
        load_bvh_reference(p, scene)


def test_wrong_value_count(tmp_path, scene):
    frames = [tiny_frame(), tiny_frame(), tiny_frame() + " 7"]
    p = write(tmp_path, tiny_bvh(frames))
    line = TINY_HIERARCHY.count("\n") + 3 + 3  # hierarchy, MOTION/Frames/Frame Time, third frame
    with pytest.raises(InputError, match=rf"line {line}: frame 3 has 58 values but the HIERARCHY declares 57 channels"):
        load_bvh_reference(p, scene)


def test_frame_lines_past_the_count_are_not_read(tmp_path):
    """An exporter's count one short (Assimp's Boxing_Toes.bvh: 3070 frame lines, "Frames: 3069") is read as bvhio
    reads it: the declared frames, the numbers of the lines past them left out of the clip as of its raw numbers."""
    from runner.capture.bvh import read_bvh

    frames = [tiny_frame(hips_pos=(1.0, 17.0, 10.0 + i)) for i in range(4)]
    clip = read_bvh(write(tmp_path, tiny_bvh(frames).replace("Frames: 4", "Frames: 3")))
    assert clip.local_quat.shape[0] == 3 and clip.raw.shape[0] == 3
    np.testing.assert_allclose(clip.raw[:, 2], [10.0, 11.0, 12.0], rtol=0, atol=1e-12)


def test_truncated_file_does_not_hang(tmp_path, scene):
    """bvhio 1.5.4 loops forever at end of file; the importer must catch a short MOTION section first."""
    text = tiny_bvh([tiny_frame(), tiny_frame(), tiny_frame()]).replace("Frames: 3", "Frames: 5")
    p = write(tmp_path, text)
    with pytest.raises(InputError, match=r"has 3 frame lines but line \d+ says Frames: 5"):
        load_bvh_reference(p, scene)
    p = write(tmp_path, TINY_HIERARCHY[:400])
    with pytest.raises(InputError, match=r"the file ends inside the HIERARCHY \(truncated\?\)"):
        load_bvh_reference(p, scene)
    p = write(tmp_path, TINY_HIERARCHY)
    with pytest.raises(InputError, match="no MOTION line after the HIERARCHY"):
        load_bvh_reference(p, scene)


def test_bad_numbers_and_headers(tmp_path, scene):
    p = write(tmp_path, tiny_bvh([tiny_frame(), tiny_frame().replace("17", "abc", 1)]))
    with pytest.raises(InputError, match=r"frame 2 has the non-number 'abc'"):
        load_bvh_reference(p, scene)
    p = write(tmp_path, tiny_bvh([tiny_frame(), tiny_frame().replace("17", "-inf", 1)]))
    with pytest.raises(InputError, match=r"frame 2 has the value '-inf'; give a finite number, or nan where"):
        load_bvh_reference(p, scene)
    p = write(tmp_path, tiny_bvh([tiny_frame(), tiny_frame()]).replace("Frame Time: 0.1", "Frame Time: fast"))
    with pytest.raises(InputError, match=r"Frame Time 'fast' is not a positive number of seconds"):
        load_bvh_reference(p, scene)
    p = write(tmp_path, tiny_bvh([tiny_frame()]))
    with pytest.raises(InputError, match=r"Frames: 1; need at least 2 frames"):
        load_bvh_reference(p, scene)
    p = write(tmp_path, tiny_bvh([tiny_frame(), tiny_frame()]))  # the first is the T-pose: one frame of motion
    with pytest.raises(InputError, match=r"has 1 frame of motion after its 1 rest frame .* a motion needs at least 2"):
        load_bvh_reference(p, scene)


def test_a_byte_order_mark_is_not_part_of_the_file(tmp_path):
    """A file written with a UTF-8 byte-order mark first (.NET's UTF-8 writers do) reads as the same file without
    it (bvhio alone refuses it: "First line must be only HIERARCHY"), and the text kept for the export has none."""
    from runner.capture.bvh import read_bvh
    from runner.capture.clip import read_capture

    text = tiny_bvh([tiny_frame()] + [tiny_frame(LeftLeg=(0, 0, a)) for a in (0, 20, 40)])
    plain, marked = tmp_path / "plain.bvh", tmp_path / "marked.bvh"
    plain.write_text(text, encoding="utf-8")
    marked.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    a, b = read_bvh(plain), read_bvh(marked)
    assert a.names == b.names and np.array_equal(a.local_quat, b.local_quat) and np.array_equal(a.local_pos, b.local_pos)
    assert read_capture(marked).text == text


def test_bad_channels(tmp_path, scene):
    text = tiny_bvh([tiny_frame(), tiny_frame()])
    p = write(tmp_path, text.replace("CHANNELS 3 Zrotation Yrotation Xrotation", "CHANNELS 3 Zrotation Yrotation", 1))
    with pytest.raises(InputError, match=r"line 9: CHANNELS says 3 channels but lists 2 \(Zrotation Yrotation\)"):
        load_bvh_reference(p, scene)
    p = write(tmp_path, text.replace("Xrotation\n", "Wrotation\n", 1))
    with pytest.raises(InputError, match=r"unknown channel 'Wrotation'"):
        load_bvh_reference(p, scene)


def test_malformed_hierarchy(tmp_path, scene):
    text = tiny_bvh([tiny_frame(), tiny_frame()])
    p = write(tmp_path, text.replace("    OFFSET 0 -7.5 0\n", "", 1))  # LeftLeg loses its OFFSET line
    with pytest.raises(InputError, match=r"line 12: expected .OFFSET x y z., found .CHANNELS 3 Zrotation Yrotation Xrotation.; fix the HIERARCHY"):
        load_bvh_reference(p, scene)
    p = write(tmp_path, text.replace("  JOINT RightUpLeg\n  {\n", "  JOINT RightUpLeg\n", 1))
    with pytest.raises(InputError, match=r"line 31: expected '\{' opening the joint, found 'OFFSET -1.5 -1.5 0'"):
        load_bvh_reference(p, scene)


def test_a_skeleton_without_a_head_names_the_roles(tmp_path, scene):
    """The chest is where the arms and the neck branch off: without a head there is no such joint, and the
    one-line error names the roles not found and the skeleton map that would name them."""
    lines = tiny_bvh([tiny_frame(), tiny_frame()]).splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.strip() == "JOINT Neck")
    lines = lines[:at] + lines[at + 14:]  # the Neck and Head block
    frame = " ".join(tiny_frame().split()[:-6])
    text = "\n".join(lines[:lines.index("MOTION") + 3] + [frame, frame]) + "\n"
    p = write(tmp_path, text)
    with pytest.raises(InputError, match=r"bad\.bvh: cannot recognise the skeleton's chest, head, l_upper_arm.*"
                                         r"skeleton map.*--skeleton-map FILE") as e:
        load_bvh_reference(p, scene)
    assert "\n" not in str(e.value)


def test_root_without_position_channels(tmp_path, scene):
    """A root with rotation channels only stands at its OFFSET, as BVH (bvhio, Blender) reads it (three.js's
    pirouette.bvh): the same reference as the file whose root's position channels hold that OFFSET."""
    frames = [tiny_frame(LeftUpLeg=(0, 0, 5.0 * i), RightLeg=(0, 0, -8.0 * i)) for i in range(6)]
    text = tiny_bvh([" ".join(f.split()[3:]) for f in frames]).replace(
        "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation", "CHANNELS 3 Zrotation Yrotation Xrotation")
    rooted = load_bvh_reference(write(tmp_path, text.replace("  OFFSET 0 0 0", "  OFFSET 1 17 10", 1)), scene)
    positioned = load_bvh_reference(write(tmp_path, tiny_bvh(frames), "positioned.bvh"), scene)
    np.testing.assert_allclose(rooted.qpos, positioned.qpos, rtol=0, atol=1e-9)


# ---- clips of other captures: other Euler orders, frame rates, bone lengths; another skeleton ----------


def test_other_channel_order_frame_rate_and_bone_lengths_give_the_same_motion(tmp_path, scene, layout):
    """The channel order is read per joint from the file (not assumed Z Y X), the frame rate from
    'Frame Time', and the figure keeps its own bone lengths whatever the subject's."""
    from bvh_edit import edit_bvh

    short = edit_bvh(CLIP, tmp_path / "short.bvh", seconds=0.5)
    base = load_bvh_reference(short, scene)
    for order in ("XYZ", "YXZ"):
        other = load_bvh_reference(edit_bvh(CLIP, tmp_path / f"{order}.bvh", seconds=0.5, order=order), scene)
        assert other.qpos == pytest.approx(base.qpos, abs=2e-5), order
    half = load_bvh_reference(edit_bvh(CLIP, tmp_path / "60fps.bvh", seconds=0.5, stride=2), scene)
    assert half.frame_time == pytest.approx(2 / 120, rel=1e-4)
    assert half.count == (base.count + 1) // 2 and half.times[-1] == pytest.approx(base.times[-1], abs=0.01)
    # the same poses at every other frame (the root height correction smooths over 9 frames of each)
    for slot in layout.quat_slots[1:]:
        d = np.abs(np.sum(half.qpos[:, slot] * base.qpos[::2][: half.count, slot], axis=1))
        assert d.min() > 0.9999
    big = load_bvh_reference(edit_bvh(CLIP, tmp_path / "big.bvh", seconds=0.5, scale=1.2), scene)
    for slot in layout.quat_slots[1:]:  # joint angles do not depend on the subject's bone lengths
        d = np.abs(np.sum(big.qpos[:, slot] * base.qpos[:, slot], axis=1))
        assert d.min() > 1 - 1e-9


def test_joints_of_other_names_are_recognised_by_the_hierarchy(tmp_path, scene):
    """Joints renamed to names of no family (LThigh, RUpperArm, Torso7) play the same roles: the
    hierarchy and the bone lengths say which joint is which, the L/R prefixes the side; the reference is
    the original's."""
    from bvh_edit import edit_bvh

    base = load_bvh_reference(edit_bvh(CLIP, tmp_path / "base.bvh", seconds=0.2), scene)
    clip = edit_bvh(CLIP, tmp_path / "other.bvh", seconds=0.2,
                    rename={"LeftUpLeg": "LThigh", "RightArm": "RUpperArm", "Spine1": "Torso7"})
    other = load_bvh_reference(clip, scene)
    assert np.abs(other.qpos - base.qpos).max() < 1e-9
    assert other.skeleton.roles["l_upper_leg"] == "LThigh" and other.skeleton.roles["chest"] == "Torso7"


def test_default_scene_is_fitted_to_the_clip_not_the_step(tmp_path, capsys):
    """Issue 15: without --scene a flat walk was retargeted onto models/run_and_step.xml (and lifted onto
    its box). Now the scene is fitted to the clip and written next to --out."""
    from bvh_edit import edit_bvh

    src = REPO / "models" / "cmu" / "16_23.bvh"  # shipped with its attribution (models/cmu/README.md)
    walk = edit_bvh(src, tmp_path / "walk.bvh", seconds=0.8)
    out = tmp_path / "walk.keyframes.json"
    assert keyframes_from_bvh_main([str(walk), "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["scene"] == "walk.scene.xml"
    fitted = mujoco.MjModel.from_xml_path(str(tmp_path / "walk.scene.xml"))  # loads from where it is saved
    assert "step" not in {fitted.geom(i).name for i in range(fitted.ngeom)}
    assert doc["contacts"] and {c["surface"] for c in doc["contacts"]} == {"floor"}
    kf, info = read_keyframes(out, StateLayout.from_model(fitted))
    assert info.contacts and not kf.is_partial.any()
    assert kf.values[:, 2].max() < 1.2  # the walker is not lifted onto a box


def test_a_small_hop_keeps_its_height(tmp_path, scene):
    """The clip with the figure lifted 15 cm over 0.35 s around the right foot's stance (`edit_bvh`
    hop): the root-height correction must not put the lifted foot back on the floor where it slows at
    the top of the hop (it did: 6-7 cm of the 15 were left, and the foot was "in contact" at 5 cm),
    and the frames away from the hop keep the correction of the unedited clip. Not the full 15 cm:
    in the unedited clip the right foot's stance gets its own correction, ~3 cm off the one
    interpolated across the hop from the left foot's stances (the retargeting's height error differs
    between the feet), so 12 cm is what a correct hop keeps here. Both clips are retargeted with the
    rest pose's body frames, so that they are retargeted alike frame by frame: frames measured on each
    clip depend on where its feet are still and low, which the hop changes."""
    from bvh_edit import edit_bvh

    from runner.capture.stance import capture_rest

    start, duration, height = 0.25, 0.35, 0.15
    base = load_bvh_reference(CLIP, scene, root_scale=1.0, rest_pose=True)
    hop = load_bvh_reference(edit_bvh(CLIP, tmp_path / "hop.bvh", hop=(start, duration, height)), scene,
                             root_scale=1.0, rest_pose=True)
    t = hop.times
    s = np.clip((t - start) / duration, 0.0, 1.0)
    lift = hop.qpos[:, 2] - base.qpos[:, 2]
    top = np.argmin(np.abs(s - 0.5))
    assert lift[top] >= 0.75 * height, lift[top]
    away = (t < start - 0.1) | (t > start + duration + 0.1)
    assert np.abs(lift[away]).max() <= 0.005
    rest, _ = capture_rest(scene, hop.qpos, hop.frame_time)
    assert not rest[np.abs(s - 0.5) < 0.2].any()  # a flight at the top of the hop


def test_names_with_spaces_and_named_end_sites(tmp_path, scene):
    """3ds Max Biped names hold spaces ("Bip01 L Thigh") and MotionBuilder names its End Sites ("End Site
    LeftToe_end"), an exporter of ASF/AMC names numbers them ("End Site5"): the name is the rest of the JOINT line
    (bvhio keeps its first word, which made two joints "Bip01"), an End Site's name or number names nothing; the
    motion is the file's with the plain names."""
    from runner.capture.bvh import read_bvh

    frames = [tiny_frame(hips_pos=(1.0, 17.0, 10.0 + i), LeftUpLeg=(5.0 * i, 10, 0), LeftLeg=(0, 0, -20.0 * i))
              for i in range(3)]
    plain = read_bvh(write(tmp_path, tiny_bvh(frames), "plain.bvh"))
    text = tiny_bvh(frames).replace("JOINT LeftUpLeg", "JOINT Bip01 L Thigh").replace("JOINT LeftLeg", "JOINT Bip01  L Calf")
    text = text.replace("End Site", "End Site LeftToe_end", 1)
    assert text.count("End Site") >= 2
    text = text[::-1].replace("End Site"[::-1], "End Site5"[::-1], 1)[::-1]  # the last End Site numbered
    clip = read_bvh(write(tmp_path, text, "biped.bvh"))
    np.testing.assert_allclose(np.array(sorted(map(tuple, clip.end_sites.values()))),
                               np.array(sorted(map(tuple, plain.end_sites.values()))), rtol=0, atol=1e-12)
    assert clip.names == tuple("Bip01 L Thigh" if n == "LeftUpLeg" else "Bip01 L Calf" if n == "LeftLeg" else n
                               for n in plain.names)
    np.testing.assert_allclose(clip.local_quat, plain.local_quat, rtol=0, atol=1e-12)
    np.testing.assert_allclose(clip.offsets, plain.offsets, rtol=0, atol=1e-12)
