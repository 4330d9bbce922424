"""Clips of other skeleton conventions go in without user action and come back out onto their own skeleton.

The conventions are the shipped CMU clip 35_17 re-exported by tests/bvh_conventions.py (LAFAN1-, Bandai
Namco-, Vicon-, Rokoko/Mixamo-, 3ds Max- and Unreal-style; the known answer is the CMU clip's own forward
kinematics, tests/bvh_fk.py), and real clips of other captures in tests/data/bvh/ (their sources and
licence in tests/data/bvh/README.md). Checked: the roles, unit, up axis and rest frames recognised; the
same subject's figure, reference and contacts as the CMU clip gives; and `dynsplines export --to
FILE.bvh` writing the source skeleton whose joints are, at the keyframe times, within 0.1 mm of the
source's where the keyframe is the capture, and within 5 mm where the footplant moved a resting foot
(the independent forward kinematics of both files).
"""
from pathlib import Path

import numpy as np
import pytest
from bvh_conventions import CONVENTIONS, convention, read, resample, scale, write
from bvh_edit import edit_bvh
from bvh_fk import AXES, parse, world

from runner.capture.bvh import read_bvh
from runner.capture.skeleton import recognise
from runner.cli import main
from runner.saved_path import load_saved_path

REPO = Path(__file__).resolve().parents[3]
CLIP = REPO / "models" / "cmu" / "35_17.bvh"
REAL = REPO / "tests" / "data" / "bvh"
#: [m] a joint of the way back this near the source's at a keyframe is the source's (the acceptance)
KEY_TOLERANCE = 1e-4
#: [m] how far a key the footplant moved may be: these clips' feet rest within a few mm of their surfaces
PLANTED_TOLERANCE = 0.005
FAST = ["--no-render", "--max-evals", "5", "--quiet", "--no-summary"]
#: the roles of the legs: a convention that merges spine joints keeps these joints' places exactly
LEG_JOINTS = ("Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RightUpLeg", "RightLeg", "RightFoot",
              "RightToeBase")


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    """The first second of 35_17 (its T-pose frame kept), as the conventions start from."""
    return edit_bvh(CLIP, tmp_path_factory.mktemp("cmu") / "run.bvh", seconds=1.0)


@pytest.fixture(scope="module")
def conventions(source, tmp_path_factory):
    folder = tmp_path_factory.mktemp("conventions")
    return {name: convention(source, name, folder / f"{name}.bvh") for name in CONVENTIONS}


def axes_of(notes):
    """(3, 3) the re-export's axes to MuJoCo's, as CMU's map to them (so positions compare directly)."""
    return AXES @ notes.get("to_cmu", np.eye(3))


@pytest.mark.parametrize("name", sorted(CONVENTIONS))
def test_the_re_exports_are_the_clips_motion(source, conventions, name, tmp_path):
    """The test data: each re-export's joints are where the CMU clip's are (scaled by the performer's
    size; a convention that merges spine joints, only below them; another frame rate: the CMU clip
    resampled alike), by forward kinematics of both files."""
    path, clip, notes = conventions[name]
    b, b0 = parse(path), parse(twin(source, name, notes, tmp_path) if notes.get("resampled") else source)
    _, pw = world(b, notes["unit"], axes_of(notes))
    _, cmu = world(b0)
    first = len(b0.values) - len(b.values)  # the CMU frame of the file's first (its T-pose frame dropped or not)
    kept = [(new, old) for new, old in clip.answer.items() if not notes.get("merged") or old in LEG_JOINTS]
    assert len(kept) >= 9
    for new, old in kept:
        size = 1.0 if notes.get("resampled") else notes.get("size", 1.0)
        d = np.linalg.norm(pw[:, b.index(new)] - size * cmu[first:, b0.index(old)], axis=-1)
        assert d.max() < 1e-6, (new, d.max())


@pytest.mark.parametrize("name", sorted(CONVENTIONS))
def test_recognised_without_user_action(source, conventions, name):
    """The roles are the CMU clip's joints under their new names (a merged joint's role is gone), the
    unit and up axis the file's, the T-pose first frame found where the convention keeps it."""
    path, clip, notes = conventions[name]
    cmu = recognise(read_bvh(source))
    skel = recognise(read_bvh(path))
    renamed = {old: new for new, old in clip.answer.items()}
    expected = {role: renamed[joint] for role, joint in cmu.roles.items() if joint in renamed}
    assert dict(skel.roles) == expected
    assert skel.unit == pytest.approx(notes["unit"], rel=1e-12)
    assert skel.up == notes["axes"]
    assert skel.rest_frames == clip.rest_frames


