"""The support surface under a contact site: heights of points above the supporting face of each static
surface (a plane, or a box's top over its footprint, with rounded edges beside it), for the contact
constraints (`solver.constraint_set`)."""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.surfaces import StaticSurfaces


class SupportSurfaces:
    """Heights of points above the supporting face of each static surface (see module docstring).

    Args:
        surfaces: StaticSurfaces of the scene.
        rounded_edges: with surfaces chosen per point, a point beside a box's footprint is at its
            Euclidean distance from the top face (the rectangle) rather than unsupported by the box:
            sqrt(out^2 + v^2), out the horizontal distance past the footprint's edge, v the height
            above the top's plane; over the footprint it is v as before. So the height is continuous
            across a box's edge (without it, it jumps by the box's height there: a swing foot passing
            a ledge's edge 2 mm above its top is 2 mm up on one side and a ledge's height up on the
            other, and an objective built on it is discontinuous in the frames), and its gradient
            (the unit vector from the nearest point of the top face) turns from the floor's normal
            through the edge's radial direction to the top's normal. The distance function of a
            convex set is continuously differentiable outside it (Rockafellar and Wets, Variational
            Analysis, ex. 2.25 and th. 2.26).
    """

    def __init__(self, surfaces: StaticSurfaces, rounded_edges: bool = False):
        self.surfaces = surfaces
        self.rounded_edges = bool(rounded_edges)
        self.names = surfaces.names
        P = len(surfaces.plane_point)
        pts, nrm, is_box, tang, half2 = [], [], [], [], []
        for i in range(P):
            pts.append(surfaces.plane_point[i])
            nrm.append(surfaces.plane_normal[i])
            is_box.append(False)
            tang.append(np.zeros((3, 2)))
            half2.append(np.full(2, np.inf))
        for c, R, h in zip(surfaces.box_center, surfaces.box_rot, surfaces.box_half):
            up = np.concatenate([R[2], -R[2]])  # z component of +axis0..2, -axis0..2
            k = int(np.argmax(up))
            a, sgn = k % 3, (1.0 if k < 3 else -1.0)
            n = sgn * R[:, a]
            pts.append(c + h[a] * n)
            nrm.append(n)
            is_box.append(True)
            others = [b for b in range(3) if b != a]
            tang.append(R[:, others])
            half2.append(h[others])
        self.point = np.array(pts, float).reshape(-1, 3)
        self.normal = np.array(nrm, float).reshape(-1, 3)
        self.is_box = np.array(is_box, bool)
        self.tangent = np.array(tang, float).reshape(-1, 3, 2)
        self.half = np.array(half2, float).reshape(-1, 2)

    @property
    def count(self) -> int:
        return len(self.point)

    def _rounded(self, d: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`height` with `rounded_edges`: per surface, v (planes; boxes over their footprint) or the
        distance sqrt(|out|^2 + v^2) to the top face beside it; the surface nearest in |height| wins.
        d (..., S, 3) offsets from each face's point, v (..., S) heights above each face's plane."""
        loc = np.einsum("...si,sij->...sj", d, self.tangent)  # (..., S, 2) along the face
        half = np.where(self.is_box[:, None], self.half, np.inf)
        out = np.sign(loc) * np.maximum(np.abs(loc) - half, 0.0)  # (..., S, 2) past the footprint's edge
        beside = (out != 0.0).any(axis=-1)
        dist = np.sqrt((out * out).sum(axis=-1) + v * v)
        h = np.where(beside, dist, v)
        off = np.einsum("sij,...sj->...si", self.tangent, out) + v[..., None] * self.normal  # from the face
        grad = np.where(beside[..., None], off / np.maximum(dist, 1e-300)[..., None], self.normal)
        which = np.argmin(np.abs(h), axis=-1)
        hh = np.take_along_axis(h, which[..., None], -1)[..., 0]
        return hh, np.take_along_axis(grad, which[..., None, None], -2)[..., 0, :]

    def index(self, name: str) -> int | None:
        """Index of a surface by name; None for "" (automatic)."""
        if not name:
            return None
        if name not in self.names:
            raise InputError(f"unknown surface {name!r}; the scene's surfaces are: {', '.join(self.names)}")
        return self.names.index(name)

    def height(self, p: np.ndarray, which: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Signed height of points above their support face, and that face's unit normal.

        Args:
            p: (..., 3) points [m]. which: surface index, or None to choose per point.
        Returns:
            h (...,) [m] (dh/dp = n), n (..., 3) (read-only: may be a broadcast view). With
            `rounded_edges` and surfaces chosen per point, n is the gradient of the rounded height
            (a unit vector, the face's normal over a footprint).
        """
        if which is None and self.count == 1:
            which = 0
        if which is not None and np.ndim(which) == 0:  # one surface for all points: no choosing
            n = self.normal[int(which)]
            return (p - self.point[int(which)]) @ n, np.broadcast_to(n, p.shape)
        d = p[..., None, :] - self.point  # (..., S, 3)
        h = np.einsum("...si,si->...s", d, self.normal)
        if which is None and self.rounded_edges:
            return self._rounded(d, h)
        if which is None:
            loc = np.abs(np.einsum("...si,sij->...sj", d, self.tangent))
            ok = ~self.is_box | (loc <= self.half).all(axis=-1)
            ok = np.where(ok.any(axis=-1, keepdims=True), ok, True)  # nothing under: nearest of all
            which = np.argmin(np.where(ok, np.abs(h), np.inf), axis=-1)
        which = np.broadcast_to(np.asarray(which), h.shape[:-1])
        hh = np.take_along_axis(h, which[..., None], -1)[..., 0]
        return hh, self.normal[which]


# ---------------------------------------------------------------------------------------------------
# site kinematics with velocities
