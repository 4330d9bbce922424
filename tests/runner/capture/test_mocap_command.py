"""`dynsplines mocap CLIP`: bad input is one line and exit code 2; a short clip runs end to end into a
keyframe file (rerunnable with `animate`), a fitted scene, a saved path with contacts and metrics, and a
metrics report."""
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest
from bvh_edit import edit_bvh

from runner.cli import main
from runner.exit_codes import EXIT_INPUT
from runner.problem_file import find_reference
from runner.saved_path import contacts_from_array, load_saved_path
from solver.keyframe_file import read_keyframes
from solver.layout import StateLayout

REPO = Path(__file__).resolve().parents[3]
CLIP = REPO / "models" / "cmu" / "127_33.bvh"
FAST = ["--no-render", "--max-evals", "40", "--quiet"]


@pytest.fixture(scope="module")
def short_clip(tmp_path_factory):
    """The first 0.65 s of 127_33 (three foot contacts on the floor, and a flight between two steps)."""
    return edit_bvh(CLIP, tmp_path_factory.mktemp("clip") / "run.bvh", seconds=0.65)


def one_line_error(capsys, argv):
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == EXIT_INPUT, err
    assert err.count("\n") == 1 and err.startswith("dynsplines: error: "), err
    return err


def test_missing_clip(tmp_path, capsys):
    err = one_line_error(capsys, ["mocap", str(tmp_path / "nope.bvh"), "--out-dir", str(tmp_path)])
    assert "nope.bvh" in err and "no such" in err


def test_a_bad_skeleton_map_is_one_line(tmp_path, capsys):
    """`--skeleton-map FILE`: a joint the clip lacks, an unknown key, a file that is not JSON: one line
    naming the file, the key and the value."""
    clip = edit_bvh(CLIP, tmp_path / "c.bvh", seconds=0.2)
    smap = tmp_path / "map.json"
    smap.write_text('{"l_foot": "LAnkle"}')
    err = one_line_error(capsys, ["mocap", str(clip), "--out-dir", str(tmp_path / "o"), "--skeleton-map", str(smap),
                                  *FAST])
    assert "map.json" in err and '"l_foot"' in err and "LAnkle" in err and "not a joint" in err
    smap.write_text('{"left_foot": "LeftFoot"}')
    err = one_line_error(capsys, ["keyframes-from-bvh", str(clip), "--out", str(tmp_path / "k.keyframes.json"),
                                  "--skeleton-map", str(smap)])
    assert "map.json" in err and "unknown key" in err and "left_foot" in err
    smap.write_text("hips: Hips")
    err = one_line_error(capsys, ["mocap", str(clip), "--out-dir", str(tmp_path / "o"), "--skeleton-map", str(smap),
                                  *FAST])
    assert "map.json" in err and "not JSON" in err


def test_missing_scene_and_bad_video_name(tmp_path, short_clip, capsys):
    err = one_line_error(capsys, ["mocap", str(short_clip), "--out-dir", str(tmp_path), "--scene",
                                  str(tmp_path / "none.xml"), *FAST])
    assert "none.xml" in err
    err = one_line_error(capsys, ["mocap", str(short_clip), "--out-dir", str(tmp_path), "--out",
                                  str(tmp_path / "v.txt")])
    assert "v.txt" in err


def test_a_malformed_capture_frame_in_the_scene_is_one_line(tmp_path, short_clip, capsys):
    scene = tmp_path / "mine.xml"
    text = (REPO / "models" / "floor.xml").read_text().replace('file="humanoid39.xml"',
                                                                 f'file="{REPO / "models" / "humanoid39.xml"}"')
    scene.write_text(text.replace("</mujoco>", '<custom><numeric name="capture:frame" data="1 0 0 0 0"/></custom></mujoco>'))
    err = one_line_error(capsys, ["mocap", str(short_clip), "--out-dir", str(tmp_path / "o"), "--scene", str(scene),
                                  "--figure", "default", *FAST])
    assert "mine.xml" in err and "capture:frame" in err and "w x y z tx ty tz" in err