def twin(source, name, notes, folder):
    """The CMU clip with the re-export's performer size and frame rate, in CMU's own convention."""
    c = read(source)
    if notes.get("size"):
        c = scale(c, notes["size"])
    if notes.get("resampled"):
        c = resample(c, 100.0)
    return write(c, folder / f"{name}_cmu.bvh")


def contacts_and_legs(clip, folder):
    """The subject's figure and the fitted scene of `clip` (`--scene auto`): its contacts (site, start,
    end, surface), the leg joints' quaternions, the root height, the figure's leg and arm segments."""
    import mujoco

    from runner.capture.contact_detection import reference_contacts
    from runner.capture.scene import clip_scene, name_surfaces
    from runner.capture.subject_figure import write_subject_figure
    from solver.figure import Figure
    from solver.layout import StateLayout

    figure = write_subject_figure(read_bvh(clip), folder / f"{clip.stem}.figure.xml")
    cs = clip_scene(clip, "auto", figure, folder / f"{clip.stem}.scene.xml")
    ref, model = cs.reference, cs.model
    contacts = name_surfaces(model, ref, reference_contacts(model, ref.qpos, ref.frame_time))
    layout = StateLayout.from_model(model)
    legs = np.concatenate([ref.qpos[:, layout.joint(j).qpos_slice] for j in ("l_hip", "l_knee", "l_ankle", "r_hip",
                                                                            "r_knee", "r_ankle")], axis=1)
    fm = mujoco.MjModel.from_xml_path(str(figure))
    fig = Figure.from_model(fm)
    lengths = [fig.segments[b].length for b in ("l_thigh", "l_shin", "r_thigh", "r_shin", "l_upper_arm", "l_forearm")]
    soles = np.concatenate([fm.site_pos[fm.site(s).id] for s in fig.contact_sites])  # the fitted soles
    return [(c.site, c.start, c.end, c.surface) for c in contacts], legs, ref.qpos[:, 2], np.r_[lengths, soles]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CONVENTIONS))
def test_the_same_figure_reference_and_contacts_as_the_cmu_clip(source, conventions, name, tmp_path):
    """What `mocap` finds on a re-export is what it finds on the CMU clip of the same performer size and
    frame rate: the same contacts (sites, times, surfaces), the same leg motion on the figure, the same
    root height (the root's heading may differ with the file's axes), the same bones and soles. (Where the
    convention merges spine joints, the trunk's mean direction differs, and with it the pelvis's frame
    and the hip joints' rotations: there the knees and ankles.)"""
    path, _, notes = conventions[name]
    a = contacts_and_legs(twin(source, name, notes, tmp_path), tmp_path)
    b = contacts_and_legs(path, tmp_path)
    assert b[0] == a[0] and len(a[0]) >= 4
    qa, qb = (q.reshape(len(q), -1, 4) for q in (a[1], b[1]))
    if notes.get("merged"):
        qa, qb = qa[:, [1, 2, 4, 5]], qb[:, [1, 2, 4, 5]]
    assert np.abs(np.abs(np.sum(qa * qb, axis=-1)) - 1.0).max() < 1e-9  # the same rotations (q or -q)
    assert b[2] == pytest.approx(a[2], abs=1e-5)
    assert b[3] == pytest.approx(a[3], abs=1e-5)


def key_distances(src, out, npz, unit, axes, rest_frames):
    """(K, J) [m] joint distances between two files on one skeleton at the saved path's keyframe times
    (tests/bvh_fk.py on both), and the keyframe frames."""
    a, b = parse(src), parse(out)
    _, pa = world(a, unit, axes)
    _, pb = world(b, unit, axes)
    k = rest_frames + np.rint(load_saved_path(npz).keyframe_times / a.frame_time).astype(int)
    return np.linalg.norm(pa[k] - pb[k], axis=-1), k


def as_captured(npz):
    """(K,) bool: the keyframes that are the reference (the capture as the figure has it; the keyframe
    file's 6 decimals), not moved by the footplant."""
    saved = load_saved_path(npz)
    k = np.rint(saved.keyframe_times / (saved.reference_times[1] - saved.reference_times[0])).astype(int)
    return np.abs(saved.keyframes - saved.reference_qpos[k]).max(axis=1) < 1e-5


