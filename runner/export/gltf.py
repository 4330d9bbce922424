"""glTF 2.0 binary (.glb) export: the figure as a node tree with TRS animation, and the static scene.

Nodes: ``world`` (a fixed rotation from MuJoCo axes, z up and the figure facing +x, to glTF axes, Y up
and the asset facing +Z: (X, Y, Z)_gltf = (y, z, x)_mujoco) holds the static geoms of the scene's world
body (floor plane as a finite quad, boxes, ...) and one figure per track. A figure is a node per body
(named after the body; with several tracks ``<track>_<body>``; geom nodes ``geom_<name>``) whose local transform is MuJoCo's: the
root node's translation and rotation are the free joint's `qpos`, every other body node has its
`body_pos` as translation and `body_quat` times its ball joint's quaternion as rotation. Each geom is a
child node (`geom_pos`, `geom_quat`) with a triangle mesh: capsules, spheres, ellipsoids and cylinders
as latitude-longitude meshes, boxes and planes as quads. Optionally, sites (e.g. the contact sites) are
small spheres named ``site_<name>`` (``<track>_site_<name>``), for a viewer to colour.

Animation: one per track, named after it: root translation and every body's rotation, LINEAR, one key
per sample (times from 0 [s]; the path's start time is in the animation's `extras`). Units: metres.
Colours: the geom's material `rgba` (times the mean colour of its texture, if any), else `geom_rgba`.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from runner.export.bvh import MUJOCO_TO_BVH, figure_skeleton
from solver.errors import InputError

__all__ = ["MUJOCO_TO_GLTF", "WORLD_ROTATION", "Track", "figure_gltf", "glb_bytes", "write_glb", "geom_mesh"]

#: (3, 3) axis change MuJoCo -> glTF (the same as for BVH: Y up, facing +Z, left +X).
MUJOCO_TO_GLTF = MUJOCO_TO_BVH
#: the `world` node's rotation (x, y, z, w): the rotation whose matrix is MUJOCO_TO_GLTF.
WORLD_ROTATION = (-0.5, -0.5, -0.5, 0.5)
#: [m] half size of the quad drawn for an infinite plane.
PLANE_HALF = 20.0
_SEGMENTS = 20  # around an axis
_RINGS = 8  # per quarter circle

_FLOAT, _USHORT, _UINT = 5126, 5123, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


@dataclass(frozen=True)
class Track:
    """A motion of the figure. times: (n,) [s]. qpos: (n, nq)."""

    name: str
    times: np.ndarray
    qpos: np.ndarray


# ------------------------------------------------------------------------------------------- meshes
def _rings_piece(rings, segments=_SEGMENTS):
    """Triangles joining rings (radius, z, normal radial part, normal z part), top to bottom; a ring of
    radius 0 is a pole (one vertex). Outward normals, counter-clockwise seen from outside."""
    th = 2 * math.pi * np.arange(segments) / segments
    c, s = np.cos(th), np.sin(th)
    pos, nrm, idx, starts = [], [], [], []
    for r, z, nr, nz in rings:
        starts.append(len(pos))
        if r == 0.0:
            pos.append((0.0, 0.0, z))
            nrm.append((0.0, 0.0, nz))
        else:
            pos += list(zip(r * c, r * s, np.full(segments, z)))
            nrm += list(zip(nr * c, nr * s, np.full(segments, nz)))
    for k in range(len(rings) - 1):
        a, b = starts[k], starts[k + 1]
        pa, pb = rings[k][0] == 0.0, rings[k + 1][0] == 0.0
        for i in range(segments):
            j = (i + 1) % segments
            if pa and not pb:
                idx += [a, b + i, b + j]
            elif pb and not pa:
                idx += [a + i, b, a + j]
            elif not pa and not pb:
                idx += [a + i, b + i, b + j, a + i, b + j, a + j]
    return np.array(pos, float), np.array(nrm, float), np.array(idx, int)


def _sphere_rings(radius, z_offset=0.0, lo=0.0, hi=math.pi, n=2 * _RINGS):
    out = []
    for phi in np.linspace(lo, hi, n + 1):
        sr, cr = math.sin(phi), math.cos(phi)
        r = 0.0 if sr < 1e-12 else radius * sr
        out.append((r, radius * cr + z_offset, sr, cr))
    return out


def _quad(center, u, v):
    """Face center +- u +- v with normal u x v (unit), counter-clockwise seen from the normal side."""
    n = np.cross(u, v)
    n = n / np.linalg.norm(n)
    pos = np.array([center - u - v, center + u - v, center + u + v, center - u + v])
    return pos, np.tile(n, (4, 1)), np.array([0, 1, 2, 0, 2, 3])


def _join(pieces):
    pos, nrm, idx, off = [], [], [], 0
    for p, n, i in pieces:
        pos.append(p)
        nrm.append(n)
        idx.append(i + off)
        off += len(p)
    return np.concatenate(pos), np.concatenate(nrm), np.concatenate(idx)


def geom_mesh(model, g: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Triangle mesh of geom g in its own frame: positions (v, 3) [m], unit normals (v, 3), indices (3t,).
    None for geom types without a primitive mesh here (meshes, height fields)."""
    import mujoco

    T = mujoco.mjtGeom
    kind, size = int(model.geom_type[g]), model.geom_size[g]
    if kind == int(T.mjGEOM_SPHERE):
        return _rings_piece(_sphere_rings(size[0]))
    if kind == int(T.mjGEOM_CAPSULE):
        r, h = size[0], size[1]
        rings = _sphere_rings(r, h, 0.0, math.pi / 2, _RINGS) + _sphere_rings(r, -h, math.pi / 2, math.pi, _RINGS)
        return _rings_piece(rings)
    if kind == int(T.mjGEOM_ELLIPSOID):
        p, n, i = _rings_piece(_sphere_rings(1.0))
        n = n / size
        return p * size, n / np.linalg.norm(n, axis=1, keepdims=True), i
    if kind == int(T.mjGEOM_CYLINDER):
        r, h = size[0], size[1]
        return _join([_rings_piece([(0.0, h, 0, 1), (r, h, 0, 1)]),
                      _rings_piece([(r, h, 1, 0), (r, -h, 1, 0)]),
                      _rings_piece([(r, -h, 0, -1), (0.0, -h, 0, -1)])])
    if kind == int(T.mjGEOM_BOX):
        e = np.eye(3) * size
        faces = []
        for a in range(3):
            b, c = e[(a + 1) % 3], e[(a + 2) % 3]
            faces.append(_quad(e[a], b, c))
            faces.append(_quad(-e[a], c, b))
        return _join(faces)
    if kind == int(T.mjGEOM_PLANE):
        hx = size[0] if size[0] > 0 else PLANE_HALF
        hy = size[1] if size[1] > 0 else PLANE_HALF
        return _quad(np.zeros(3), np.array([hx, 0.0, 0.0]), np.array([0.0, hy, 0.0]))
    return None


