"""Blender opens the exports as a user would: `dynsplines export` of run-and-step (the shipped keyframes)
and of a motion-capture clip to BVH and glb, each imported with Blender's default importer (BVH with
"Update Scene FPS", docs/export.md) by `blender_import.py` in Blender's own Python (`bpy` from PyPI, in
its own virtual environment: it pins its Python and numpy).

What is checked, against references that do not come from the exporter:
* names: the armature's bones are the BVH file's ROOT/JOINT names; the glb imports as an armature whose
  bones are the figure's bodies (the MJCF's), parented as its body tree, and objects for its other nodes;
* time: the keyed frames over the scene's frame rate are the file's sample times (BVH: `Frames` and
  `Frame Time`; glb: the animation's input accessor);
* the figure on the floor: its lowest point over the animation within 2 cm of z = 0;
* size: the BVH rest armature's height is the file's (OFFSETs summed along the Y-up chains) and a
  person's, in metres; the glb figure's vertical extent at each key is MuJoCo's for the path at that time
  (the exact extent of each capsule and ellipsoid, `mj_kinematics`);
* the motion: the pelvis' displacement from its start at each key is the saved path's root displacement
  (the natural cubic spline through the saved frames, scipy), within 1 cm; the glb's bones at each key
  are where MuJoCo puts the bodies for the path at that time (within 1 mm), and its skinned meshes as
  Blender deforms them have MuJoCo's vertical extent.

Blender's interpreter: $DYNSPLINES_BPY_PYTHON, else .venv-bpy/bin/python in the checkout (.ci/run and the
README's "Full test suite" install it).
"""
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pygltflib
import pytest
from scipy.interpolate import CubicSpline

ROOT = Path(__file__).resolve().parents[2]
BPY_PYTHON = Path(os.environ.get("DYNSPLINES_BPY_PYTHON", ROOT / ".venv-bpy" / "bin" / "python"))
SCRIPT = Path(__file__).with_name("blender_import.py")
FIGURE = ROOT / "models" / "humanoid39.xml"
UNIT = 0.0254 / 0.45  # metres per unit of the CMU BVH clips (models/cmu/README.md "Units")

pytestmark = [pytest.mark.slow, pytest.mark.client]

# the command's own solves (a few seconds each): the floor check below reads where the solved feet are, and a
# subproblem cut short by --max-evals may leave a foot in the floor (reported out of reach)
_SOLVE = ["--no-render", "--quiet", "--no-summary", "--save-path", "path.npz"]
CLIPS = {
    "run-and-step": ["run-and-step", *_SOLVE],
    "mocap": ["mocap", str(ROOT / "models" / "cmu" / "127_33.bvh"), "--every", "0.25", "--out-dir", "mocap", *_SOLVE],
}


