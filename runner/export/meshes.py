"""Triangle meshes of MuJoCo geoms for the glTF export (`runner.export.gltf`): capsules, spheres,
ellipsoids and cylinders as latitude-longitude meshes whose vertices lie on the exact surface, boxes and
planes as quads; and a geom's display colour.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["PLANE_HALF", "geom_mesh", "geom_colour", "sphere_mesh"]

#: [m] half size of the quad drawn for an infinite plane.
PLANE_HALF = 20.0
_SEGMENTS = 20  # around an axis
_RINGS = 8  # per quarter circle


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


def geom_colour(model, g: int) -> tuple[float, float, float, float]:
    """RGBA in [0, 1] of geom g: its material's `rgba` (times the mean colour of its texture, if any),
    else `geom_rgba`."""
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


def sphere_mesh(radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sphere of `radius` [m] about the origin: positions (v, 3), unit normals (v, 3), indices (3t,)."""
    return _rings_piece(_sphere_rings(radius))
