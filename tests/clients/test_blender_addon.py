"""The Blender add-on as a user drives it: `dynsplines blender-addon` writes the zip, Blender installs it
as an extension, imports a shipped CMU clip with its own BVH importer and runs the operators headless
(`blender_addon_run.py` in Blender's Python; `bpy` as CI installs it, see test_blender.py).

What is checked, against references that do not come from the add-on or the solve:
* in-between: the clip's action thinned to six keys (an animator's keyed frames), run twice; the new
  action `<action>.dynsplines` exists once (the second run replaced the first's, solving the keys
  again, not the bake), is assigned, the original is kept, and it is baked at every frame from
  the first key to the last; at the keyed frames every bone's head and tail is where the original action
  puts it (within 1 mm, world positions in Blender); between the keys it is not Blender's own
  interpolation (the solve moved it); no foot is more than 1 mm below Blender's floor (z = 0) where the
  keys do not put it lower (a key with a foot in the floor: its limit there is the key's own,
  docs/design.md), measured as below; a selected cube is the scene's box, in metres;
* the in-between and the clean after the clip went through Blender's FBX exporter and importer (another
  rig: FBX's bone orientations, leaf bones);
* clean: at the keyframes `mocap` picked, the bones that drive the figure's leg bodies are where MuJoCo
  puts those bodies for the keyframe poses (within 1 mm); the feet are never more than 1 mm below Blender's
  floor (z = 0), measured at the figure's contact spheres carried on Blender's foot bones (their offset
  from the bone taken from the retargeted capture, by MuJoCo, at one frame);
* cancelled after the solve's first round (as Esc does): the new action is there and meets the keys;
* a rig whose bones have no convention's names (so no named length unit) is solved at an assumed size and
  meets the keys (1 mm), with the command's warning of the assumed unit as a warning report; with a
  skeleton map file in the panel giving what the names no longer say (the unit) it is solved and meets
  the keys, and a partial key there (only the hips and the left leg keyed at one frame) meets those bones
  (1 mm) and leaves the right leg free; a map whose unit is no unit gives an error report with the
  command's one line (bpy.ops raises RuntimeError with the report), not a traceback, and no new action.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
BPY_PYTHON = Path(os.environ.get("DYNSPLINES_BPY_PYTHON", ROOT / ".venv-bpy" / "bin" / "python"))
SCRIPT = Path(__file__).with_name("blender_addon_run.py")
CLIP = ROOT / "models" / "cmu" / "127_33.bvh"
UNIT = 0.0254 / 0.45  # metres per unit of the CMU BVH clips (models/cmu/README.md "Units")
#: scene frames keyed in the in-between test: Blender's importer puts the clip's T-pose at frame 1 and its
#: motion at 2..206 (205 frames at 120 fps); six keys about 0.33 s apart
KEYS = (2, 42, 82, 122, 162, 206)
FEET = {"l": "LeftFoot", "r": "RightFoot"}
#: the figure's leg bodies and the CMU joints that drive them (their origins are the joints' places; the arms'
#: are not: the figure's shoulder and elbow sit where the merged clavicle chain puts them)
DRIVEN = {"pelvis": "Hips", "l_thigh": "LeftUpLeg", "l_shin": "LeftLeg", "l_foot": "LeftFoot",
          "r_thigh": "RightUpLeg", "r_shin": "RightLeg", "r_foot": "RightFoot"}

pytestmark = [pytest.mark.slow, pytest.mark.client]


@pytest.fixture(scope="module")
def addon(tmp_path_factory):
    """(the add-on zip, the `dynsplines` command) for Blender."""
    if not BPY_PYTHON.is_file():
        pytest.skip(f"Blender's bpy is not installed ({BPY_PYTHON} missing): python3 -m venv .venv-bpy && "
                    ".venv-bpy/bin/pip install bpy==5.0.1, or set DYNSPLINES_BPY_PYTHON to a Python that imports bpy; "
                    'README "Full test suite"')
    cli = Path(sys.executable).parent / "dynsplines"
    if not cli.is_file():
        pytest.skip(f"the dynsplines command is not installed next to {sys.executable} (pip install -e .)")
    out = tmp_path_factory.mktemp("addon") / "dynsplines-addon.zip"
    res = subprocess.run([sys.executable, "-m", "runner", "blender-addon", "--out", str(out)], capture_output=True,
                         text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    return out, cli


def run_blender(addon, mode, tmp_path, keys=()):
    """What `blender_addon_run.py` printed (a dict, see there); the command's files kept in tmp_path/files."""
    zip_path, cli = addon
    argv = [str(BPY_PYTHON), str(SCRIPT), str(zip_path), str(cli), str(CLIP), mode, ",".join(map(str, keys)),
            str(tmp_path / "files"), ",".join(FEET.values())]
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender-user"))  # the extension installs here
    res = subprocess.run(argv, capture_output=True, text=True, timeout=300, env=env)
    assert res.returncode == 0, f"Blender failed:\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    *printed, last = res.stdout.strip().splitlines()
    return dict(json.loads(last), printed=printed)  # printed: Blender's own lines, its reports among them


