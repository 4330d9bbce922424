"""The way back onto the source skeleton is exact where the path is the capture: a path through the capture at
its keyframes and away from it between them, exported with `dynsplines export --to FILE.bvh`, read back by
bvhio (its own forward kinematics, `Joint.PositionWorld`) and by tests/bvh_fk.py (the text read and the
matrix chain built here), has every joint of the source skeleton within 0.1 mm of the source's at every
key - CMU's merged chains (LowerBack and Spine below the chest, LHipJoint, the clavicles) and the joints the
figure does not have (fingers, neck, head, toes, end joints, a static root, IK and twist joints) included -
and the figures `export` reports are those of the file it wrote.
"""
import re

import numpy as np
import pytest
from bvh_conventions import convention
from bvh_edit import edit_bvh
from bvh_fk import parse, world
from posture_clips import seated_clip

from runner.paths import MODELS
from solver.quaternion import mul, normalize

#: [m] the acceptance: a joint at a key this near the source's is the source's
AT_KEY = 1e-4
#: frames between two keys (every 0.05 s at 120 fps)
KEY_STEP = 6
#: the change the path makes between keys: every joint turned 15 deg about one axis, the root moved 3 cm
TURN = normalize(np.array([np.cos(np.radians(7.5)), np.sin(np.radians(7.5)), 0.3, 0.0]))
SHIFT = np.array([0.03, -0.01, 0.02])


def bvhio_positions(path) -> tuple[list, np.ndarray]:
    """Joint names and world positions (n, J, 3) [file units] of every frame, by bvhio alone."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        import bvhio

    root = bvhio.readAsHierarchy(str(path))
    joints = [j for j, _, _ in root.layout()]
    out = []
    for f in range(len(joints[0].Keyframes)):
        root.loadPose(f, recursive=True)
        out.append([np.array(j.PositionWorld, float) for j in joints])
    return [j.Name for j in joints], np.array(out)


def changed(qpos, layout):
    """qpos with every quaternion turned by TURN and the root moved by SHIFT [m]."""
    out = qpos.copy()
    out[..., :3] += SHIFT
    for idx in layout.quat_slots:
        out[..., idx] = normalize(mul(out[..., idx], np.broadcast_to(TURN, out[..., idx].shape)))
    return out


def path_through_keys(tmp_path, clip, capture=None):
    """A saved path made from `clip` (embedded) on its subject's figure and a floor-only scene: at every
    KEY_STEP-th captured frame the reference (the capture as the figure has it), but at the second key,
    which is the reference changed (`changed`); halfway between keys the reference changed. Keys avoid
    the frames whose reference the import corrected (a glitch repaired, a knee or elbow clamped).
    Returns (npz, key frame indices after the rest frames, the index of the changed key)."""
    from runner.capture.bvh import read_bvh
    from runner.capture.reference_motion import load_bvh_reference
    from runner.capture.scene_fit import FittedScene, scene_mjcf
    from runner.capture.subject_figure import write_subject_figure
    from solver.layout import StateLayout
    from solver.model import load_model

    figure = write_subject_figure(read_bvh(clip), tmp_path / "c.figure.xml")
    scene = tmp_path / "c.scene.xml"
    scene.write_text(scene_mjcf(FittedScene(0.0), figure, relative_to=tmp_path, capture=capture))
    model = load_model(scene)
    ref = load_bvh_reference(clip, model)
    layout = StateLayout.from_model(model)
    corrected = np.zeros(ref.count, bool)
    for g in ref.glitches:
        corrected[round(g.start / ref.frame_time):round(g.end / ref.frame_time) + 1] = True
    for a in (ref.clamped or {}).values():
        corrected |= a > 0
    keys = np.array([k for k in range(0, ref.count, KEY_STEP) if not corrected[k]])
    mids = (keys[:-1] + keys[1:]) // 2
    frames = np.concatenate([ref.qpos[keys], changed(ref.qpos[mids], layout)])
    order = np.argsort(np.r_[keys, mids])
    t, frames = np.r_[ref.times[keys], ref.times[mids]][order], frames[order]
    frames[t == ref.times[keys[1]]] = changed(ref.qpos[keys[1]], layout)
    npz = tmp_path / "path.npz"
    np.savez(npz, frame_times=t, frames=frames, keyframe_times=ref.times[keys], keyframes=frames[np.isin(t, ref.times[keys])],
             plain_frame_times=t, plain_frames=frames, reference_times=ref.times, reference_qpos=ref.qpos,
             scene=np.array(scene.name), clip=np.array(clip.name), clip_text=np.array(clip.read_text()))
    return npz, keys, 1


def assert_change_written(npz, clip, out, frame):
    """At file frame `frame`, a key where the path is known exactly (its saved frame): each joint that drives
    a figure body has, by tests/bvh_fk.py, the world rotation MuJoCo's kinematics gives that body times the
    inverse of its recorded body offset (figure world = source world x R_off); the hips are where the path's
    root is less the reference's height correction (the source's hips moved by SHIFT); every other joint
    has the source's local rotation."""
    import mujoco
    from bvh_fk import local_rotations
    from scipy.spatial.transform import Rotation

    from runner.capture.body_frames import DRIVERS
    from runner.capture.bvh import read_bvh
    from runner.capture.figure_record import clip_skeleton
    from solver.model import load_model

    saved = np.load(npz)
    model = load_model(npz.parent / str(saved["scene"]))
    skel, body, _ = clip_skeleton(read_bvh(clip), model)
    t = (frame - skel.rest_frames) * saved["reference_times"][1]
    qpos = saved["frames"][np.argmin(np.abs(saved["frame_times"] - t))]
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    b_src, b_out = parse(clip), parse(out)
    rot, pos = world(b_out, skel.unit, skel.axes)
    drivers = {b_out.index(skel.roles[role]) for role in DRIVERS.values()}
    for name, role in DRIVERS.items():
        j = b_out.index(skel.roles[role])
        r_off = Rotation.from_quat(np.r_[body.offsets[name][1:], body.offsets[name][0]]).as_matrix()
        xmat = data.xmat[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)].reshape(3, 3)
        assert np.abs(rot[frame, j] @ r_off - xmat).max() < 1e-6, name
    hips = b_out.index(skel.roles["hips"])
    assert np.abs(pos[frame, hips] - world(b_src, skel.unit, skel.axes)[1][frame, hips] - SHIFT).max() < 1e-6
    others = [j for j in range(len(b_out.names)) if j not in drivers]
    assert np.abs(local_rotations(b_out)[frame, others] - local_rotations(b_src)[frame, others]).max() < 1e-6


