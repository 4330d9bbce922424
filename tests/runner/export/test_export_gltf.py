"""glTF export: node transforms at the sampled times are MuJoCo's body poses; the skin's vertices, computed
from the file alone (joint world matrix x inverse bind matrix x bind-pose vertex), lie on MuJoCo's geoms
at those times; meshes are closed and face outward; the Khronos validator finds no error or warning (a
`client` test: skipped without node and gltf-validator, a failure then in CI)."""
import json
import os
import shutil
import subprocess
from pathlib import Path

import mujoco
import numpy as np
import pygltflib
import pytest

from runner.export.gltf import MUJOCO_TO_GLTF, WORLD_ROTATION, Track, figure_gltf, glb_bytes, write_glb
from runner.export.meshes import geom_mesh
from runner.export.sampling import default_fps, sample_motion
from runner.saved_path import load_saved_path
from solver.layout import StateLayout

_TYPES = {5126: np.float32, 5121: np.uint8, 5123: np.uint16, 5125: np.uint32}
_WIDTH = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}


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


def _on_surface(model, g, v):
    """(v,) [m] how far points v (k, 3), in geom g's frame, are from the exact surface of its primitive
    (0 on it): the distance to the axis segment less the radius for a capsule, |v| - r for a sphere; for
    an ellipsoid and a box the scaled radius |v / size| - 1 and max |v_i / size_i| - 1 times the
    smallest half size (a lower bound of the distance, exact at 0)."""
    T = mujoco.mjtGeom
    s, kind = model.geom_size[g], model.geom_type[g]
    if kind == T.mjGEOM_CAPSULE:
        axis = np.stack([np.zeros(len(v)), np.zeros(len(v)), np.clip(v[:, 2], -s[1], s[1])], axis=1)
        return np.linalg.norm(v - axis, axis=1) - s[0]
    if kind == T.mjGEOM_SPHERE:
        return np.linalg.norm(v, axis=1) - s[0]
    if kind == T.mjGEOM_ELLIPSOID:
        return (np.linalg.norm(v / s, axis=1) - 1.0) * s.min()
    if kind == T.mjGEOM_BOX:
        return (np.abs(v / s).max(axis=1) - 1.0) * s.min()
    raise AssertionError(f"geom type {kind} has no reference surface here")


def _half_extents(model, g):
    """(3,) [m] half extents of geom g's primitive along its own axes."""
    T = mujoco.mjtGeom
    s, kind = model.geom_size[g], int(model.geom_type[g])
    if kind == T.mjGEOM_CAPSULE:
        return np.array([s[0], s[0], s[0] + s[1]])
    return np.full(3, s[0]) if kind == T.mjGEOM_SPHERE else s


def skinned_vertices(gltf, anim, k):
    """{node name: (v, 3) glTF world positions of its skinned mesh at key k}, from the file alone: the
    weighted sum over a vertex's joints of joint world matrix x inverse bind matrix x bind-pose vertex
    (glTF 2.0 sec. 3.7.3.3)."""
    poses = world_poses(gltf, anim, k)
    out = {}
    for node in gltf.nodes:
        if node.skin is None:
            continue
        skin = gltf.skins[node.skin]
        ibm = accessor(gltf, skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)  # column-major
        world = np.zeros((len(skin.joints), 4, 4))
        for i, j in enumerate(skin.joints):
            p, R = poses[gltf.nodes[j].name]
            world[i, :3, :3], world[i, :3, 3], world[i, 3, 3] = R, p, 1.0
        [prim] = gltf.meshes[node.mesh].primitives
        v = accessor(gltf, prim.attributes.POSITION).astype(float)
        joints = accessor(gltf, prim.attributes.JOINTS_0).astype(int)
        weights = accessor(gltf, prim.attributes.WEIGHTS_0).astype(float)
        assert np.allclose(weights.sum(axis=1), 1.0, atol=1e-6)
        vh = np.c_[v, np.ones(len(v))]
        skinned = np.einsum("vi,virc,vc->vr", weights, (world @ ibm)[joints], vh)
        out[node.name] = skinned[:, :3]
    return out


