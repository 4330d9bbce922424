"""glTF 2.0 binary (.glb) export: the figure as an armature (a skin) with TRS animation, and the static scene.

Nodes: ``world`` (a fixed rotation from MuJoCo axes, z up and the figure facing +x, to glTF axes, Y up
and the asset facing +Z: (X, Y, Z)_gltf = (y, z, x)_mujoco) holds the static geoms of the scene's world
body (floor plane as a finite quad, boxes, ...) and one figure per track. A figure is a joint node per
body (named after the body; with several tracks ``<track>_<body>``), parented as MuJoCo's body tree, whose
local transform is MuJoCo's: the root node's translation and rotation are the free joint's `qpos`, every
other body node has its `body_pos` as translation and `body_quat` times its ball joint's quaternion as
rotation. Geoms are triangle meshes (`runner.export.meshes`) named ``geom_<name>``; optionally, sites
(e.g. the contact sites) are small spheres named ``site_<name>`` (``<track>_site_<name>``).

Skinned (the default; glTF 2.0 sec. 3.7.3): the body nodes are the joints of a skin (named after the
track, its `skeleton` the root body's node), and each geom or site is a mesh node at the scene root (a
skinned mesh is not moved by its parents' transforms) whose vertices are bound rigidly to their body's
joint (JOINTS_0 = that joint, WEIGHTS_0 = (1, 0, 0, 0)). The bind pose is the model's `qpos0` (ball
joints at identity): bind-pose vertices are the geom's mesh placed by MuJoCo's forward kinematics at
qpos0, in glTF world axes, and joint j's inverse bind matrix is the inverse of its node's world matrix
there, so that at any time a vertex lands at joint world matrix x inverse bind matrix x bind vertex,
where MuJoCo puts the geom. Blender and game engines import this as an armature with one bone per body.
Rigid (``skinned=False``, the viewer): each geom or site is a child node of its body's node
(`geom_pos`, `geom_quat`) with the mesh in the geom's own frame.

Animation: one per track, named after it: root translation and every body's rotation, LINEAR, one key
per sample (times from 0 [s]; the path's start time is in the animation's `extras`). Units: metres.
Colours: `runner.export.meshes.geom_colour`.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from runner.export.bvh import MUJOCO_TO_BVH, figure_skeleton
from runner.export.meshes import geom_colour, geom_mesh, sphere_mesh
from solver.errors import InputError

__all__ = ["MUJOCO_TO_GLTF", "WORLD_ROTATION", "Track", "figure_gltf", "glb_bytes", "write_glb"]

#: (3, 3) axis change MuJoCo -> glTF (the same as for BVH: Y up, facing +Z, left +X).
MUJOCO_TO_GLTF = MUJOCO_TO_BVH
#: the `world` node's rotation (x, y, z, w): the rotation whose matrix is MUJOCO_TO_GLTF.
WORLD_ROTATION = (-0.5, -0.5, -0.5, 0.5)

_UBYTE, _USHORT, _UINT, _FLOAT = 5121, 5123, 5125, 5126
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


@dataclass(frozen=True)
class Track:
    """A motion of the figure. times: (n,) [s]. qpos: (n, nq)."""

    name: str
    times: np.ndarray
    qpos: np.ndarray


# -------------------------------------------------------------------------------------------- glTF
class _Builder:
    def __init__(self):
        import pygltflib

        self.g = pygltflib
        self.gltf = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0", generator="dynsplines export"))
        self.blob = bytearray()
        self.materials: dict[tuple, int] = {}

    def view(self, data: bytes, target=None) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        self.gltf.bufferViews.append(self.g.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data),
                                                       target=target))
        self.blob += data
        return len(self.gltf.bufferViews) - 1

    def accessor(self, array, kind, component=_FLOAT, target=None, bounds=False) -> int:
        dtype = {_FLOAT: np.float32, _UBYTE: np.uint8, _USHORT: np.uint16, _UINT: np.uint32}[component]
        a = np.ascontiguousarray(array, dtype=dtype)
        view = self.view(a.tobytes(), target)
        flat = a.reshape(len(a), -1)
        kw = {}
        if bounds:
            kw = dict(min=[float(x) for x in flat.min(axis=0)], max=[float(x) for x in flat.max(axis=0)])
            if component != _FLOAT:
                kw = {k: [int(x) for x in v] for k, v in kw.items()}
        self.gltf.accessors.append(self.g.Accessor(bufferView=view, componentType=component, count=len(a),
                                                   type=kind, **kw))
        return len(self.gltf.accessors) - 1

    def material(self, rgba) -> int:
        key = tuple(round(x, 6) for x in rgba)
        if key not in self.materials:
            pbr = self.g.PbrMetallicRoughness(baseColorFactor=list(key), metallicFactor=0.0, roughnessFactor=0.8)
            self.gltf.materials.append(self.g.Material(
                name=f"rgba {' '.join(f'{x:g}' for x in key)}", pbrMetallicRoughness=pbr,
                alphaMode="BLEND" if key[3] < 1 else None))
            self.materials[key] = len(self.gltf.materials) - 1
        return self.materials[key]

    def mesh(self, name, pos, nrm, idx, rgba, joint: int | None = None) -> int:
        """A mesh of one primitive; with `joint`, its vertices bound to that skin joint with weight 1."""
        n = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        big = len(pos) > 65535
        attrs = self.g.Attributes(POSITION=self.accessor(pos, "VEC3", target=_ARRAY_BUFFER, bounds=True),
                                  NORMAL=self.accessor(n, "VEC3", target=_ARRAY_BUFFER))
        if joint is not None:
            attrs.JOINTS_0 = self.accessor(np.tile([joint, 0, 0, 0], (len(pos), 1)), "VEC4",
                                           _UBYTE if joint < 256 else _USHORT, target=_ARRAY_BUFFER)
            attrs.WEIGHTS_0 = self.accessor(np.tile([1.0, 0.0, 0.0, 0.0], (len(pos), 1)), "VEC4",
                                            target=_ARRAY_BUFFER)
        ind = self.accessor(idx, "SCALAR", _UINT if big else _USHORT, target=_ELEMENT_ARRAY_BUFFER)
        prim = self.g.Primitive(attributes=attrs, indices=ind, material=self.material(rgba))
        self.gltf.meshes.append(self.g.Mesh(name=name, primitives=[prim]))
        return len(self.gltf.meshes) - 1

    def node(self, **kw) -> int:
        self.gltf.nodes.append(self.g.Node(**kw))
        return len(self.gltf.nodes) - 1


def _xyzw(q) -> list[float]:
    q = np.asarray(q, float)
    return [float(q[1]), float(q[2]), float(q[3]), float(q[0])]


def _is_identity(q) -> bool:
    return bool(np.allclose(q, (1, 0, 0, 0)))


def _track_animation(B, sk, tr, nodes: list, qpos: np.ndarray, local: np.ndarray):
    """The glTF Animation of one track: the root node's translation and every joint node's rotation,
    sampled at the track's times from 0 and interpolated linearly (glTF 2.0 sec. 3.11)."""
    times = np.asarray(tr.times, float)
    inp = B.accessor(times - times[0], "SCALAR", bounds=True)
    samplers = [B.g.AnimationSampler(input=inp, output=B.accessor(qpos[:, sk.root_pos], "VEC3"),
                                     interpolation="LINEAR")]
    channels = [B.g.AnimationChannel(sampler=0, target=B.g.AnimationChannelTarget(node=nodes[0],
                                                                                  path="translation"))]
    for j in range(sk.count):
        q = local[:, j][:, [1, 2, 3, 0]]
        samplers.append(B.g.AnimationSampler(input=inp, output=B.accessor(q, "VEC4"), interpolation="LINEAR"))
        channels.append(B.g.AnimationChannel(sampler=len(samplers) - 1, target=B.g.AnimationChannelTarget(
            node=nodes[j], path="rotation")))
    return B.g.Animation(name=tr.name, samplers=samplers, channels=channels,
                         extras={"start_time_s": float(times[0]), "samples": len(times)})