def assert_result_action(got, first, last):
    name = got["original"] + ".dynsplines"
    assert got["error"] is None, got["error"]
    assert got["assigned"] == name and got["original"] in got["actions"], got["actions"]
    assert got["frames"] == list(range(first, last + 1))  # baked at every frame


def key_error(got):
    """[m] the largest distance of any bone's head or tail in the result action from the original's at the KEYS
    (Blender's world positions, in CMU units times UNIT)."""
    frames = got["frames"]
    result, original = np.array(got["result_points"]), np.array(got["original_points"])
    at_keys = [frames.index(k) for k in KEYS]
    return float(np.linalg.norm(result[at_keys] - original[at_keys], axis=-1).max() * UNIT)


def lowest_contact_mm(got, files):
    """({scene frame: [mm]} the height over Blender's z = 0 of the lowest point of the figure's contact
    spheres, carried on the result's foot bones (negative: below). Each site's place on its foot bone: the foot body's
    orientation relative to the bone in the retargeted capture (MuJoCo's kinematics of the saved path's
    reference at its first frame) times the site's offset in the body (the figure's MJCF). A rest frame
    before the motion (clean: the clip's T-pose, copied) is left out."""
    with np.load(files / "path.npz") as z:
        ref0 = z["reference_qpos"][0]
        ref_t = z["reference_times"]
    model = mujoco.MjModel.from_xml_path(str(next(files.glob("*.scene.xml"))))
    data = mujoco.MjData(model)
    data.qpos[:] = ref0
    mujoco.mj_kinematics(model, data)
    first = got["frames"][-1] - (len(ref_t) - 1)  # the scene frame of the reference's first frame
    original = np.array(got["feet_original"])[got["frames"].index(first)]
    result = np.array(got["feet_result"])[got["frames"].index(first):]  # (n, 2, 4, 4) world [Blender units]
    lowest = np.full(len(result), np.inf)
    for j, side in enumerate(FEET):
        body = model.body(f"{side}_foot").id
        bone = original[j, :3, :3] / np.linalg.norm(original[j, :3, 0])
        offset = bone.T @ data.xmat[body].reshape(3, 3)  # body frame in the bone's, constant
        for site in ("heel", "toe"):
            s = model.site(f"{side}_{site}")
            try:  # a rounded contact (docs/contacts.md "Rounded contacts"), else a point
                radius = float(model.numeric(f"figure:radius:{side}_{site}").data[0])
            except KeyError:
                radius = 0.0
            rot = result[:, j, :3, :3] / np.linalg.norm(result[:, j, :3, 0], axis=-1)[:, None, None]
            pos = result[:, j, :3, 3] * UNIT + rot @ offset @ model.site_pos[s.id]
            lowest = np.minimum(lowest, pos[:, 2] - radius)
    return dict(zip(got["frames"][got["frames"].index(first):], 1000.0 * lowest, strict=True))