def test_skinned_vertices_lie_on_mujoco_geoms(saved_npz, scene_model):
    """At sampled times every vertex of every skinned figure mesh, taken back into MuJoCo's frame of its
    geom (`geom_xpos`, `geom_xmat` from `mj_kinematics`), lies on the geom's exact surface, spans its
    extent along each axis, and keeps its place in that frame over time: the skin moves it with the geom.
    Tolerance 10 um: float32 vertices and matrices within ~3 m of the origin."""
    model = scene_model
    saved = load_saved_path(saved_npz)
    motion = sample_motion(saved, "optimized", 30.0, StateLayout.from_model(model).quat_slots)
    gltf = figure_gltf(model, [Track("optimized", motion.times, motion.qpos)], sites=("l_heel",))
    gltf = pygltflib.GLTF2.load_binary_from_file_object(__import__("io").BytesIO(glb_bytes(gltf)))
    anim = gltf.animations[0]
    data = mujoco.MjData(model)
    figure_geoms = {f"geom_{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)}": g
                    for g in range(model.ngeom) if model.geom_bodyid[g] != 0}
    first = {}
    for k in range(0, len(motion.times), 5):
        data.qpos[:] = motion.qpos[k]
        mujoco.mj_kinematics(model, data)
        verts = skinned_vertices(gltf, anim, k)
        assert set(verts) == set(figure_geoms) | {"site_l_heel"}
        for name, v in verts.items():
            mj = v @ MUJOCO_TO_GLTF  # glTF world -> MuJoCo world (the axis change is a rotation)
            if name.startswith("site_"):
                s = model.site("l_heel").id
                assert np.abs(np.linalg.norm(mj - data.site_xpos[s], axis=1) - 0.025).max() < 1e-5, (name, k)
                continue
            g = figure_geoms[name]
            local = (mj - data.geom_xpos[g]) @ data.geom_xmat[g].reshape(3, 3)
            assert np.abs(_on_surface(model, g, local)).max() < 1e-5, (name, k)
            half = _half_extents(model, g)
            assert np.allclose(local.max(axis=0), half, atol=1e-5) and np.allclose(local.min(axis=0), -half, atol=1e-5)
            assert np.abs(local - first.setdefault(name, local)).max() < 1e-5, (name, k)


def test_the_skin_is_the_figure_tree(scene_model):
    """One joint per figure body, named after it and parented as MuJoCo's body tree; skinned meshes at the
    scene root without a transform of their own (glTF 2.0 sec. 3.7.3), bound with weight 1."""
    model = scene_model
    gltf = figure_gltf(model, [Track("optimized", np.zeros(1), model.qpos0[None])])
    [skin] = gltf.skins
    names = [gltf.nodes[j].name for j in skin.joints]
    body = lambda b: mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(b))  # noqa: E731
    figure = [body(b) for b in range(1, model.nbody) if model.body_rootid[b] != 0 or model.body_jntnum[b]]
    assert sorted(names) == sorted(figure) and len(names) == 12
    parent = {c: i for i, n in enumerate(gltf.nodes) for c in (n.children or [])}
    for j in skin.joints:
        b = model.body(gltf.nodes[j].name).id
        up = gltf.nodes[parent[j]].name
        assert up == (body(model.body_parentid[b]) if model.body_parentid[b] else "optimized"), (gltf.nodes[j].name, up)
    assert gltf.nodes[skin.skeleton].name == "pelvis"
    skinned = [i for i, n in enumerate(gltf.nodes) if n.skin is not None]
    assert skinned and set(skinned) <= set(gltf.scenes[0].nodes)
    for i in skinned:
        n = gltf.nodes[i]
        assert n.translation is None and n.rotation is None and n.scale is None and n.matrix is None
        [prim] = gltf.meshes[n.mesh].primitives
        assert np.all(accessor(gltf, prim.attributes.WEIGHTS_0) == [1, 0, 0, 0])


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
    assert [s.name for s in gltf.skins] == ["optimized", "plain"]
    assert all(gltf.nodes[j].name.startswith(f"{s.name}_") for s in gltf.skins for j in s.joints)


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
@pytest.mark.parametrize("skinned", [True, False])
def test_khronos_validator_reports_no_errors_or_warnings(tmp_path, saved_npz, scene_model, skinned):
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
    glb.write_bytes(glb_bytes(figure_gltf(scene_model, [Track("optimized", m.times, m.qpos)], sites=("l_toe",),
                                          skinned=skinned)))
    script = VALIDATOR_DIR / "validate_test.mjs"
    script.write_text(_SCRIPT)
    res = subprocess.run(["node", str(script), str(glb)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    issues = json.loads(res.stdout)
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]
