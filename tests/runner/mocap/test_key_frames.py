"""An animator's keyed frames as the keyframes (`--key-frames`, the Blender add-on's in-between): the keys
are at exactly those frames of the file (times from its Frame Time), with the clip's own poses (no
footplant, no root-height correction: the retargeted file frame, by the subject figure's kinematics, puts
the hips where the file does), and bad frames are one line."""
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
    assert main(["keyframes-from-bvh", str(short_clip), "--out", str(out), "--key-frames", "0,30,77",
                 "--scene", "floor", "--quiet"]) == 0
    doc = json.loads(out.read_text())
    frame_time = float(Path(short_clip).read_text().split("Frame Time:")[1].split()[0])
    times = [k["time"] for k in doc["keyframes"]]
    assert all(any(abs(t - f * frame_time) < 1e-6 for t in times) for f in frames), times
    model = mujoco.MjModel.from_xml_path(str(out.parent / doc["scene"]))
    keys, _ = read_keyframes(out, model)
    for f in frames:  # [m]; the file's frame f is motion frame f - 1 after the T-pose; the root is the file's hips
        k = int(np.argmin(np.abs(keys.times - f * frame_time)))
        assert np.abs(keys.values[k, :3] - _hips(short_clip, f + 1)).max() < 1e-6, (f, keys.values[k, :3])
    world = [g for g in range(model.ngeom) if model.geom_bodyid[g] == 0]  # --scene floor: a plane at z = 0 alone
    assert [model.geom_type[g] for g in world] == [mujoco.mjtGeom.mjGEOM_PLANE] and model.geom_pos[world[0], 2] == 0


@pytest.mark.parametrize("frames, match", [("0", "give at least two whole frame numbers"),
                                            ("0,30,30", "the frames must increase and lie in the clip, 0..78"),
                                            ("0,500", "the frames must increase and lie in the clip"),
                                            ("a,b", "is not a comma-separated list of frame numbers")])
def test_bad_key_frames_are_one_line(short_clip, tmp_path, capsys, frames, match):
    rc = main(["keyframes-from-bvh", str(short_clip), "--out", str(tmp_path / "k.json"), "--key-frames", frames,
               "--quiet"])
    err = capsys.readouterr().err
    assert rc == EXIT_INPUT and err.count("\n") == 1 and match in err, err