def cmu_clip(tmp_path, name, seconds=0.5):
    return edit_bvh(MODELS / "cmu" / f"{name}.bvh", tmp_path / f"{name}.bvh", seconds=seconds)


def other_skeleton(tmp_path, name):
    """35_17's first half second on another convention (tests/bvh_conventions.py)."""
    return convention(cmu_clip(tmp_path, "35_17"), name, tmp_path / f"{name}.bvh")[0]


def root_at_offset(tmp_path):
    """The seated clip with a root of rotation channels only, standing at its OFFSET (48 cm up), as three.js's
    pirouette.bvh has it: the export gives the root position channels to carry the path's root."""
    head, motion = seated_clip(tmp_path / "seated.bvh").read_text().split("MOTION\n")
    root = "  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
    assert root in head
    head = head.replace(root, "  OFFSET 0 48 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n", 1)
    lines = motion.splitlines()
    out = tmp_path / "rooted.bvh"
    out.write_text(head + "MOTION\n" + "\n".join(lines[:2] + [" ".join(ln.split()[3:]) for ln in lines[2:]]) + "\n")
    return out


CLIPS = {"16_23": lambda p: cmu_clip(p, "16_23"), "35_17": lambda p: cmu_clip(p, "35_17"),
         "83_02": lambda p: cmu_clip(p, "83_02", 0.35), "ue5": lambda p: other_skeleton(p, "ue5"),
         "rokoko": lambda p: other_skeleton(p, "rokoko"), "lafan1": lambda p: other_skeleton(p, "lafan1"),
         "bandai": lambda p: other_skeleton(p, "bandai"), "max3ds": lambda p: other_skeleton(p, "max3ds"),
         "seated": lambda p: seated_clip(p / "seated.bvh"), "root at its offset": root_at_offset}