def test_bad_root_scale_is_one_line(tmp_path, short_clip, capsys):
    assert main(["mocap", str(short_clip), "--root-scale", "0", *FAST]) == EXIT_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--root-scale" in err and "> 0" in err


def test_help_names_the_default_outputs(capsys):
    assert main(["mocap", "--help"]) == 0
    out = capsys.readouterr().out
    assert "renders/<clip stem>/" in out and "auto" in out and "--keys" in out and "--max-time" in out


@pytest.mark.slow
def test_the_captures_flights_are_written(tmp_path):
    """The capture's flights are written into the keyframe file (the clearance term's, docs/contacts.md
    "Flights where the capture flies"): as long in all as the flight metric counts them on the capture (6
    decimals, rounded outward). The first 0.65 s of the run 35_17: two steps and a flight of about 0.07 s
    between them (127_33's first 0.65 s flies 0 to 0.05 s in all by the flight metric's 3 cm, as the heel's
    sphere comes out)."""
    clip = edit_bvh(REPO / "models" / "cmu" / "35_17.bvh", tmp_path / "run.bvh", seconds=0.65)
    out = tmp_path / "out"
    assert main(["mocap", str(clip), "--out-dir", str(out), *FAST, "--metrics", str(tmp_path / "m.json")]) == 0
    model = mujoco.MjModel.from_xml_path(str(out / "run.scene.xml"))
    _, info = read_keyframes(out / "run.keyframes.json", StateLayout.from_model(model))
    captured = json.loads((tmp_path / "m.json").read_text())["metrics"]["motion"]["optimized"]["reference"]
    assert info.flights and sum(b - a for a, b in info.flights) == pytest.approx(
        captured["flight_time_s"], abs=2e-6 * len(info.flights))


