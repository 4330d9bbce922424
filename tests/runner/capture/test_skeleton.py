"""Skeleton recognition (runner/capture/skeleton.py) and the skeleton map (runner/capture/skeleton_map.py):
roles found without names, units and up axes of any file, rest frames at any frame rate, the map winning,
every bad map or skeleton one line naming the file, the key and the fix; and the correction the way back
reports (the hyperextension clamp, against hand-computed geometry)."""
import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from bvh_conventions import read, reframe, rename, scale, write
from bvh_edit import edit_bvh

from runner.capture.bvh import read_bvh
from runner.capture.skeleton import recognise, unit_note
from runner.capture.skeleton_map import ROLES, SkeletonMap, parse_skeleton_map, read_skeleton_map
from solver.errors import InputError

REPO = Path(__file__).resolve().parents[3]
CMU = REPO / "models" / "cmu"
CLIP = CMU / "35_17.bvh"


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    return edit_bvh(CLIP, tmp_path_factory.mktemp("short") / "run.bvh", seconds=0.6)


def test_a_complete_map_gives_the_recognised_skeleton_again(short, tmp_path):
    skel = recognise(read_bvh(short))
    assert set(skel.roles) == set(ROLES) - {"l_toe", "r_toe"} | {"l_toe", "r_toe"}  # CMU's skeleton has every role
    path = tmp_path / "map.json"
    path.write_text(skel.skeleton_map().text())
    again = recognise(read_bvh(short), read_skeleton_map(path))
    assert dict(again.roles) == dict(skel.roles) and again.unit == skel.unit and again.up == skel.up
    assert json.loads(path.read_text())["unit"] == "cmu"


def test_the_map_wins(short):
    clip = read_bvh(short)
    skel = recognise(clip, SkeletonMap({"spine": "Spine", "neck": "Neck1"}, 0.0254, "inch", "y", "m.json"))
    assert skel.roles["spine"] == "Spine" and skel.roles["neck"] == "Neck1" and skel.unit == 0.0254
    with pytest.raises(InputError, match=r"m\.json: \"l_foot\": 'Foot' is not a joint of .*run\.bvh"):
        recognise(clip, SkeletonMap({"l_foot": "Foot"}, source="m.json"))
    with pytest.raises(InputError, match=r"the joint LeftLeg plays the roles l_upper_leg, l_lower_leg"):
        recognise(clip, SkeletonMap({"l_upper_leg": "LeftLeg"}, source="m.json"))
    with pytest.raises(InputError, match=r"the l_lower_leg joint RightLeg does not descend from the l_upper_leg joint "
                                         r"LeftUpLeg; fix the skeleton map"):
        recognise(clip, SkeletonMap({"l_lower_leg": "RightLeg", "r_lower_leg": "LeftLeg"}, source="m.json"))


@pytest.mark.parametrize("text, match", [
    ('{"hips": "Hips",}', r"m\.json: line 1: not JSON"),
    ('["Hips"]', r"m\.json: a skeleton map is a JSON object"),
    ('{"pelvis": "Hips"}', r"m\.json: unknown key \"pelvis\"; the keys are the roles hips, spine"),
    ('{"hips": 3}', r"m\.json: \"hips\": 3 is not a joint name"),
    ('{"unit": "feet"}', r"m\.json: \"unit\": 'feet' is neither one of m, cm, mm, inch, cmu nor a number"),
    ('{"unit": -1}', r"\"unit\": -1 is neither"),
    ('{"up": "w"}', r"m\.json: \"up\": 'w' is not an axis; give one of x, y, z, -x, -y, -z"),
    ('{"rest_frames": 2}', r"m\.json: \"rest_frames\": 2 is not 0 or 1; give 1 when the file's first frame is a rest"),
    ('{"rest_frames": true}', r"\"rest_frames\": True is not 0 or 1"),
])
def test_a_bad_map_is_one_line(text, match):
    with pytest.raises(InputError, match=match) as e:
        parse_skeleton_map(text, "m.json")
    assert "\n" not in str(e.value)


def test_the_map_gives_the_rest_frames(short, tmp_path):
    """A CMU clip's first frame is its T-pose (1 rest frame, from its names); a map's "rest_frames": 0 says the
    file has none (the Blender add-on's export), and the recognised skeleton's map records it again."""
    clip = read_bvh(short)
    assert recognise(clip).rest_frames == 1
    skel = recognise(clip, parse_skeleton_map('{"rest_frames": 0}', "m.json"))
    assert skel.rest_frames == 0 and json.loads(skel.skeleton_map().text())["rest_frames"] == 0
    assert "rest_frames" not in json.loads(recognise(clip).skeleton_map().text())  # found, not given: not recorded


