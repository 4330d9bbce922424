"""Writing one's own scene (models/README.md "Writing a scene"): the shipped flat-floor scene, a copied scene that loses its
included figure, a scene without a floor, and a keyframe file whose "model" is not there - each a clear
one-line error naming the file and the fix, reported when the scene or file is read."""
import json
import shutil
from pathlib import Path

import pytest

from runner.cli import main
from runner.exit_codes import EXIT_INPUT
from runner.problem_file import load_problem
from solver import model as model_module
from solver.errors import InputError
from solver.keyframe_file import read_keyframes
from solver.layout import StateLayout
from solver.model import load_model
from solver.surfaces import StaticSurfaces

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"


def one_line_error(capsys, argv):
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err.strip()
    assert code == EXIT_INPUT, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def small_keyframes(tmp_path, scene=None):
    doc = json.loads((MODELS / "run_and_step.keyframes.json").read_text())
    doc["keyframes"] = doc["keyframes"][:3]
    doc["scene"] = str(scene or MODELS / "run_and_step.xml")
    doc["model"] = str(MODELS / "humanoid39.xml")
    doc["source"] = {}
    p = tmp_path / "k.json"
    p.write_text(json.dumps(doc))
    return p


def test_floor_scene_is_the_figure_on_a_flat_floor():
    model = load_model(MODELS / "floor.xml")
    model_module.check_scene(model, MODELS / "floor.xml")
    surfaces = StaticSurfaces.from_model(model)
    assert surfaces.names == ("floor",)
    assert StateLayout.from_model(model).nq == 51


def test_floor_scene_works_with_the_shipped_keyframes(tmp_path):
    """The shipped keyframes on the flat floor: their contacts read against the floor scene's figure and
    surfaces; one on the shipped scene's step is refused at once, naming the file and the entry."""
    path = small_keyframes(tmp_path, MODELS / "floor.xml")
    with pytest.raises(InputError, match=rf"^{path}: contacts\[\d+\]: 'surface' is 'step', which the scene does not have"):
        load_problem(path, None)
    doc = json.loads(path.read_text())
    for c in doc["contacts"]:
        c.pop("surface", None)  # whichever surface is under the site
    path.write_text(json.dumps(doc))
    keyframes, info, _model, _layout, scene = load_problem(path, None)
    assert scene == MODELS / "floor.xml" and keyframes.count == 3 and len(info.contacts) == len(doc["contacts"])


def test_a_copied_scene_names_the_missing_include_and_the_fix(tmp_path, capsys):
    copy = tmp_path / "my_scene.xml"
    shutil.copy(MODELS / "run_and_step.xml", copy)
    with pytest.raises(InputError) as e:
        load_model(copy)
    msg = str(e.value)
    assert "my_scene.xml includes humanoid39.xml" in msg
    assert "absolute path" in msg and "copy humanoid39.xml next to the scene" in msg
    err = one_line_error(capsys, ["animate", small_keyframes(tmp_path), "--scene", copy, "--no-render", "--quiet"])
    assert "my_scene.xml includes humanoid39.xml" in err


def test_a_copied_scene_with_the_figure_by_absolute_path_loads_anywhere(tmp_path):
    text = (MODELS / "floor.xml").read_text().replace('file="humanoid39.xml"', f'file="{MODELS / "humanoid39.xml"}"')
    copy = tmp_path / "sub" / "mine.xml"
    copy.parent.mkdir()
    copy.write_text(text)
    model_module.check_scene(load_model(copy), copy)


def test_scene_without_a_floor_is_refused_up_front_naming_the_file(tmp_path, capsys):
    figure = MODELS / "humanoid39.xml"
    err = one_line_error(capsys, ["animate", small_keyframes(tmp_path), "--scene", figure, "--no-render", "--quiet"])
    assert "humanoid39.xml has no static floor plane or box" in err
    assert "models/floor.xml" in err and "plane" in err
    out = tmp_path / "k2.json"
    err = one_line_error(capsys, ["keyframes-from-bvh", MODELS / "cmu" / "127_33.bvh", "--out", out,
                                  "--scene", figure])
    assert "humanoid39.xml has no static floor plane or box" in err and "models/floor.xml" in err
    assert not out.exists()


