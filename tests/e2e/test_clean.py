"""`dynsplines clean` end to end on a shipped walk (16_23, 299 frames at 120 Hz): the outputs, the feet, the
pins on the written BVH read back, and the saved path's cleaned clip at the capture's frames."""
import json
from pathlib import Path

import numpy as np
import pytest

from runner.capture.bvh import read_bvh
from runner.clean import CleanOptions, process_clean
from runner.paths import MODELS

CLIP = MODELS / "cmu" / "16_23.bvh"


@pytest.fixture(scope="module")
def cleaned(tmp_path_factory):
    out = tmp_path_factory.mktemp("clean")
    o = CleanOptions(pins=(1.0,), pin_ends=True, render=False, quiet=True, summary=False)
    return out, process_clean(CLIP, out, o, say=lambda *_: None)


def test_clean_writes_its_outputs_and_meets_the_feet_limits(cleaned):
    out, result = cleaned
    assert result["exit"] == "ok"
    for name in ("save_path", "bvh", "glb", "metrics", "scene"):
        assert (out / result["outputs"][name].split("/")[-1]).is_file(), name
    report = json.loads((out / "16_23.clean.metrics.json").read_text())
    feet = report["metrics"]["motion"]["optimized"]["path"]
    assert report["metrics"]["optimized"]["max_penetration_mm"] <= 1.0 + 0.1  # the 1 mm tolerance
    assert feet["float_contact_mm"] <= report["metrics"]["motion"]["plain"]["path"]["float_contact_mm"]
    # --feet planted (the default): the capture's 1.50 mm/frame of skate in contact at least halved
    assert feet["skate_contact_mm"] <= 0.5 * report["metrics"]["motion"]["plain"]["path"]["skate_contact_mm"]
    c = result["clean"]
    # no new jolt: the change's peaks within the 6 Hz capture's, both by central differences at the frames, the
    # bound's own measure (exact for the pelvis's position; 1 % for a ball joint's rotation, which is not linear)
    assert c["change_pelvis_m_s2"] <= (1 + 1e-9) * c["capture_pelvis_m_s2"]
    assert c["change_joint_rad_s2"] <= 1.01 * c["capture_joint_rad_s2"]


def test_pins_are_the_source_on_the_written_bvh(cleaned):
    out, result = cleaned
    on = result["keyframes_on_source"]
    assert on["keys"] == 3 and on["max_mm"] <= 0.1  # the ends and the pin at 1 s, read back by bvhio
    src, written = read_bvh(CLIP), read_bvh(out / "16_23.clean.bvh")
    assert len(written.local_quat) == len(src.local_quat)  # every frame, at the capture's rate
    assert abs(written.frame_time - src.frame_time) < 1e-9


def test_saved_path_holds_the_cleaned_clip_at_the_capture_frames(cleaned):
    out, result = cleaned
    z = np.load(out / "16_23.clean.npz")
    np.testing.assert_array_equal(z["path_times"], z["reference_times"])
    assert z["path_qpos"].shape == z["reference_qpos"].shape
    pins = [int(np.argmin(np.abs(z["reference_times"] - t))) for t in result["pins"]]
    np.testing.assert_allclose(z["path_qpos"][pins], z["reference_qpos"][pins], rtol=0, atol=1e-12)


