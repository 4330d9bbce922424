"""An animator's keyed frames as the keyframes (`--key-frames`, the Blender add-on's in-between): the keys
are at exactly those frames of the file (times from its Frame Time), with the clip's own poses (no
footplant, no root-height correction: the retargeted file frame, by the subject figure's kinematics, puts
the hips where the file does), and bad frames are one line; partial keys (`--key-joints`); the clip's own
ground plane with boxes in its coordinates (`--scene floor --boxes`)."""
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
from bvh_edit import edit_bvh

from runner.cli import main
from runner.exit_codes import EXIT_INPUT
from solver.keyframe_file import read_keyframes

REPO = Path(__file__).resolve().parents[3]
CLIP = REPO / "models" / "cmu" / "127_33.bvh"
UNIT = 0.0254 / 0.45  # [m] per unit of the CMU clips (models/cmu/README.md "Units")


@pytest.fixture(scope="module")
def short_clip(tmp_path_factory):
    """The first 0.65 s of 127_33, its T-pose frame first."""
    return edit_bvh(CLIP, tmp_path_factory.mktemp("clip") / "run.bvh", seconds=0.65)


def _hips(path, row):
    """[m] the Hips' position channels (Y up -> z) in the file's `row`-th motion line."""
    text = Path(path).read_text().split("MOTION", 1)[1].strip().splitlines()
    x, y, z = (float(v) for v in text[2 + row].split()[:3])
    return np.array([z, x, y]) * UNIT  # (X, Y, Z)_file = (y, z, x)_MuJoCo for the CMU clips


def test_keys_at_the_given_frames_with_the_files_poses(short_clip, tmp_path):
    frames = (0, 30, 77)
    out = tmp_path / "k.keyframes.json"
    boxes = tmp_path / "boxes.json"  # a box in the file's coordinates, off the path (CMU: Y up, its unit)
    boxes.write_text(json.dumps([{"min": [100, 0, 100], "max": [110, 5, 120]}]))
    assert main(["keyframes-from-bvh", str(short_clip), "--out", str(out), "--key-frames", "0,30,77",
                 "--scene", "floor", "--boxes", str(boxes), "--quiet"]) == 0
    doc = json.loads(out.read_text())
    frame_time = float(Path(short_clip).read_text().split("Frame Time:")[1].split()[0])
    times = [k["time"] for k in doc["keyframes"]]
    assert all(any(abs(t - f * frame_time) < 1e-6 for t in times) for f in frames), times
    model = mujoco.MjModel.from_xml_path(str(out.parent / doc["scene"]))
    keys, _ = read_keyframes(out, model)
    for f in frames:  # [m]; the file's frame f is motion frame f - 1 after the T-pose; the root is the file's hips
        k = int(np.argmin(np.abs(keys.times - f * frame_time)))
        assert np.abs(keys.values[k, :3] - _hips(short_clip, f + 1)).max() < 1e-6, (f, keys.values[k, :3])
    world = [g for g in range(model.ngeom) if model.geom_bodyid[g] == 0]  # --scene floor: a plane at z = 0, the box
    assert [model.geom_type[g] for g in world] == [mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_BOX]
    assert model.geom_pos[world[0], 2] == 0
    # (X, Y, Z)_file = (y, z, x)_MuJoCo: centre (105, 2.5, 110) -> (110, 105, 2.5), half (5, 2.5, 10) -> (10, 5, 2.5)
    assert np.allclose(model.geom_pos[world[1]], np.array([110, 105, 2.5]) * UNIT, atol=1e-6)
    assert np.allclose(model.geom_size[world[1]], np.array([10, 5, 2.5]) * UNIT, atol=1e-6)


@pytest.mark.parametrize("frames, match", [("0", "give at least two whole frame numbers"),
                                            ("0,30,30", "the frames must increase and lie in the clip, 0..78"),
                                            ("0,500", "the frames must increase and lie in the clip"),
                                            ("a,b", "is not a comma-separated list of frame numbers")])
def test_bad_key_frames_are_one_line(short_clip, tmp_path, capsys, frames, match):
    rc = main(["keyframes-from-bvh", str(short_clip), "--out", str(tmp_path / "k.json"), "--key-frames", frames,
               "--quiet"])
    err = capsys.readouterr().err
    assert rc == EXIT_INPUT and err.count("\n") == 1 and match in err, err


def test_a_partial_key_fixes_the_figure_joints_its_joints_drive(short_clip, tmp_path):
    """--key-joints: keyed CMU joints -> the figure joints they drive (docs/mocap.md "What the figure keeps"):
    Hips the root, LHipJoint (merged, composed into the thigh) the left hip, LowerBack (merged into the
    torso) the torso, LeftForeArm the left elbow; the toes, the head and a hand fix nothing, so a key of
    those alone is no key."""
    spec = tmp_path / "joints.json"
    spec.write_text(json.dumps({"30": ["Hips", "LHipJoint", "LowerBack", "LeftForeArm", "LeftToeBase", "Head"],
                                "50": ["LeftHand", "RightToeBase"]}))
    out = tmp_path / "k.keyframes.json"
    assert main(["keyframes-from-bvh", str(short_clip), "--out", str(out), "--key-frames", "0,30,50,77",
                 "--key-joints", str(spec), "--scene", "floor", "--quiet"]) == 0
    doc = json.loads(out.read_text())
    model = mujoco.MjModel.from_xml_path(str(out.parent / doc["scene"]))
    keys, _ = read_keyframes(out, model)
    frame_time = float(Path(short_clip).read_text().split("Frame Time:")[1].split()[0])
    assert not any(abs(t - 50 * frame_time) < 1e-6 for t in keys.times), keys.times  # fixes nothing: no key
    k = int(np.argmin(np.abs(keys.times - 30 * frame_time)))
    fixed = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)
             if keys.mask[k, model.jnt_qposadr[j]]}
    assert fixed == {"root", "l_hip", "torso", "l_elbow"}, fixed
    assert keys.mask[[i for i in range(len(keys.times)) if i != k]].all()  # the other keys are full


@pytest.mark.parametrize("text", ['[{"min": [0, 0, 0], "max": [1, 0, 1]}]', '{"min": [0, 0, 0]}', '[{"min": [0, 0]}]'])
def test_a_bad_box_is_one_line(short_clip, tmp_path, capsys, text):
    boxes = tmp_path / "boxes.json"
    boxes.write_text(text)
    rc = main(["keyframes-from-bvh", str(short_clip), "--out", str(tmp_path / "k.json"), "--scene", "floor",
               "--boxes", str(boxes), "--quiet"])
    err = capsys.readouterr().err
    assert rc == EXIT_INPUT and "box 0 is" in err and "with min < max" in err and err.count("\n") == 1, err


def test_key_joints_need_key_frames(short_clip, tmp_path, capsys):
    spec = tmp_path / "joints.json"
    spec.write_text('{"31": ["Hips"]}')
    rc = main(["keyframes-from-bvh", str(short_clip), "--out", str(tmp_path / "k.json"), "--key-frames", "0,30",
               "--key-joints", str(spec), "--quiet"])
    err = capsys.readouterr().err
    assert rc == EXIT_INPUT and "frames [31] are not among --key-frames" in err and err.count("\n") == 1, err