@dataclass(frozen=True)
class _Part:
    """A mesh of the figure rigid with one body: joint = the body's index in the skeleton, name (node
    name without the track's prefix), pos (3,) [m] and quat (w, x, y, z) in the body's frame, the mesh in
    its own frame (positions (v, 3), normals (v, 3), indices), rgba; kind ('geom' or 'site') and its id."""

    joint: int
    name: str
    pos: np.ndarray
    quat: np.ndarray
    mesh: tuple
    rgba: tuple
    kind: str
    id: int


def _figure_parts(model, sk, sites: Sequence[str], site_radius: float) -> list[_Part]:
    """The figure's geoms (those with a mesh) and the named sites (spheres of site_radius [m]), body by body.
    Raises InputError for an unknown site."""
    import mujoco

    site_ids = []
    for s in sites:
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
        if i < 0:
            raise InputError(f"site {s!r} is not in the scene; sites: "
                             + ", ".join(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, k) for k in range(model.nsite)))
        site_ids.append(i)
    sphere = sphere_mesh(site_radius) if sites else None
    parts = []
    for j, b in enumerate(int(b) for b in sk.bodies):
        for g in range(model.body_geomadr[b], model.body_geomadr[b] + model.body_geomnum[b]):
            mesh = geom_mesh(model, g)
            if mesh is not None:
                parts.append(_Part(j, f"geom_{_geom_name(model, g)}", model.geom_pos[g], model.geom_quat[g], mesh,
                                   geom_colour(model, g), "geom", g))
        parts += [_Part(j, f"site_{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, s)}", model.site_pos[s],
                        np.array([1.0, 0.0, 0.0, 0.0]), sphere, (1.0, 1.0, 0.0, 1.0), "site", s)
                  for s in site_ids if model.site_bodyid[s] == b]
    return parts