def test_free_ends_are_reported_apart_from_the_pins(tmp_path):
    """Without --pin-ends the clip's ends are the clean's to move: the check read back from the written BVH
    holds the pin alone to the source (0.1 mm) and gives the ends' change apart, as the clean's figure."""
    o = CleanOptions(pins=(0.3,), render=False, quiet=True, summary=False)
    result = process_clean(MODELS / "cmu" / "143_31.bvh", tmp_path, o, say=lambda *_: None)
    on = result["keyframes_on_source"]
    assert on["keys"] == 1 and on["max_mm"] <= 0.1 and abs(on["time_s"] - 0.3) < 1e-3
    assert on["ends_max_mm"] >= 0.0  # the two ends, measured on the file and reported apart
    # the summary's keyframe error is the pin's alone, where capture and cleaned clip are one: the free ends,
    # keyframes of the problem that fix nothing, are not compared with the cleaned clip's own values there
    report = json.loads((tmp_path / "143_31.clean.metrics.json").read_text())
    assert on["ends_max_mm"] > 0.1 and report["metrics"]["optimized"]["keyframe_error"] <= 1e-9
    assert report["metrics"]["plain"]["keyframe_error"] <= 1e-9
    from runner.capture.source_export import export_on_source  # `dynsplines export` of the saved path: the same

    check = export_on_source(tmp_path / "143_31.clean.npz", tmp_path / "again.bvh", required=True).check
    assert check.free.tolist() == [abs(t - 0.3) >= 1e-3 for t in check.times] and len(check.times) == 3


@pytest.mark.slow
def test_a_clean_that_can_meet_every_constraint_raises_nothing(tmp_path):
    """The first 97 frames of AnimatedDrawings' zombie (30 fps, 3.2 s; `runner.bench.clean_scaling`'s 1x length):
    the subproblems stall with the feet far off (the slide at about 120 tolerances, the change's acceleration at
    35), and the least violation sought from that path alone certified 238 mm of slide out of reach, the clip
    written with 1.6 mm a frame of skate. Sought from the capture itself too (d = 0), it finds a path that meets
    every constraint, so nothing may be raised: the clean converges and its skate, measured on the written path
    by MuJoCo's kinematics, is within the clean's 0.2 mm a frame."""
    from runner.bench.clean_scaling import PREFIX_CLIP, prefix_bvh

    clip = tmp_path / "zombie97.bvh"
    prefix_bvh(PREFIX_CLIP, clip, 97)
    result = process_clean(clip, tmp_path, CleanOptions(render=False, quiet=True, summary=False), say=lambda *_: None)
    report = json.loads((tmp_path / "zombie97.clean.metrics.json").read_text())
    assert report["status"] == "converged" and not report["certificate"], (report["status"], report["certificate"])
    assert report["metrics"]["motion"]["optimized"]["path"]["skate_contact_mm"] <= 0.2
    assert result["exit"] == "ok"


@pytest.mark.slow
def test_every_site_in_contact_stays_as_near_its_surface_as_captured(tmp_path):
    """A shipped dance (05_09, 150 frames at 60 Hz) standing on the floor and a box, heels and toes in contact the
    whole clip: its heels must come down to the planted limit, and a foot pitched about the ankle would lower a
    heel by lifting its toe several times as far (before each site had a pair of its own, the clean lifted both
    toes 2.4-4.6 cm). Each site's mean height over its contact at the capture's frames, on the written path by
    MuJoCo's kinematics above the plane or box top the schedule names, is no more than the capture's, FLOAT_LIMIT
    where lower, plus the 1 mm tolerance and what the certificate raised at that site."""
    import mujoco

    from solver.foot_bounds import FLOAT_LIMIT

    process_clean(MODELS / "cmu" / "05_09.bvh", tmp_path, CleanOptions(render=False, quiet=True, summary=False),
                  say=lambda *_: None)
    saved = np.load(tmp_path / "05_09.clean.npz", allow_pickle=True)
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "05_09.scene.xml"))
    raised = {r["label"]: r["amount"] for r in json.loads(str(saved["certificate_json"])) if r["constraint"] == "planted"}
    t = saved["path_times"]
    heights = [_heights(model, saved[k], saved["contacts"]) for k in ("reference_qpos", "path_qpos")]
    for k, (site, start, end, _) in enumerate(saved["contacts"]):
        on = (t >= start - 1e-9) & (t <= end + 1e-9)
        captured, cleaned = heights[0][on, k].mean(), heights[1][on, k].mean()
        # [m] the tolerance and the 0.1 mm by which the pair's smoothed positive part may fall under a mean height
        assert cleaned <= max(FLOAT_LIMIT, captured) + 1e-3 + raised.get(str(site), 0.0) + 1e-4, (site, captured, cleaned)