@pytest.mark.parametrize("name", sorted(CLIPS))
def test_a_path_through_the_capture_exports_to_the_source_at_its_keys(tmp_path, name):
    """Every joint within 0.1 mm of the source at every key where the path is the capture, by bvhio and by
    tests/bvh_fk.py; the changed key and the frames between keys are not the source (the change is
    written); the frames `export` reports are the file's, and its keyframe figures are the file's (as
    both readers measure them)."""
    from runner.capture.bvh import read_bvh
    from runner.capture.skeleton import recognise
    from runner.capture.source_export import export_on_source

    clip = CLIPS[name](tmp_path)
    npz, keys, moved = path_through_keys(tmp_path, clip)
    out = tmp_path / "back.bvh"
    res = export_on_source(npz, out)
    skel = recognise(read_bvh(clip))
    rest, unit = skel.rest_frames, skel.unit
    b_src, b_out = parse(clip), parse(out)
    assert res.frames == len(b_out.values) == int(out.read_text().split("Frames:")[1].split()[0])
    assert len(b_out.values) == rest + keys[-1] + 1  # the rest frames, then every frame to the last key
    names, p_src = bvhio_positions(clip)
    assert names == b_src.names and len(names) == len(read_bvh(clip).names)
    _, p_out = bvhio_positions(out)
    by_bvhio = np.linalg.norm(p_out[rest + keys] - p_src[rest + keys], axis=-1) * unit
    by_fk = np.linalg.norm(world(b_out, unit)[1][rest + keys] - world(b_src, unit)[1][rest + keys], axis=-1)
    kept = np.arange(len(keys)) != moved
    assert by_bvhio[kept].max() < AT_KEY and by_fk[kept].max() < AT_KEY, (by_bvhio[kept].max(), by_fk[kept].max())
    assert by_bvhio[moved].max() > 0.01  # the changed key is written as changed: the path's pose
    assert_change_written(npz, clip, out, rest + keys[moved])
    between = rest + (keys[:-1] + keys[1:]) // 2
    assert np.linalg.norm(p_out[between] - p_src[between], axis=-1).max() * unit > 0.01
    check = res.check  # what export reports: read from the file
    assert np.allclose(check.times, np.load(npz)["keyframe_times"]) and check.missed == 0
    assert np.abs(check.distance - by_fk).max() < 1e-6 and list(np.flatnonzero(check.moved)) == [moved]