def test_keyframe_file_model_must_exist_relative_to_the_file(tmp_path):
    p = small_keyframes(tmp_path)
    doc = json.loads(p.read_text())
    doc["model"] = "humanoid39.xml"  # not next to k.json
    p.write_text(json.dumps(doc))
    layout = StateLayout.from_model(load_model(MODELS / "humanoid39.xml"))
    with pytest.raises(InputError, match=r"k\.json: field 'model' is 'humanoid39\.xml', but .*humanoid39\.xml is "
                                         r"not a file .*relative to the keyframe file's folder.*or remove the field"):
        read_keyframes(p, layout)
    del doc["model"]
    p.write_text(json.dumps(doc))
    assert read_keyframes(p, layout)[1].model is None


def test_keyframes_from_bvh_records_a_model_that_exists(tmp_path):
    scene = tmp_path / "mine.xml"
    scene.write_text((MODELS / "floor.xml").read_text().replace('file="humanoid39.xml"',
                                                                 f'file="{MODELS / "humanoid39.xml"}"'))
    out = tmp_path / "k.json"
    assert main(["keyframes-from-bvh", str(MODELS / "cmu" / "127_33.bvh"), "--out", str(out), "--scene", str(scene),
                 "--every", "0.5", "--figure", "default"]) == 0
    doc = json.loads(out.read_text())
    assert (out.parent / doc["model"]).resolve().is_file()
    assert (out.parent / doc["scene"]).resolve() == scene.resolve()


def test_a_capture_floor_that_rises_along_the_walk_is_levelled(tmp_path):
    """07_04 (a slow walk whose capture floor rises about 5 cm along the walk, models/cmu/README.md):
    `keyframes-from-bvh --scene auto` fits the tilted floor and writes the scene in the levelled frame.
    The independent reference: a straight line through the heights of the source's toe-base joints (its
    own forward kinematics) at the frames they are still, against x. The transform the scene records
    takes a floor of that slope (within 0.004, 20 %; no cross slope: the stances spread 0.25 m across the
    walk) to +z; the written floor is the plane z = 0 (MuJoCo's geom pose); and the same still toes,
    moved by the transform, no longer rise (slope within 0.004 of 0) and are 0-6 cm above z = 0."""
    import mujoco
    import numpy as np
    from bvh_fk import parse, world

    from solver.capture_frame import CaptureFrame

    src = REPO / "models" / "cmu" / "07_04.bvh"  # shipped with its attribution (models/cmu/README.md)
    clip = parse(src)
    _, p = world(clip)
    still = []
    for joint in ("LeftToeBase", "RightToeBase"):
        q = p[1:, clip.index(joint)]
        still.append(q[np.linalg.norm(np.gradient(q, clip.frame_time, axis=0), axis=1) < 0.2])
    still = np.concatenate(still)
    source_slope = np.polyfit(still[:, 0], still[:, 2], 1)[0]
    assert source_slope > 0.01  # the clip does rise: more than 1 cm per metre

    out = tmp_path / "k.json"
    assert main(["keyframes-from-bvh", str(src), "--out", str(out), "--scene", "auto", "--quiet"]) == 0
    scene = out.parent / json.loads(out.read_text())["scene"]
    model = mujoco.MjModel.from_xml_path(str(scene))
    surfaces = StaticSurfaces.from_model(model)
    np.testing.assert_allclose(surfaces.plane_normal, [[0.0, 0.0, 1.0]], atol=1e-12)
    assert surfaces.height_above(np.zeros((1, 3)))[0] == pytest.approx(0.0, abs=1e-12)
    t = CaptureFrame.from_model(model)
    n = t.matrix().T @ [0.0, 0.0, 1.0]  # the capture floor's normal, in the capture's coordinates
    slope = -n[:2] / n[2]
    assert slope[0] == pytest.approx(source_slope, abs=0.004)
    assert abs(slope[1]) < 0.002
    level = t.points(still)
    assert abs(np.polyfit(level[:, 0], level[:, 2], 1)[0]) < 0.004
    assert 0.0 < np.median(level[:, 2]) < 0.06  # the toe joints' centres, a few cm above the sole on the floor
