"""glTF export: node transforms at the sampled times are MuJoCo's body poses; meshes are closed and face
outward; the Khronos validator finds no error or warning (a `client` test: skipped without node and
gltf-validator, a failure then in CI)."""
import json
import os
import shutil
import subprocess
from pathlib import Path

import mujoco
import numpy as np
import pygltflib
import pytest

from runner.export.gltf import MUJOCO_TO_GLTF, WORLD_ROTATION, Track, figure_gltf, geom_mesh, glb_bytes, write_glb
from runner.export.sampling import default_fps, sample_motion
from runner.saved_path import load_saved_path
from solver.layout import StateLayout

_TYPES = {5126: np.float32, 5123: np.uint16, 5125: np.uint32}
_WIDTH = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}


def accessor(gltf, i):
    a = gltf.accessors[i]
    v = gltf.bufferViews[a.bufferView]
    blob = gltf.binary_blob()
    out = np.frombuffer(blob, _TYPES[a.componentType], a.count * _WIDTH[a.type], v.byteOffset + (a.byteOffset or 0))
    return out.reshape(a.count, -1)


def qmat(q_wxyz):
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, np.asarray(q_wxyz, float))
    return R.reshape(3, 3)


def world_poses(gltf, anim, k):
    """{node name: (position (3,), rotation matrix (3, 3))} in glTF world axes at key k of animation anim."""
    local = {}
    for ch in anim.channels:
        local.setdefault(ch.target.node, {})[ch.target.path] = accessor(gltf, anim.samplers[ch.sampler].output)[k]
    parent = {c: i for i, n in enumerate(gltf.nodes) for c in (n.children or [])}
    out = {}

    def pose(i):
        n = gltf.nodes[i]
        t = np.array(local.get(i, {}).get("translation", n.translation or [0, 0, 0]), float)
        q = np.array(local.get(i, {}).get("rotation", n.rotation or [0, 0, 0, 1]), float)
        R = qmat(q[[3, 0, 1, 2]])
        if i not in parent:
            return t, R
        pt, pR = pose(parent[i])
        return pt + pR @ t, pR @ R

    for i, n in enumerate(gltf.nodes):
        out[n.name] = pose(i)
    return out


def test_world_rotation_is_the_axis_change():
    assert np.allclose(qmat(np.array(WORLD_ROTATION)[[3, 0, 1, 2]]), MUJOCO_TO_GLTF)


@pytest.mark.parametrize("which", ["optimized", "reference"])
def test_node_transforms_equal_mujoco_body_poses(tmp_path, saved_npz, scene_model, which):
    model = scene_model
    saved = load_saved_path(saved_npz)
    motion = sample_motion(saved, which, 30.0, StateLayout.from_model(model).quat_slots)
    out = tmp_path / "clip.glb"
    write_glb(out, model, [Track(which, motion.times, motion.qpos)])
    gltf = pygltflib.GLTF2.load_binary(str(out))
    anim = gltf.animations[0]
    keys = accessor(gltf, anim.samplers[0].input)[:, 0]
    assert np.allclose(keys, motion.times - motion.times[0], atol=1e-6)
    assert all(s.interpolation == "LINEAR" for s in anim.samplers)
    data = mujoco.MjData(model)
    M = MUJOCO_TO_GLTF
    for k in range(0, len(motion.times), 4):
        data.qpos[:] = motion.qpos[k]
        mujoco.mj_kinematics(model, data)
        poses = world_poses(gltf, anim, k)
        for b in range(1, model.nbody):
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b)
            p, R = poses[name]
            assert np.abs(p - M @ data.xpos[b]).max() < 1e-5, (name, k)
            assert np.abs(R - M @ qmat(data.xquat[b])).max() < 1e-5, (name, k)


def test_several_tracks_and_sites_are_named_apart(saved_npz, scene_model):
    saved = load_saved_path(saved_npz)
    slots = StateLayout.from_model(scene_model).quat_slots
    tracks = [Track(w, *(lambda m: (m.times, m.qpos))(sample_motion(saved, w, 20.0, slots)))
              for w in ("optimized", "plain")]
    gltf = figure_gltf(scene_model, tracks, sites=("l_heel", "r_toe"))
    names = [n.name for n in gltf.nodes]
    assert len(set(names)) == len(names)
    assert {"optimized_pelvis", "plain_pelvis", "plain_site_l_heel", "optimized_site_r_toe"} <= set(names)
    assert [a.name for a in gltf.animations] == ["optimized", "plain"]


def test_meshes_are_closed_and_face_outward(scene_model):
    """Signed volume of every closed primitive is positive and near the analytic volume."""
    T = mujoco.mjtGeom
    for g in range(scene_model.ngeom):
        kind, size = int(scene_model.geom_type[g]), scene_model.geom_size[g]
        if kind == int(T.mjGEOM_PLANE):
            continue
        pos, nrm, idx = geom_mesh(scene_model, g)
        tri = pos[idx.reshape(-1, 3)]
        vol = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
        exact = {int(T.mjGEOM_BOX): 8 * np.prod(size),
                 int(T.mjGEOM_CAPSULE): np.pi * size[0] ** 2 * (2 * size[1] + 4 / 3 * size[0]),
                 int(T.mjGEOM_ELLIPSOID): 4 / 3 * np.pi * np.prod(size)}[kind]
        assert 0.95 * exact < vol <= exact * 1.0001
        assert np.allclose(np.linalg.norm(nrm, axis=1), 1.0)


VALIDATOR_DIR = Path(os.environ.get("GLTF_VALIDATOR_DIR", Path(__file__).resolve().parents[3] / ".gltf-validator"))
_SCRIPT = """
import { validateBytes } from 'gltf-validator';
import { readFileSync } from 'fs';
const report = await validateBytes(new Uint8Array(readFileSync(process.argv[2])), { maxIssues: 100 });
console.log(JSON.stringify(report.issues));
"""


@pytest.mark.client
def test_khronos_validator_reports_no_errors_or_warnings(tmp_path, saved_npz, scene_model):
    """Needs node and `npm install gltf-validator` in $GLTF_VALIDATOR_DIR (default .gltf-validator/ in the
    checkout; .ci/run installs it there)."""
    if shutil.which("node") is None:
        pytest.skip("node is not installed (apt-get install nodejs npm; README \"Full test suite\")")
    if not (VALIDATOR_DIR / "node_modules" / "gltf-validator").is_dir():
        pytest.skip(f"gltf-validator not installed in {VALIDATOR_DIR} (npm install --prefix {VALIDATOR_DIR} "
                    "gltf-validator, or set GLTF_VALIDATOR_DIR; README \"Full test suite\")")
    saved = load_saved_path(saved_npz)
    slots = StateLayout.from_model(scene_model).quat_slots
    m = sample_motion(saved, "optimized", default_fps(saved), slots)
    glb = tmp_path / "clip.glb"
    glb.write_bytes(glb_bytes(figure_gltf(scene_model, [Track("optimized", m.times, m.qpos)], sites=("l_toe",))))
    script = VALIDATOR_DIR / "validate_test.mjs"
    script.write_text(_SCRIPT)
    res = subprocess.run(["node", str(script), str(glb)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    issues = json.loads(res.stdout)
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]