def _heights(model, qpos, contacts) -> np.ndarray:
    """(n, c) [m] each contact's site height above its surface, the floor z = 0 or a box's top face, at each pose
    (MuJoCo's kinematics: the site's centre less its radius)."""
    import mujoco

    data = mujoco.MjData(model)
    names = {model.numeric(i).name for i in range(model.nnumeric)}
    out = np.empty((len(qpos), len(contacts)))
    for i, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for k, (site, _, _, surface) in enumerate(contacts):
            radius = model.numeric(f"figure:radius:{site}").data[0] if f"figure:radius:{site}" in names else 0.0
            z = data.site_xpos[model.site(str(site)).id, 2] - radius
            g = model.geom(str(surface))
            assert abs(data.geom_xmat[g.id, 8] - 1.0) < 1e-9  # level: the floor, or a box turned about z only
            top = 0.0 if g.type[0] == mujoco.mjtGeom.mjGEOM_PLANE else float(data.geom_xpos[g.id, 2] + g.size[2])
            out[i, k] = z - top
    return out


@pytest.mark.slow
def test_a_joint_the_capture_holds_still_may_move_within_what_the_capture_resolves(tmp_path):
    """A hand-built sit-to-stand whose ankles never turn (tests/posture_clips.py): the import scales the root's
    path by the legs' ratio while the hips move 42 cm over the planted feet, so the feet slide about 2 cm, which
    only turning the ankles undoes. With the ankles' own peak (0) as their no-jolt limit the clean certified the
    slide out of reach (16 mm at every site); their limit is what the filtered capture resolves
    (`solver.displacement.still_peaks`), the clean meets every constraint, and no joint's change is harder than
    the larger of its capture peak and that floor."""
    from posture_clips import sit_to_stand_clip

    from solver.displacement import still_peaks

    clip = sit_to_stand_clip(tmp_path / "sit_to_stand.bvh")
    result = process_clean(clip, tmp_path, CleanOptions(render=False, quiet=True, summary=False), say=lambda *_: None)
    report = json.loads((tmp_path / "sit_to_stand.clean.metrics.json").read_text())
    assert report["status"] == "converged" and not report["certificate"], (report["status"], report["certificate"])
    assert result["clean"]["change_joint_rad_s2"] <= max(result["clean"]["capture_joint_rad_s2"], still_peaks([False])[0])
    assert report["metrics"]["motion"]["optimized"]["path"]["skate_contact_mm"] <= 0.2


def test_the_contacts_written_are_the_ones_cleaned_with_and_an_edited_file_replaces_them(tmp_path):
    """The clean writes its contact schedule beside its outputs; given back edited (`--contacts`: here the left
    foot's contacts deleted, a step detection missed), that schedule, not the detected one, is what the clean
    holds the feet to and saves with the path."""
    from runner.saved_path import contacts_from_array

    clip = MODELS / "cmu" / "143_31.bvh"
    first = process_clean(clip, tmp_path / "a", CleanOptions(render=False, quiet=True, summary=False), say=lambda *_: None)
    written = json.loads(Path(first["outputs"]["contacts"]).read_text())
    saved = contacts_from_array(np.load(first["outputs"]["save_path"])["contacts"])
    assert {(c.site, c.surface) for c in saved} == {(e["site"], e["surface"]) for e in written["contacts"]}
    assert any(e["site"].startswith("l_") for e in written["contacts"])
    written["contacts"] = [e for e in written["contacts"] if not e["site"].startswith("l_")]
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(written))
    o = CleanOptions(render=False, quiet=True, summary=False, contacts=edited)
    again = process_clean(clip, tmp_path / "b", o, say=lambda *_: None)
    saved = contacts_from_array(np.load(again["outputs"]["save_path"])["contacts"])
    assert saved and not any(c.site.startswith("l_") for c in saved)
    assert json.loads(Path(again["outputs"]["contacts"]).read_text())["contacts"] == written["contacts"]