def _geom_colour(model, g: int) -> tuple[float, float, float, float]:
    m = int(model.geom_matid[g])
    if m < 0:
        return tuple(float(x) for x in model.geom_rgba[g])
    rgba = np.array(model.mat_rgba[m], float)
    texids = np.atleast_1d(model.mat_texid[m])
    tex = [int(t) for t in texids if t >= 0]
    if tex:
        t = tex[0]
        nch = int(model.tex_nchannel[t])
        n = int(model.tex_width[t] * model.tex_height[t] * nch)
        data = np.asarray(model.tex_data[model.tex_adr[t]:model.tex_adr[t] + n], float).reshape(-1, nch)
        rgba[:3] *= data[:, :3].mean(axis=0) / 255.0
    return tuple(float(x) for x in rgba)


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
        dtype = {_FLOAT: np.float32, _USHORT: np.uint16, _UINT: np.uint32}[component]
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

    def mesh(self, name, pos, nrm, idx, rgba) -> int:
        n = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        big = len(pos) > 65535
        attrs = self.g.Attributes(POSITION=self.accessor(pos, "VEC3", target=_ARRAY_BUFFER, bounds=True),
                                  NORMAL=self.accessor(n, "VEC3", target=_ARRAY_BUFFER))
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


def figure_gltf(model, tracks: Sequence[Track], sites: Sequence[str] = (), site_radius: float = 0.025):
    """A `pygltflib.GLTF2` of the scene and one animated figure per track (module docstring), with its
    binary blob set (`gltf.binary_blob()`).

    Args:
        model: MjModel of the scene with the figure. tracks: the motions (each n >= 1 samples).
        sites: names of sites to draw as small spheres (e.g. the contact sites), site_radius [m].
    Raises:
        InputError: no tracks, a track with no samples or a qpos width other than model.nq, unknown site.
    """
    import mujoco

    if not tracks:
        raise InputError("no motion to export; give at least one track")
    for tr in tracks:
        if np.ndim(tr.qpos) != 2 or len(tr.qpos) < 1 or tr.qpos.shape[1] != model.nq or len(tr.times) != len(tr.qpos):
            raise InputError(f"track {tr.name!r}: qpos shape {np.shape(tr.qpos)} with {len(tr.times)} times; "
                             f"expected (n >= 1, {model.nq}) and n times")
    sk = figure_skeleton(model, head=False)  # the torso node holds the head's mesh
    B = _Builder()
    name = lambda g: mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}"  # noqa: E731
    meshes = {}
    for g in range(model.ngeom):
        mesh = geom_mesh(model, g)
        if mesh is not None:
            meshes[g] = B.mesh(name(g), *mesh, _geom_colour(model, g))
    site_ids = []
    for s in sites:
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
        if i < 0:
            raise InputError(f"site {s!r} is not in the scene; sites: "
                             + ", ".join(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, k) for k in range(model.nsite)))
        site_ids.append(i)
    site_mesh = B.mesh("site", *_rings_piece(_sphere_rings(site_radius)), (1.0, 1.0, 0.0, 1.0)) if sites else None

    def geom_nodes(body, prefix):
        out = []
        for g in range(model.body_geomadr[body], model.body_geomadr[body] + model.body_geomnum[body]):
            if g in meshes:
                kw = dict(translation=[float(x) for x in model.geom_pos[g]]) if np.any(model.geom_pos[g]) else {}
                if not _is_identity(model.geom_quat[g]):
                    kw["rotation"] = _xyzw(model.geom_quat[g])
                out.append(B.node(name=f"{prefix}geom_{name(g)}", mesh=meshes[g], **kw))
        return out

    world_children = geom_nodes(0, "")
    animations = []
    for tr in tracks:
        prefix = f"{tr.name}_" if len(tracks) > 1 else ""
        qpos = np.asarray(tr.qpos, float)
        local = sk.local_quat(qpos)  # (n, J, 4)
        nodes = [0] * sk.count
        for j in reversed(range(sk.count)):  # children first: a node lists its children by index
            b = int(sk.bodies[j])
            children = geom_nodes(b, prefix)
            children += [B.node(name=f"{prefix}site_{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, s)}",
                                mesh=site_mesh, translation=[float(x) for x in model.site_pos[s]])
                         for s in site_ids if model.site_bodyid[s] == b]
            children += [nodes[c] for c in range(sk.count) if sk.parents[c] == j]
            t = qpos[0, sk.root_pos] if j == 0 else sk.offsets[j]
            nodes[j] = B.node(name=f"{prefix}{sk.names[j]}", children=children or None,
                              translation=[float(x) for x in t], rotation=_xyzw(local[0, j]))
        world_children.append(nodes[0])
        animations.append(_track_animation(B, sk, tr, nodes, qpos, local))
    world = B.node(name="world", rotation=list(WORLD_ROTATION), children=world_children)
    B.gltf.animations = animations
    B.gltf.scenes = [B.g.Scene(name="dynsplines", nodes=[world])]
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