def _dynsplines(*args, cwd):
    res = subprocess.run([sys.executable, "-m", "runner", *args], cwd=cwd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, f"dynsplines {' '.join(args)}:\n{res.stdout}\n{res.stderr}"


@pytest.fixture(scope="module", params=sorted(CLIPS))
def exported(request, tmp_path_factory):
    """Folder with path.npz (the saved path), path.bvh and path.glb exported from it by `dynsplines export`."""
    if not BPY_PYTHON.is_file():
        pytest.skip(f"Blender's bpy is not installed ({BPY_PYTHON} missing): python3 -m venv .venv-bpy && "
                    ".venv-bpy/bin/pip install bpy==5.0.1, or set DYNSPLINES_BPY_PYTHON to a Python that imports bpy; "
                    'README "Full test suite"')
    out = tmp_path_factory.mktemp(request.param)
    _dynsplines(*CLIPS[request.param], cwd=out)
    for ext in ("bvh", "glb"):
        _dynsplines("export", "path.npz", "--to", f"path.{ext}", cwd=out)
    return out


def blender_import(path):
    """What `blender_import.py` printed for one file (a dict, see there)."""
    res = subprocess.run([str(BPY_PYTHON), str(SCRIPT), str(path)], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, f"Blender could not import {path}:\n{res.stderr[-3000:]}"
    return json.loads(res.stdout.strip().splitlines()[-1])


def root_spline(npz):
    """(t0, spline of the root position (3,) [m] in MuJoCo axes): the optimized path's root."""
    with np.load(npz) as z:
        times, frames = z["frame_times"], z["frames"]
    return float(times[0]), CubicSpline(times, frames[:, :3], bc_type="natural")


def capture_frame(npz):
    """The transform from the capture's coordinates to the saved path's scene (`solver.capture_frame`)."""
    import mujoco

    from runner.saved_path import load_saved_path
    from solver.capture_frame import CaptureFrame

    return CaptureFrame.from_model(mujoco.MjModel.from_xml_path(str(load_saved_path(npz).scene_path)))


def root_correction_m(npz, t):
    """(n, 3) [m] MuJoCo axes: the reference's root height correction at times t that the export onto the
    source skeleton takes off the root (`runner.capture.source_export.root_correction`)."""
    from bvh_fk import AXES, UNIT

    from runner.capture.figure_record import clip_skeleton
    from runner.capture.source_export import root_correction, source_clip
    from runner.saved_path import load_saved_path

    saved = load_saved_path(npz)
    model = mujoco.MjModel.from_xml_path(str(saved.scene_path))
    clip = source_clip(saved)
    skel = clip_skeleton(clip, model)[0]  # a CMU clip: its axes and unit are bvh_fk's AXES and UNIT
    c = root_correction(clip, skel, model, (saved.reference_times, saved.reference_qpos), t)
    return c @ AXES.T * UNIT


def assert_root_travel(pelvis, t, npz, in_capture=False):
    """pelvis: (n, 3) [m] world positions in Blender at times t (n,) [s] from the path's start; in_capture:
    the file is in the capture's coordinates (the source skeleton), the path in its scene's levelled frame."""
    t0, spline = root_spline(npz)
    ref = spline(t0 + t)
    if in_capture:  # the export also takes off the reference's height correction (docs/mocap.md)
        ref = capture_frame(npz).inverse().points(ref) - root_correction_m(npz, t0 + t)
    got_d = np.linalg.norm(pelvis - pelvis[0], axis=1)
    ref_d = np.linalg.norm(ref - ref[0], axis=1)
    assert ref_d[-1] > 0.5, ref_d[-1]  # the clips travel: a test of a standing figure would prove little
    assert abs(got_d[-1] - ref_d[-1]) < 0.01, (got_d[-1], ref_d[-1])  # the travel
    assert np.abs(got_d - ref_d).max() < 0.01, np.abs(got_d - ref_d).max()  # and at every key
    assert np.abs((pelvis[:, 2] - pelvis[0, 2]) - (ref[:, 2] - ref[0, 2])).max() < 0.01  # up is up


# ------------------------------------------------------------------------------------------------ BVH
def read_bvh(path):
    """Joint names (file order), frame count, frame time [s] and the rest skeleton's vertical extent
    (min, max) of Y (the BVH's up axis) over joints and end sites, from the file's text."""
    text = Path(path).read_text()
    head, motion = text.split("MOTION", 1)
    names, stack, ys = [], [np.zeros(3)], []
    for line in head.splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] in ("ROOT", "JOINT"):
            names.append(words[1])
        elif words[0] == "OFFSET":
            pos = stack[-1] + np.array(words[1:4], float)
            stack.append(pos)
            ys.append(pos[1])
        elif words[0] == "}":
            stack.pop()
    frames = int(re.search(r"Frames:\s*(\d+)", motion).group(1))
    frame_time = float(re.search(r"Frame Time:\s*([0-9.eE+-]+)", motion).group(1))
    return names, frames, frame_time, (min(ys), max(ys))


def _source_text(npz):
    """The source clip's text stored in a saved path ("" for a path not made from a clip)."""
    with np.load(npz) as z:
        return str(z["clip_text"]) if "clip_text" in z.files else ""


def test_blender_imports_the_bvh(exported):
    path = exported / "path.bvh"
    names, n, dt, (ylo, yhi) = read_bvh(path)
    got = blender_import(path)
    [(arm, bones)] = got["bones"].items()
    assert bones == names  # the armature's bones are the file's joints, whichever skeleton it writes
    assert got["frame_ranges"] == [[1.0, float(n)]] and got["frames"] == [float(f) for f in range(1, n + 1)]
    assert abs(got["fps"] * dt - 1.0) < 1e-4, (got["fps"], dt)
    lo, hi = got["rest"][arm]
    assert abs((hi - lo) - (yhi - ylo)) < 1e-3, (hi - lo, yhi - ylo)  # upright: the file's Y is Blender's Z
    lowest = min(got["zmin"][arm])
    source = _source_text(exported / "path.npz")
    if source:
        (exported / "source.bvh").write_text(source)
        src_names, _, src_dt, _ = read_bvh(exported / "source.bvh")
        # a clip's path on the subject's figure goes onto the source skeleton; run-and-step's (the shipped
        # figure, its keyframes made from a clip) onto the figure's own (docs/export.md)
        assert (names == src_names) == exported.name.startswith("mocap"), (names[:3], src_names[:3])
        source = source if names == src_names else ""
    if source:  # on the source skeleton (docs/export.md): it imports in place of the source clip
        assert abs(dt - src_dt) < 1e-9  # same joints, same frame rate
        src = blender_import(exported / "source.bvh")
        [src_arm] = src["bones"]
        assert np.allclose(got["rest"][arm], src["rest"][src_arm], atol=1e-3)  # the same rest pose
        # on the capture's floor: the lowest point over the animation within 2 cm of the source's [m]
        src_lowest = min(src["zmin"][src_arm])
        assert abs(lowest - src_lowest) * UNIT < 0.02, (lowest * UNIT, src_lowest * UNIT)
        scale = UNIT  # the source's units, as a user who imports the source sees them
    else:
        assert abs(lowest) < 0.02, lowest  # the figure stands on the floor, neither under it nor above it
        scale = 1.0
    assert 1.4 < (hi - lo) * scale < 2.1, (hi - lo) * scale  # a person's height in metres
    pelvis = np.array(got["bone_heads"][f"{arm}/{names[0]}"]) * scale
    skip = 1 if source else 0  # on the source skeleton the first frame is the source's T-pose, as in the clip
    assert_root_travel(pelvis[skip:], np.arange(n - skip) * dt, exported / "path.npz", in_capture=bool(source))


# ------------------------------------------------------------------------------------------------ glb
def _accessor(gltf, i):
    a = gltf.accessors[i]
    v = gltf.bufferViews[a.bufferView]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[a.type]
    return np.frombuffer(gltf.binary_blob(), np.float32, a.count * width, v.byteOffset + (a.byteOffset or 0))


def mujoco_extent(model, data, qpos, geoms):
    """(zmin, zmax) [m] of the given geoms (capsules, ellipsoids, spheres, boxes) at qpos: exact
    support functions along z of the posed primitives (`mj_kinematics` normalizes the quaternions)."""
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    lo, hi = np.inf, -np.inf
    T = mujoco.mjtGeom
    for g in geoms:
        Rz = data.geom_xmat[g].reshape(3, 3)[2]  # z components of the geom's axes
        s = model.geom_size[g]
        kind = model.geom_type[g]
        if kind == T.mjGEOM_CAPSULE:
            h = abs(Rz[2]) * s[1] + s[0]
        elif kind == T.mjGEOM_ELLIPSOID:
            h = float(np.sqrt(np.sum((Rz * s) ** 2)))
        elif kind == T.mjGEOM_SPHERE:
            h = s[0]
        elif kind == T.mjGEOM_BOX:
            h = float(np.abs(Rz * s).sum())
        else:
            raise AssertionError(f"geom type {kind} has no reference extent here")
        z = data.geom_xpos[g][2]
        lo, hi = min(lo, z - h), max(hi, z + h)
    return lo, hi


#: (3, 3) MuJoCo world -> Blender world after the glTF round trip: both are z up; the figure's forward,
#: MuJoCo +x, is glTF +Z (docs/export.md) and Blender -Y (Blender's importer: glTF +Y up -> +Z, +Z -> -Y).
MUJOCO_TO_BLENDER = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _figure_model(exported):
    """The path's own figure (a subject's, for a clip): its MJCF as MuJoCo reads it, and the path's
    optimized qpos spline."""
    with np.load(exported / "path.npz") as z:
        figure = exported / str(z["figure"]) if "figure" in z.files and str(z["figure"]) else FIGURE
        spline = CubicSpline(z["frame_times"], z["frames"], bc_type="natural")
        t0 = float(z["frame_times"][0])
    return mujoco.MjModel.from_xml_path(str(figure)), lambda t: spline(t0 + t)


def test_blender_imports_the_glb(exported):
    path = exported / "path.glb"
    gltf = pygltflib.GLTF2.load_binary(str(path))
    anim = gltf.animations[0]
    times = _accessor(gltf, anim.samplers[0].input).astype(float)
    model, qpos_at = _figure_model(exported)
    body = lambda b: mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(b))  # noqa: E731
    tree = {body(b): body(model.body_parentid[b]) if model.body_parentid[b] else None for b in range(1, model.nbody)}

    got = blender_import(path)
    [(arm, bones)] = got["bones"].items()  # one armature: the skin, its bones the figure's bodies
    assert len(bones) == len(tree) == 12 and got["bone_parents"][arm] == tree, got["bone_parents"]
    skinned = [n.name for n in gltf.nodes if n.skin is not None]
    assert skinned and all(got["objects"][m] == "MESH" for m in skinned)
    joints = {gltf.nodes[j].name for skin in gltf.skins for j in skin.joints}
    assert set(got["objects"]) == {n.name for n in gltf.nodes} - joints  # the other nodes are objects
    fps = got["fps"]
    assert np.abs(np.array(got["frames"]) / fps - times).max() < 1e-4  # keys at the file's times [s]
    [(f0, f1)] = got["frame_ranges"]
    assert abs(f0 / fps - times[0]) < 1e-4 and abs(f1 / fps - times[-1]) < 1e-4, (f0, f1, fps)

    data = mujoco.MjData(model)
    qpos = qpos_at(times)
    heads = np.array([got["bone_heads"][f"{arm}/{b}"] for b in bones]).transpose(1, 0, 2)  # (n, 12, 3)
    ref_heads = []
    for q in qpos:  # the bodies' origins (the bones' heads) where MuJoCo puts them
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        ref_heads.append([MUJOCO_TO_BLENDER @ data.xpos[model.body(b).id] for b in bones])
    assert np.abs(heads - np.array(ref_heads)).max() < 1e-3, np.abs(heads - np.array(ref_heads)).max()
    feet = np.linalg.norm(heads[:, bones.index("l_foot")] - heads[:, bones.index("r_foot")], axis=1)
    assert np.ptp(feet) > 0.1, np.ptp(feet)  # the bones move relative to each other: the legs swing [m]

    zmin = np.min([got["zmin"][m] for m in skinned], axis=0)
    zmax = np.max([got["zmax"][m] for m in skinned], axis=0)
    assert abs(zmin.min()) < 0.02, zmin.min()  # on the floor at some time, never deeper than 2 cm
    geoms = [g for g in range(model.ngeom) if f"geom_{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)}" in skinned]
    assert len(geoms) == len(skinned), "the glb's figure meshes are the figure's geoms"
    ref = np.array([mujoco_extent(model, data, q, geoms) for q in qpos])
    # tolerance: the meshes are 20-gons inscribed in the exact surfaces (at most 1.3 % of a radius inside)
    assert np.abs(zmin - ref[:, 0]).max() < 3e-3, np.abs(zmin - ref[:, 0]).max()
    assert np.abs(zmax - ref[:, 1]).max() < 3e-3, np.abs(zmax - ref[:, 1]).max()
    height = zmax[0] - zmin[0]
    assert 1.3 < height < 2.2, height  # metres (a running figure, a little under its standing 1.75 m)
    assert_root_travel(heads[:, bones.index("pelvis")], times, exported / "path.npz")