def test_inbetween_keeps_the_keys(addon, tmp_path):
    got = run_blender(addon, "rerun", tmp_path, KEYS)  # run twice: the second solves the keys again
    assert got["actions"] == [got["original"], got["original"] + ".dynsplines"]  # the result replaced
    assert_inbetween(got, tmp_path, "in-between")
    # the selected cube (x 49..51, y -2..2, z 0..2 Blender units, off the path) is the scene's box [m]
    model = mujoco.MjModel.from_xml_path(str(next((tmp_path / "files").glob("*.scene.xml"))))
    [box] = [g for g in range(model.ngeom) if model.geom_bodyid[g] == 0 and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX]
    assert np.allclose(model.geom_pos[box], np.array([50.0, 0.0, 1.0]) * UNIT, atol=1e-5), model.geom_pos[box]
    assert np.allclose(model.geom_size[box], np.array([1.0, 2.0, 1.0]) * UNIT, atol=1e-5), model.geom_size[box]


def test_inbetween_after_an_fbx_round_trip(addon, tmp_path):
    """The clip through Blender's FBX exporter and importer (FBX's bone orientations and leaf bones)."""
    got = run_blender(addon, "fbx", tmp_path, KEYS)
    assert any(b.endswith("_end") for b in got["bones"])  # the FBX importer's leaf bones: another rig
    assert_inbetween(got, tmp_path, "FBX in-between")


def assert_inbetween(got, tmp_path, label):
    """The in-between's result: the action, the keys (1 mm), the solve's own motion, the floor."""
    assert_result_action(got, KEYS[0], KEYS[-1])
    frames = got["frames"]
    result, original = np.array(got["result_points"]), np.array(got["original_points"])  # (n, 2 B, 3)
    at_keys = [frames.index(k) for k in KEYS]
    err = np.linalg.norm(result[at_keys] - original[at_keys], axis=-1).max() * UNIT
    print(f"{label}: {len(KEYS)} keys, bones within {1000 * err:.4f} mm of the keys")
    assert err < 1e-3, err  # [m]
    moved = np.linalg.norm(result - original, axis=-1).max() * UNIT
    assert moved > 0.01, moved  # [m] between the keys the solve, not Blender's Bezier curves
    low = lowest_contact_mm(got, tmp_path / "files")
    keyed = min(low[k] for k in KEYS)  # a key may put a foot in the floor (its limit is then the key's own)
    print(f"{label}: lowest contact sphere {min(low.values()):.2f} mm above z = 0 (the keys' {keyed:.2f} mm)")
    assert min(low.values()) > min(0.0, keyed) - 1.0, (min(low.values()), keyed)


@pytest.mark.parametrize("mode", ["clean", "fbx-clean"])
def test_clean_stands_on_the_floor(addon, tmp_path, mode):
    got = run_blender(addon, mode, tmp_path)
    files = tmp_path / "files"
    with np.load(files / "path.npz") as z:
        key_t, key_q, ref_t = z["keyframe_times"], z["keyframes"], z["reference_times"]
    last = got["frames"][-1]
    assert_result_action(got, last - len(ref_t), last)  # the T-pose frame before the motion, as imported
    model = mujoco.MjModel.from_xml_path(str(next(files.glob("*.scene.xml"))))
    data = mujoco.MjData(model)
    fps = (len(ref_t) - 1) / ref_t[-1]
    bones = got["bones"]
    result = np.array(got["result_points"])
    worst = 0.0
    for t, q in zip(key_t, key_q, strict=True):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        row = got["frames"].index(last - len(ref_t) + 1 + int(round(t * fps)))
        for body, joint in DRIVEN.items():
            worst = max(worst, float(np.linalg.norm(result[row, bones.index(joint)] * UNIT - data.xpos[model.body(body).id])))
    print(f"{mode}: {len(key_t)} keyframes, driving bones within {1000 * worst:.4f} mm of MuJoCo's bodies")
    assert worst < 1e-3, worst  # [m]
    low = min(lowest_contact_mm(got, files).values())
    print(f"{mode}: lowest contact sphere {low:.2f} mm above z = 0")
    assert low > -1.0, low


