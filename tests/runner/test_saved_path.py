"""The one reader of the saved-path contract (`runner.saved_path.load_saved_path`): typed fields, the
bookkeeping fields when present, one-line errors naming the file and the field."""
import json

import numpy as np
import pytest

from runner.saved_path import FIELDS, REQUIRED, load_saved_path
from solver.errors import InputError


def _fields(nq=5, **over):
    t = np.linspace(0.0, 1.0, 4)
    f = dict(frame_times=t, frames=np.zeros((4, nq)), plain_frame_times=t[::3], plain_frames=np.zeros((2, nq)),
             keyframe_times=t[::3], keyframes=np.zeros((2, nq)), reference_times=np.zeros(0),
             reference_qpos=np.zeros((0, nq)), scene=np.array("models/run_and_step.xml"))
    f.update(over)
    return f


def test_typed_fields_and_optional_bookkeeping(tmp_path):
    p = tmp_path / "a.npz"
    np.savez(p, **_fields())
    s = load_saved_path(p)
    assert s.nq == 5 and not s.has_reference and s.metrics == {} and s.source == p
    assert s.scene.is_absolute() and s.scene_path == s.scene and s["frames"].shape == (4, 5)
    np.savez(p, **_fields(metrics_json=np.array(json.dumps({"optimized": {"x": 1}}))))
    assert load_saved_path(p).metrics == {"optimized": {"x": 1}}
    assert set(REQUIRED) <= set(FIELDS)


@pytest.mark.parametrize("over, match", [
    (dict(frames=np.zeros((4, 6))), "field 'plain_frames' has shape"),
    (dict(frame_times=np.zeros(3)), "field 'frame_times' has shape .3,.; expected .4,."),
    (dict(reference_qpos=np.zeros((2, 5))), "field 'reference_times' has shape"),
    (dict(metrics_json=np.array("{not json")), "field 'metrics_json' is not JSON"),
])
def test_damaged_files_are_one_line_naming_the_field(tmp_path, over, match):
    p = tmp_path / "bad.npz"
    np.savez(p, **_fields(**over))
    with pytest.raises(InputError, match=match) as e:
        load_saved_path(p)
    assert str(p) in str(e.value) and "\n" not in str(e.value)


def test_missing_field_folder_and_not_a_zip(tmp_path):
    f = _fields()
    del f["plain_frames"]
    np.savez(tmp_path / "m.npz", **f)
    with pytest.raises(InputError, match="plain_frames missing"):
        load_saved_path(tmp_path / "m.npz")
    with pytest.raises(InputError, match="it is a folder"):
        load_saved_path(tmp_path)
    (tmp_path / "t.npz").write_text("hello")
    with pytest.raises(InputError, match="not a zip archive"):
        load_saved_path(tmp_path / "t.npz")


def test_saved_keyframes_are_the_poses_the_path_meets(tmp_path):
    """A keyframe file may give a joint's quaternion as q or -q (the same rotation); the saved `keyframes`
    are as the path meets them, so `frames` at a keyframe time equal `keyframes` where the mask fixes a
    component, sign included (a natural spline through the frames evaluated independently with scipy)."""
    from scipy.interpolate import make_interp_spline

    from runner.cli import main
    from runner.paths import MODELS

    doc = json.loads((MODELS / "run_and_step.keyframes.json").read_text())
    doc["scene"] = str(MODELS / "run_and_step.xml")
    doc["model"] = str(MODELS / "humanoid39.xml")
    doc.pop("source", None)  # no reference clip: faster, and beside the point
    for joint in ("l_knee", "r_hip"):  # flip the sign of two joints of keyframe 2
        doc["keyframes"][2]["joints"][joint] = [-v for v in doc["keyframes"][2]["joints"][joint]]
    kf = tmp_path / "flipped.keyframes.json"
    kf.write_text(json.dumps(doc))
    out = tmp_path / "p.npz"
    assert main(["animate", str(kf), "--no-render", "--quiet", "--no-summary", "--max-evals", "3", "--save-path", str(out)]) == 0
    z = np.load(out)
    path = make_interp_spline(z["frame_times"], z["frames"], k=3, bc_type="natural")(z["keyframe_times"])
    fixed = z["keyframe_mask"]
    assert np.abs(path[fixed] - z["keyframes"][fixed]).max() < 1e-9
    assert np.isnan(z["keyframes"][~fixed]).all()