def test_a_missing_map_file(tmp_path):
    with pytest.raises(InputError, match=r"--skeleton-map .*none\.json: no such file"):
        read_skeleton_map(tmp_path / "none.json")


def test_sides_without_names_come_from_the_geometry(short, tmp_path):
    """Every joint renamed J00, J01, ...: the roles are CMU's (left: on the side of up x the feet's
    forward direction; the hand where the fingers branch off, CMU's clavicle being as long as its forearm)."""
    c = read(short)
    names = {n: f"J{i:02d}" for i, n in enumerate(c.names)}
    path = write(rename(c, names), tmp_path / "nameless.bvh")
    cmu, other = recognise(read_bvh(short)), recognise(read_bvh(path))
    assert dict(other.roles) == {r: names[j] for r, j in cmu.roles.items()}


@pytest.mark.parametrize("unit, name", [(1.0, "m"), (0.001, "mm"), (0.01, "cm"), (0.0254, "inch")])
def test_the_unit_from_the_legs(short, tmp_path, unit, name):
    c = scale(read(short), 0.0254 / 0.45 / unit)
    skel = recognise(read_bvh(write(c, tmp_path / f"{name}.bvh")))
    assert skel.unit == unit and skel.unit_name == name


def test_a_skeleton_of_no_persons_size_is_read_as_a_typical_subject_with_a_warning(short, tmp_path):
    path = write(scale(read(short), 1e-4), tmp_path / "tiny.bvh")  # legs of 1.5 mm in metres, or 3.8 cm in inches
    skel = recognise(read_bvh(path))
    # no named unit makes a person of it: the unit makes a typical 1.75 m subject, which undoes the 1e-4 to within
    # the CMU subject's own stature (an adult's, 1.5-2.0 m): the clip's true unit is CMU's, 0.0254 / 0.45 m
    assert 1.75 / 2.0 <= skel.unit * 1e-4 / (0.0254 / 0.45) <= 1.75 / 1.5
    assert skel.unit_assumed is not None
    note = unit_note(skel)
    assert re.search(r"tiny\.bvh: the legs are .* none 0\.8-2\.4 m tall: read as a 1\.75 m subject", note.replace(
        "cannot tell the length unit of ", "")), note
    assert 'give "unit" in a skeleton map' in note
    # the complete map a subject figure records keeps the warning: recognising with it flags the unit again
    again = recognise(read_bvh(path), parse_skeleton_map(skel.skeleton_map().text(), "record"))
    assert again.unit == pytest.approx(skel.unit, rel=1e-12) and again.unit_assumed == skel.unit_assumed
    assert unit_note(recognise(read_bvh(short))) is None  # a unit found: no warning


@pytest.mark.parametrize("up, axes", [("z", [[1, 0, 0], [0, 0, -1], [0, 1, 0]]), ("-y", [[1, 0, 0], [0, -1, 0],
                                                                                        [0, 0, -1]]),
                                      ("x", [[0, 1, 0], [-1, 0, 0], [0, 0, 1]])])
def test_any_up_axis_gives_the_same_joint_rotations(short, tmp_path, up, axes):
    """The file's axes turned (its up along Z, -Y or X): the up axis found, and the figure's joints turn
    as on the original (the root's heading may differ)."""
    import mujoco

    from runner.capture.reference_motion import load_bvh_reference

    c = read(short)
    g = np.array(axes, float)
    path = write(reframe(c, np.broadcast_to(g.T, (len(c.names), 3, 3)), axes=g), tmp_path / f"up_{up}.bvh")
    assert recognise(read_bvh(path)).up == up
    model = mujoco.MjModel.from_xml_path(str(REPO / "models" / "humanoid39.xml"))
    a, b = load_bvh_reference(short, model), load_bvh_reference(path, model)
    dots = np.abs(np.sum(a.qpos[:, 7:].reshape(len(a.qpos), -1, 4) * b.qpos[:, 7:].reshape(len(b.qpos), -1, 4), -1))
    assert np.abs(dots - 1.0).max() < 1e-9
    assert b.qpos[:, 2] == pytest.approx(a.qpos[:, 2], abs=1e-6)