def test_unknown_bones_are_solved_at_an_assumed_size_with_a_warning(addon, tmp_path):
    got = run_blender(addon, "unknown", tmp_path, KEYS)
    assert_result_action(got, KEYS[0], KEYS[-1])
    warned = [ln for ln in got["printed"] if ln.startswith("Warning: dynsplines: warning:")]  # Blender's report line
    assert any("cannot tell the length unit" in ln for ln in warned), got["printed"][-20:]
    assert all(len(ln) < 1000 and "Traceback" not in ln for ln in warned), warned
    err = key_error(got)
    print(f"unknown bones: {warned[0]}; bones within {1000 * err:.4f} mm of the keys")
    assert err < 1e-3, err  # [m]


def test_a_bad_skeleton_map_gives_the_report(addon, tmp_path):
    got = run_blender(addon, "badmap", tmp_path, KEYS)
    assert "furlong" in (got["error"] or ""), got["error"]
    assert got["error"] is not None and "dynsplines: error:" in got["error"], got["error"]
    assert "Traceback" not in got["error"] and len(got["error"].strip().splitlines()) == 1, got["error"]
    assert got["actions"] == [got["original"]] and got["assigned"] == got["original"]  # nothing new


def test_a_mapped_rig_with_a_partial_key(addon, tmp_path):
    """The renamed rig with a skeleton map file in the panel giving the unit (the roles come from the
    hierarchy), and at frame 82 only the hips and the left leg keyed (a partial key): the full keys are
    met, at the partial key those bones are where it puts them and the right leg is the solve's."""
    left = ("Hips", "LHipJoint", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase")
    keys = [f"{f}:{'+'.join(left)}" if f == 82 else str(f) for f in KEYS]
    got = run_blender(addon, "mapped", tmp_path, keys)
    assert_result_action(got, KEYS[0], KEYS[-1])
    frames, bones, n = got["frames"], got["bones"], len(got["bones"])  # bones: the names as imported
    result, original = np.array(got["result_points"]), np.array(got["original_points"])
    err = np.linalg.norm(result - original, axis=-1) * UNIT  # (frames, 2 B) [m]
    full = [frames.index(k) for k in KEYS if k != 82]
    keyed = [i for b in left for i in (bones.index(b), n + bones.index(b))]  # heads and tails
    right = [i for b in ("RightLeg", "RightFoot") for i in (bones.index(b), n + bones.index(b))]
    print(f"mapped rig, partial key: full keys within {1000 * err[full].max():.4f} mm; at the partial key the "
          f"keyed bones within {1000 * err[frames.index(82), keyed].max():.4f} mm, the right leg "
          f"{1000 * err[frames.index(82), right].max():.1f} mm from Blender's interpolation")
    assert err[full].max() < 1e-3 and err[frames.index(82), keyed].max() < 1e-3
    assert err[frames.index(82), right].max() > 1e-3  # free at the partial key: not Blender's curves


def test_cancel_returns_a_valid_action(addon, tmp_path):
    """Esc after the solve's first round (the add-on's SolveRun polled as its timer does): the best path so
    far comes back as the new action, and it still meets the keys."""
    got = run_blender(addon, "cancel", tmp_path, KEYS)
    assert_result_action(got, KEYS[0], KEYS[-1])
    err = key_error(got)
    print(f"cancelled: bones within {1000 * err:.4f} mm of the keys")
    assert err < 1e-3, err  # [m]
    assert np.isfinite(np.array(got["result_points"])).all()