@pytest.mark.slow
def test_short_clip_end_to_end(tmp_path, short_clip, capsys):
    out = tmp_path / "out"
    assert main(["mocap", str(short_clip), "--out-dir", str(out), "--no-render", "--max-evals", "60", "--metrics", str(tmp_path / "m.json")]) == 0
    printed = capsys.readouterr().out
    assert "reference" in printed and "optimized" in printed and "penetration max [mm]" in printed
    scene = out / "run.scene.xml"
    model = mujoco.MjModel.from_xml_path(str(scene))  # the fitted scene loads from where it is saved
    layout = StateLayout.from_model(model)
    kf, info = read_keyframes(out / "run.keyframes.json", layout)
    assert info.scene == scene.resolve() and info.contacts and kf.count >= 3 and not kf.is_partial.any()
    # the subject's own figure (the default): written beside the outputs, named by the keyframe file, its
    # legs the subject's (127_33's knee OFFSET, 1 unit = 0.0254 / 0.45 m); the root path as captured
    assert info.model == (out / "run.figure.xml").resolve()
    from solver.figure import Figure

    thigh = Figure.from_model(model).segments["l_thigh"].length
    assert thigh == pytest.approx(0.0254 / 0.45 * np.hypot(2.58040, 7.08960), rel=2e-5)
    assert info.source["root_scale"] == 1.0 and find_reference(info, model, quiet=True).captured_root
    assert find_reference(info, model, quiet=True).root_scale == info.source["root_scale"]
    # a file that records no scale (made before it): as captured (the shipped file without its root_scale 1)
    doc = json.loads((REPO / "models" / "run_and_step.keyframes.json").read_text())
    doc["source"].pop("root_scale", None)
    doc["model"], doc["scene"] = str(REPO / "models" / "humanoid39.xml"), str(REPO / "models" / "run_and_step.xml")
    doc["source"]["clip"] = str(REPO / "models" / "cmu" / "127_33.bvh")
    (tmp_path / "old.keyframes.json").write_text(json.dumps(doc))
    _, shipped = read_keyframes(tmp_path / "old.keyframes.json", layout)
    assert "root_scale" not in shipped.source and find_reference(shipped, model, quiet=True).root_scale == 1.0
    assert {c.surface for c in info.contacts} == {"floor"}
    saved = load_saved_path(out / "run.npz")
    assert contacts_from_array(saved["contacts"]) == list(info.contacts)
    assert set(saved.metrics) == {"plain", "optimized", "motion"}
    assert saved.options["terms"] == "default" and "min_gap" in saved.options["solve"]  # the least change
    report = json.loads((tmp_path / "m.json").read_text())
    assert report["keyframes"] == kf.count and report["frames"] == 79 and report["fps"] == pytest.approx(120, rel=1e-4)
    # the reference the metrics compare with is the capture itself: its root path is the clip's Hips path,
    # in the levelled frame of the fitted scene (the rigid transform the scene records: its floor at z = 0),
    # raised or lowered per frame by up to ~2 cm so that the feet in contact stand on the floor (no site below it)
    from bvh_fk import parse, world

    from solver.capture_frame import CaptureFrame
    from solver.surfaces import StaticSurfaces

    _, hips = world(parse(short_clip))
    frame = CaptureFrame.from_model(model)
    assert not frame.is_identity
    c = saved.reference_qpos[:, :3] - frame.points(hips[1:, 0])
    assert np.abs(c[:, :2]).max() < 1e-6 and np.abs(c[:, 2]).max() < 0.025  # vertical, small
    data = mujoco.MjData(model)
    sites = Figure.from_model(model).contact_site_ids
    lowest = np.inf
    for q in saved.reference_qpos:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        lowest = min(lowest, StaticSurfaces.from_model(model, data).height_above(data.site_xpos[sites]).min())
    assert lowest > 0.0015  # CONTACT_CLEARANCE 2 mm above the floor, within 0.5 mm (no sinking)
    # `animate` of the keyframe file imports the clip into the same frame (it reads the transform with the scene)
    assert np.allclose(find_reference(info, model, quiet=True).qpos[:, :3], saved.reference_qpos[:, :3], atol=1e-9)
    assert report["metrics"]["optimized"]["keyframe_error"] < 1e-9
    # the keyframe file reruns with animate (the reference found through its "source" "clip")
    assert main(["animate", str(out / "run.keyframes.json"), "--no-render", "--max-evals", "20",
                 "--save-path", str(tmp_path / "again.npz")]) == 0
    assert "skating ratio" in capsys.readouterr().out
    # keys at the contact events
    assert main(["mocap", str(short_clip), "--out-dir", str(tmp_path / "c"), "--keys", "contacts", *FAST]) == 0
    kc, _ = read_keyframes(tmp_path / "c" / "run.keyframes.json", layout)
    events = sorted({c.start for c in info.contacts} | {c.end for c in info.contacts})
    for t in events:
        assert np.min(np.abs(kc.times - t)) < 0.05


@pytest.mark.slow
def test_a_hops_flight_keeps_its_length(tmp_path):
    """The flight bound on a synthetic 15 cm, 0.35 s hop of the walk 16_23 (`edit_bvh` hop, 2.5 s,
    keys every 0.25 s, fitted scene): the optimized path's flight (every contact site above 3 cm) within 30 ms
    of the capture's (the least change's flight constraint: every site above the flight height where the
    capture flies)."""
    src = REPO / "models" / "cmu" / "16_23.bvh"  # shipped with its attribution (models/cmu/README.md)
    hop = edit_bvh(src, tmp_path / "hop.bvh", hop=(0.25, 0.35, 0.15))
    report = tmp_path / "m.json"
    assert main(["mocap", str(hop), "--out-dir", str(tmp_path / "out"), "--every", "0.25", "--scene", "auto",
                 "--no-render", "--quiet", "--no-summary", "--metrics", str(report)]) == 0
    motion = json.loads(report.read_text())["metrics"]["motion"]["optimized"]
    ref, opt = motion["reference"]["flight_time_s"], motion["path"]["flight_time_s"]
    assert ref > 0.25, ref  # the hop is a flight in the capture
    assert abs(opt - ref) <= 0.030, (ref, opt)