def way_back(path, folder, scene=()):
    """`mocap` (a short solve: the keyframes are met whatever the optimizer does; `scene`: its --scene
    option, or the fitted scene) and `export --to`."""
    out_dir = folder / path.stem
    assert main(["mocap", str(path), "--out-dir", str(out_dir), *scene, *FAST]) == 0
    npz = out_dir / f"{path.stem}.npz"
    out = folder / f"{path.stem}.back.bvh"
    assert main(["export", str(npz), "--to", str(out), "--quiet"]) == 0
    return npz, out


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CONVENTIONS))
def test_the_way_back_is_the_source_skeleton_at_the_keyframes(conventions, name, tmp_path):
    """`export --to x.bvh` writes the source's HIERARCHY verbatim, its frame count and frame time, and at
    every keyframe time every joint (end joints, fingers and static roots included) within 0.1 mm of the
    source's where the keyframe is the capture (within 5 mm where the footplant moved it)."""
    path, clip, notes = conventions[name]
    npz, out = way_back(path, tmp_path)
    text, src = out.read_text().splitlines(), path.read_text().splitlines()
    m = src.index("MOTION")
    assert text[:m + 3] == src[:m + 3]
    d, k = key_distances(path, out, npz, notes["unit"], axes_of(notes), clip.rest_frames)
    kept = as_captured(npz)
    assert len(k) >= 4 and kept.sum() >= 2 and d[kept].max() < KEY_TOLERANCE, (name, d[kept].max())
    assert d.max() < PLANTED_TOLERANCE, (name, d.max())


#: the real clips (tests/data/bvh/README.md): {file: (unit, up, rest frames, {role: joint})} (the cmu1 clip
#: has the names of CMU's BVH conversion, whose first frame is a synthetic T-pose: its first is dropped)
REAL_CLIPS = {
    "fair1_jumping.bvh": (0.0254, "z", 0, {"hips": "Hips", "chest": "Spine3", "l_upper_leg": "LeftUpLeg",
                                        "r_forearm": "RightForeArm", "l_toe": "LeftToeBase", "head": "Head"}),
    "rokoko_jesse_dance.bvh": (0.01, "y", 0, {"hips": "Hips", "chest": "Spine2", "l_upper_arm": "LeftArm",
                                           "r_hand": "RightHand", "l_foot": "LeftFoot", "neck": "Neck"}),
    "cmu1_jumping_jacks.bvh": (0.0254 / 0.45, "y", 1, {"hips": "Hips", "spine": "lowerback", "chest": "Chest2",
                                                     "l_upper_leg": "LeftHip", "l_lower_leg": "LeftKnee",
                                                     "l_upper_arm": "LeftShoulder", "r_forearm": "RightElbow",
                                                     "r_hand": "RightWrist", "l_toe": "LeftToe"}),
}


#: the scene a real clip is given: the dancer holds a foot up (13 cm for 0.8 s, then a kick held at 1.1 m), which
#: the fitted scene takes for boxes, and the root correction those would need is refused (docs/mocap.md, "The
#: reference"); a scene of one's own is the way on there, the floor the dance was captured on
REAL_SCENES = {"rokoko_jesse_dance.bvh": ("--scene", str(REPO / "models" / "floor.xml"))}


@pytest.mark.parametrize("name", sorted(REAL_CLIPS))
def test_real_clips_of_other_captures_are_recognised(name):
    unit, up, rest, roles = REAL_CLIPS[name]
    skel = recognise(read_bvh(REAL / name))
    assert skel.unit == pytest.approx(unit, rel=1e-12) and skel.up == up and skel.rest_frames == rest
    assert {r: skel.roles[r] for r in roles} == roles


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(REAL_CLIPS))
def test_real_clips_of_other_captures_come_back_at_the_keyframes(name, tmp_path):
    unit, _, rest, _ = REAL_CLIPS[name]
    path = REAL / name
    npz, out = way_back(path, tmp_path, REAL_SCENES.get(name, ()))
    d, k = key_distances(path, out, npz, unit, AXES, rest)  # distances: any axes
    kept = as_captured(npz)
    assert len(k) >= 4 and kept.sum() >= 2 and d[kept].max() < KEY_TOLERANCE, (name, d[kept].max())