def _geom_name(model, g: int) -> str:
    import mujoco

    return mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}"


def _bind_pose(model):
    """MjData posed at the bind pose, the model's `qpos0` (`mj_kinematics`)."""
    import mujoco

    data = mujoco.MjData(model)
    data.qpos[:] = model.qpos0
    mujoco.mj_kinematics(model, data)
    return data


def _bound_mesh(part: _Part, bind) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A part's mesh placed where MuJoCo puts it at the bind pose, in glTF world axes: (v, 3), (v, 3), idx."""
    pos, nrm, idx = part.mesh
    xpos, xmat = ((bind.geom_xpos, bind.geom_xmat) if part.kind == "geom" else (bind.site_xpos, bind.site_xmat))
    R = MUJOCO_TO_GLTF @ xmat[part.id].reshape(3, 3)
    return pos @ R.T + MUJOCO_TO_GLTF @ xpos[part.id], nrm @ R.T, idx


def _skin(B, sk, nodes: list, bind, name: str) -> int:
    """A glTF Skin over the joint nodes (skeleton order) with inverse bind matrices (MAT4, column-major):
    the inverse of each body's world matrix at the bind pose, glTF world axes (module docstring)."""
    ibm = np.zeros((sk.count, 4, 4))
    for j, b in enumerate(int(b) for b in sk.bodies):
        R = MUJOCO_TO_GLTF @ bind.xmat[b].reshape(3, 3)
        p = MUJOCO_TO_GLTF @ bind.xpos[b]
        ibm[j, :3, :3], ibm[j, :3, 3], ibm[j, 3, 3] = R.T, -R.T @ p, 1.0
    acc = B.accessor(ibm.transpose(0, 2, 1), "MAT4")  # column-major
    B.gltf.skins.append(B.g.Skin(name=name, joints=list(nodes), skeleton=nodes[0], inverseBindMatrices=acc))
    return len(B.gltf.skins) - 1


def _rigid_trs(part: _Part) -> dict:
    kw = dict(translation=[float(x) for x in part.pos]) if np.any(part.pos) else {}
    if not _is_identity(part.quat):
        kw["rotation"] = _xyzw(part.quat)
    return kw