def test_a_levelled_scene_and_another_rate(tmp_path):
    """The scene's levelling transform is taken off the root, and at 60 fps the file's keys (every other
    one of a 120 fps clip's keys every 6 frames lands on its frames: all of them) are the source's too."""
    from runner.capture.bvh import read_bvh
    from runner.capture.skeleton import recognise
    from runner.capture.source_export import export_on_source
    from solver.capture_frame import CaptureFrame

    clip = cmu_clip(tmp_path, "127_33", 0.4)
    npz, keys, moved = path_through_keys(tmp_path, clip, CaptureFrame.levelling(0.04, (0.02, -0.01)))
    out = tmp_path / "back.bvh"
    res = export_on_source(npz, out, fps=60.0)
    unit = recognise(read_bvh(clip)).unit
    b_src, b_out = parse(clip), parse(out)
    d = np.linalg.norm(world(b_out, unit)[1][1 + keys // 2] - world(b_src, unit)[1][1 + keys], axis=-1)
    kept = np.arange(len(keys)) != moved
    assert d[kept].max() < AT_KEY and d[moved].max() > 0.01
    assert res.frames == len(b_out.values) and np.abs(res.check.distance - d).max() < 1e-6


def test_the_runs_parse_writes_the_file_the_saved_text_does(tmp_path):
    """`mocap` hands the way back the clip it parsed: the file written is byte for byte the one written from
    the path's embedded text (`source_clip`), and the check reads that file back."""
    from runner.capture.clip import read_capture
    from runner.capture.source_export import export_on_source

    clip = cmu_clip(tmp_path, "16_23", 0.3)
    npz, _, _ = path_through_keys(tmp_path, clip)
    a, b = tmp_path / "a.bvh", tmp_path / "b.bvh"
    res_a = export_on_source(npz, a)
    res_b = export_on_source(npz, b, clip=read_capture(clip).clip)
    assert a.read_bytes() == b.read_bytes() and res_a.frames == res_b.frames
    assert np.array_equal(res_a.check.distance, res_b.check.distance)


@pytest.mark.slow
def test_mocap_reports_the_file_it_would_write(tmp_path):
    """`mocap` then `export`: the keyframe figures in the metrics report are the exported file's, read back
    independently; every key the import did not correct (its keyframe is the reference there) is within
    0.1 mm of the source, and the report finds a correction at every key moved."""
    import json

    from runner.cli import main
    from runner.saved_path import load_saved_path

    clip = cmu_clip(tmp_path, "16_23", 0.8)
    o = tmp_path / "o"
    assert main(["mocap", str(clip), "--out-dir", str(o), "--every", "0.25", "--no-render", "--max-evals", "20",
                 "--quiet", "--no-summary"]) == 0
    out = tmp_path / "back.bvh"
    assert main(["export", str(o / "16_23.npz"), "--to", str(out), "--quiet"]) == 0
    saved = load_saved_path(o / "16_23.npz")
    k = np.rint(saved.keyframe_times / saved.reference_times[1]).astype(int)
    a, b = parse(clip), parse(out)
    unit = 0.0254 / 0.45
    d = np.linalg.norm(world(b, unit)[1][1 + k] - world(a, unit)[1][1 + k], axis=-1)
    report = json.loads((o / "16_23.metrics.json").read_text())["keyframes_on_source"]
    assert report["max_mm"] == pytest.approx(1000 * d.max(), abs=0.01) and report["keys"] == len(k)
    assert report["keys_moved"] == int((d.max(axis=1) > AT_KEY).sum())
    # the keys as captured: the keyframe file's values (6 decimals) are the reference's, where the footplant did not move them
    as_captured = np.abs(saved.keyframes - saved.reference_qpos[k]).max(axis=1) < 1e-5
    assert as_captured.sum() >= 2 and d[as_captured].max() < AT_KEY
    assert report["unexplained_s"] == []  # every key moved is one the import changed


def test_a_root_correction_beyond_a_fitting_scenes_is_said(tmp_path):
    """The export takes the import's root-height correction off (--root-height source); where that was more
    than the 3 cm a scene fitted to the capture's feet needs (the import's 'all the same' warning), the file's
    feet are the capture's, not the solved path's, and export says so in a line naming the size and time, as
    measured on the file read back (its hips against the path's root)."""
    from runner.capture.source_export import export_on_source

    clip = cmu_clip(tmp_path, "35_17")
    npz, _, _ = path_through_keys(tmp_path, clip)
    assert export_on_source(npz, tmp_path / "a.bvh").notes == ()  # the capture's own root: nothing to say
    saved = dict(np.load(npz))
    ref_t, ref_q = saved["reference_times"], saved["reference_qpos"].copy()
    lifted = (ref_t > 0.2) & (ref_t < 0.3)
    ref_q[lifted, 2] += 0.08  # the import lifted the root 8 cm over these frames
    saved["reference_qpos"] = ref_q
    np.savez(npz, **saved)
    notes = export_on_source(npz, tmp_path / "b.bvh").notes
    found = re.search(r"up to (\d+) mm \((\d\.\d\d) s\) from the path's root, read back", notes[0]) if len(notes) == 1 else None
    assert found, notes  # 80 mm on top of the import's own correction, which is at most 30 mm (no note above)
    assert 50 <= int(found.group(1)) <= 110 and 0.2 <= float(found.group(2)) <= 0.3
    assert export_on_source(npz, tmp_path / "c.bvh", as_solved=True).notes == ()


def test_the_corrections_at_a_key_are_named_the_root_the_footplant_lowered_too():
    """A key the footplant moved only by lowering the root (a near-straight leg then bends to hold its foot:
    a knee 11 mm off for a 0.33 mm drop) names the root, not "none"."""
    from runner.capture.source_check import corrections_text

    assert corrections_text({}, {"root": 0.33}, [], False) == "root lowered 0.33 mm by the footplant"
    assert corrections_text({"l_elbow": 13.2}, {"right": 10.4, "root": 6.0}, ["r_ankle"], True) == (
        "l_elbow 13.2 deg, right foot lowered 10.4 mm, root lowered 6.00 mm by the footplant, r_ankle glitch repaired, a partial key")
    assert corrections_text({}, {}, [], False) == "none at that key"