@pytest.mark.parametrize("name", ["35_17", "75_03", "127_33", "143_31"])
def test_the_synthetic_t_pose_is_found_at_any_frame_rate(tmp_path, name):
    """CMU's first frame (the cgspeed conversion's T-pose) is a separate pose at 120 or 60 fps and every
    4th frame (30 or 15 fps), its names aside; without it the first frame is motion."""
    src = CMU / f"{name}.bvh"
    cmu_unit = SkeletonMap(unit=0.0254 / 0.45, unit_name="cmu")
    for stride in (1, 4):
        c = read(edit_bvh(src, tmp_path / f"s{stride}.bvh", stride=stride))
        c.names = [n.replace("LHipJoint", "LHip").replace("RHipJoint", "RHip").replace("LowerBack", "Back")
                   .replace("FingerBase", "Fingers") for n in c.names]  # no longer CMU's names
        assert recognise(read_bvh(write(c, tmp_path / f"t{stride}.bvh")), cmu_unit).rest_frames == 1, stride
        c.local, c.trans = c.local[1:], c.trans[1:]
        assert recognise(read_bvh(write(c, tmp_path / f"n{stride}.bvh")), cmu_unit).rest_frames == 0, stride


def test_the_way_back_names_the_hyperextension_clamp(tmp_path):
    """A knee bent 20 degrees backwards at a keyframe: the import clamps it (the figure's knees do not bend
    backwards), so on the source skeleton the left ankle is, at that keyframe, the chord of 20 degrees
    about the knee away from the clip's (2 sin 10 deg x the 7.5-unit shin) and the toe further; every
    other joint and keyframe is the clip's: the keyframes written onto the source skeleton and read back."""
    from runner.capture.reference_motion import load_bvh_reference
    from runner.capture.scene_fit import FittedScene, scene_mjcf
    from runner.capture.source_check import keys_on_source
    from runner.capture.source_export import source_bvh_text
    from runner.capture.subject_figure import write_subject_figure
    from solver.model import load_model

    from .test_bvh_import import tiny_bvh, tiny_frame

    path = tmp_path / "hyper.bvh"
    path.write_text(tiny_bvh([tiny_frame(), tiny_frame(LeftLeg=(0, 0, -20)), tiny_frame(), tiny_frame(), tiny_frame()]))
    clip = read_bvh(path)
    figure = write_subject_figure(clip, tmp_path / "h.figure.xml")
    scene = tmp_path / "h.scene.xml"
    scene.write_text(scene_mjcf(FittedScene(0.0), figure, relative_to=tmp_path))
    model = load_model(scene)
    ref = load_bvh_reference(path, model)
    knee = ref.clamped["l_knee"]
    k = int(np.argmax(knee))
    assert knee[k] == pytest.approx(20.0, abs=1e-4) and np.delete(knee, k).max() == 0
    keyed, back = ref.keyed().qpos, tmp_path / "back.bvh"  # every frame a keyframe
    back.write_text(source_bvh_text(clip, path.read_text(), model, keyed, ref.times, 1 / ref.frame_time,
                                    (ref.times, ref.qpos)))
    d = keys_on_source(clip, back, ref.skeleton.rest_frames, ref.skeleton.unit, ref.times).distance
    chord = 2 * np.sin(np.radians(10.0)) * 7.5 * 0.0254 / 0.45
    assert d[k, clip.index("LeftFoot")] == pytest.approx(chord, abs=1e-4)
    assert d[k, clip.index("LeftToeBase")] > chord
    moved = {clip.names[j] for j in np.flatnonzero(d[k] > 1e-6)}
    assert moved == {"LeftFoot", "LeftToeBase"} and np.delete(d, k, axis=0).max() < 1e-6


def test_arms_that_hang_from_a_joint_above_the_neck(short, tmp_path):
    """A Biovision-style upper body, Chest -> Chest2 -> the collars beside Chest -> Neck -> Head: CMU's Neck hung
    from Spine instead of Spine1 (its world rotations kept), so Spine is where the head and the arms part.
    The old recognition found neither arms nor head there (no joint with three branches) and asked for a map."""
    c = read(short)
    spine, upper, neck = c.index("Spine"), c.index("Spine1"), c.index("Neck")
    local, offsets = c.local.copy(), c.offsets.copy()
    local[:, neck] = c.local[:, upper] @ c.local[:, neck]
    offsets[neck] = c.offsets[upper] + c.offsets[neck]
    parents = list(c.parents)
    parents[neck] = spine
    trans = c.trans.copy()
    trans[:, neck] = offsets[neck]
    path = write(replace(c, local=local, offsets=offsets, parents=parents, trans=trans), tmp_path / "biovision.bvh")
    cmu, other = recognise(read_bvh(short)), recognise(read_bvh(path))
    assert other.roles["chest"] == "Spine" and other.roles["neck"] == "Neck" and other.roles["head"] == cmu.roles["head"]
    for role in ("l_upper_arm", "l_forearm", "l_hand", "r_upper_arm", "r_forearm", "r_hand", "l_foot", "r_foot"):
        assert other.roles[role] == cmu.roles[role], role