def figure_gltf(model, tracks: Sequence[Track], sites: Sequence[str] = (), site_radius: float = 0.025,
                skinned: bool = True):
    """A `pygltflib.GLTF2` of the scene and one animated figure per track (module docstring), with its
    binary blob set (`gltf.binary_blob()`).

    Args:
        model: MjModel of the scene with the figure. tracks: the motions (each n >= 1 samples).
        sites: names of sites to draw as small spheres (e.g. the contact sites), site_radius [m].
        skinned: the figure as a skin (an armature) with skinned meshes; False: meshes in child nodes.
    Raises:
        InputError: no tracks, a track with no samples or a qpos width other than model.nq, unknown site.
    """
    if not tracks:
        raise InputError("no motion to export; give at least one track")
    for tr in tracks:
        if np.ndim(tr.qpos) != 2 or len(tr.qpos) < 1 or tr.qpos.shape[1] != model.nq or len(tr.times) != len(tr.qpos):
            raise InputError(f"track {tr.name!r}: qpos shape {np.shape(tr.qpos)} with {len(tr.times)} times; "
                             f"expected (n >= 1, {model.nq}) and n times")
    sk = figure_skeleton(model, head=False)  # the torso node holds the head's mesh
    B = _Builder()
    world_children = []
    for g in range(model.body_geomadr[0], model.body_geomadr[0] + model.body_geomnum[0]):
        mesh = geom_mesh(model, g)
        if mesh is not None:
            p = _Part(0, f"geom_{_geom_name(model, g)}", model.geom_pos[g], model.geom_quat[g], mesh,
                      geom_colour(model, g), "geom", g)
            world_children.append(B.node(name=p.name, mesh=B.mesh(_geom_name(model, g), *mesh, p.rgba), **_rigid_trs(p)))
    parts = _figure_parts(model, sk, sites, site_radius)
    bind = _bind_pose(model) if skinned else None
    meshes = [B.mesh(p.name, *(_bound_mesh(p, bind) if skinned else p.mesh), p.rgba, p.joint if skinned else None)
              for p in parts]
    roots, animations = [], []
    for tr in tracks:
        prefix = f"{tr.name}_" if len(tracks) > 1 else ""
        qpos = np.asarray(tr.qpos, float)
        local = sk.local_quat(qpos)  # (n, J, 4)
        nodes = [0] * sk.count
        for j in reversed(range(sk.count)):  # children first: a node lists its children by index
            children = [] if skinned else [B.node(name=prefix + p.name, mesh=m, **_rigid_trs(p))
                                           for p, m in zip(parts, meshes) if p.joint == j]
            children += [nodes[c] for c in range(sk.count) if sk.parents[c] == j]
            t = qpos[0, sk.root_pos] if j == 0 else sk.offsets[j]
            nodes[j] = B.node(name=f"{prefix}{sk.names[j]}", children=children or None,
                              translation=[float(x) for x in t], rotation=_xyzw(local[0, j]))
        roots.append(B.node(name=tr.name, rotation=list(WORLD_ROTATION), children=[nodes[0]]))
        if skinned:
            skin = _skin(B, sk, nodes, bind, tr.name)
            roots += [B.node(name=prefix + p.name, mesh=m, skin=skin) for p, m in zip(parts, meshes)]
        animations.append(_track_animation(B, sk, tr, nodes, qpos, local))
    world = B.node(name="world", rotation=list(WORLD_ROTATION), children=world_children or None)
    B.gltf.animations = animations
    B.gltf.scenes = [B.g.Scene(name="dynsplines", nodes=[world, *roots])]
    B.gltf.scene = 0
    while len(B.blob) % 4:
        B.blob.append(0)
    B.gltf.buffers = [B.g.Buffer(byteLength=len(B.blob))]
    B.gltf.set_binary_blob(bytes(B.blob))
    return B.gltf


def glb_bytes(gltf) -> bytes:
    """The .glb file of a GLTF2 made by `figure_gltf`."""
    return b"".join(gltf.save_to_bytes())


def write_glb(path: str | Path, model, tracks: Sequence[Track], sites: Sequence[str] = ()) -> int:
    """Write the scene and the tracks to a .glb file atomically. Returns its size [bytes]."""
    from runner.files import atomic_output

    data = glb_bytes(figure_gltf(model, tracks, sites))
    with atomic_output(path) as tmp:
        Path(tmp).write_bytes(data)
    return len(data)
