"""Static surfaces of a scene (floor planes, boxes) and the signed distance of points to them.

Used by the ground-penetration term (paper eq. 12, generalized from the plane y = 0 to every static
plane and box of the scene) and by contact indicators. Planes and boxes may have any orientation
(a fitted scene's floor and boxes are tilted with the capture's floor, `runner.capture.scene_fit`); heights
"above the surface" are vertical distances (for a floor tilted by 1 degree they differ from distances
along its normal by 0.015 %).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StaticSurfaces:
    """The planes and boxes attached to the world body of a MuJoCo model.

    Attributes:
        plane_point: (p, 3) a point of each plane [m].
        plane_normal: (p, 3) unit normal (the free side) of each plane.
        box_center: (b, 3) box centres [m].
        box_rot: (b, 3, 3) box orientations (columns = box axes in world).
        box_half: (b, 3) half sizes [m].
        names: names of the surfaces, planes first.
    """

    plane_point: np.ndarray
    plane_normal: np.ndarray
    box_center: np.ndarray
    box_rot: np.ndarray
    box_half: np.ndarray
    names: tuple[str, ...]

    @classmethod
    def from_model(cls, model, data=None) -> StaticSurfaces:
        """Collect geoms of type plane and box that belong to the world body (body 0).

        Args:
            model: MjModel. data: optional MjData; world geom poses are computed by mj_kinematics.
        Returns:
            StaticSurfaces (possibly empty).
        """
        import mujoco

        if data is None:
            data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        pp, pn, bc, br, bh, names = [], [], [], [], [], []
        for g in range(model.ngeom):
            if model.geom_bodyid[g] != 0:
                continue
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}"
            R = data.geom_xmat[g].reshape(3, 3).copy()
            if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE:
                pp.append(data.geom_xpos[g].copy())
                pn.append(R[:, 2])
                names.append(name)
        for g in range(model.ngeom):
            if model.geom_bodyid[g] != 0 or model.geom_type[g] != mujoco.mjtGeom.mjGEOM_BOX:
                continue
            bc.append(data.geom_xpos[g].copy())
            br.append(data.geom_xmat[g].reshape(3, 3).copy())
            bh.append(model.geom_size[g].copy())
            names.append(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}")
        return cls(
            np.array(pp, float).reshape(-1, 3),
            np.array(pn, float).reshape(-1, 3),
            np.array(bc, float).reshape(-1, 3),
            np.array(br, float).reshape(-1, 3, 3),
            np.array(bh, float).reshape(-1, 3),
            tuple(names),
        )

    @property
    def count(self) -> int:
        return len(self.plane_point) + len(self.box_center)

    def penetration(self, points: np.ndarray, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Penetration depth of points into each surface, and its gradient.

        Plane: depth = max(0, margin - n.(p - p0)). Box (grown by `margin` on every side): for a point
        inside, the distance to the nearest face (the shortest way out), else 0; the gradient is minus
        that face's outward normal. With margin 0 this is the paper's eq. 12 constraint per point.

        Args:
            points: (..., 3) world positions [m].
            margin: [m] safety distance counted as penetration (0 for the true depth).
        Returns:
            depth: (..., S) depth [m] >= 0 for each of the S surfaces (planes then boxes).
            grad: (..., S, 3) d depth / d point.
        """
        pts = np.asarray(points, float)
        shape = pts.shape[:-1]
        depths, grads = [], []
        if len(self.plane_point):
            s = np.einsum("...pk,pk->...p", pts[..., None, :] - self.plane_point, self.plane_normal)
            d = np.maximum(0.0, margin - s)
            g = np.where((d > 0)[..., None], -self.plane_normal, 0.0)
            depths.append(d)
            grads.append(np.broadcast_to(g, shape + g.shape[-2:]))
        if len(self.box_center):
            local = np.einsum("bji,...bj->...bi", self.box_rot, pts[..., None, :] - self.box_center)
            gap = self.box_half + margin - np.abs(local)  # (..., b, 3): > 0 inside along that axis
            inside = (gap > 0).all(axis=-1)
            axis = np.argmin(gap, axis=-1)
            d = np.where(inside, np.take_along_axis(gap, axis[..., None], -1)[..., 0], 0.0)
            sign = np.sign(np.take_along_axis(local, axis[..., None], -1)[..., 0])
            sign = np.where(sign == 0, 1.0, sign)
            normal_world = np.take_along_axis(
                np.broadcast_to(np.swapaxes(self.box_rot, -1, -2), local.shape[:-1] + (3, 3)),
                axis[..., None, None],
                -2,
            )[..., 0, :] * sign[..., None]
            g = np.where(inside[..., None], -normal_world, 0.0)
            depths.append(d)
            grads.append(g)
        if not depths:
            return np.zeros(shape + (0,)), np.zeros(shape + (0, 3))
        return np.concatenate(depths, axis=-1), np.concatenate(grads, axis=-2)

    def signed_distances(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance of points to each surface (negative inside), and its gradient.

        Plane: n.(p - p0). Box: the exact signed distance of a box (outside: the distance to it, inside:
        minus the distance to the nearest face; Quilez, "Distance functions", 2008), continuously
        differentiable outside; its gradient is the unit vector from the nearest point of the box (the
        nearest face's outward normal inside).

        Args:
            points: (..., 3) world positions [m].
        Returns:
            distance: (..., S) [m] for the S surfaces (planes then boxes). grad: (..., S, 3).
        """
        pts = np.asarray(points, float)
        shape = pts.shape[:-1]
        out, grads = [], []
        if len(self.plane_point):
            out.append(np.einsum("...pk,pk->...p", pts[..., None, :] - self.plane_point, self.plane_normal))
            grads.append(np.broadcast_to(self.plane_normal, shape + self.plane_normal.shape))
        if len(self.box_center):
            each = [_box_distance(pts, c, r, h) for c, r, h in zip(self.box_center, self.box_rot, self.box_half)]
            out.append(np.stack([d for d, _ in each], axis=-1))
            grads.append(np.stack([g for _, g in each], axis=-2))
        if not out:
            return np.zeros(shape + (0,)), np.zeros(shape + (0, 3))
        return np.concatenate(out, axis=-1), np.concatenate(grads, axis=-2)

    def box_distance(self, points: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
        """The signed distance of points to box b alone (`signed_distances`) and its gradient.

        Args:
            points: (..., 3) world positions [m]. b: the box's index among the boxes.
        Returns:
            distance: (...,) [m]. grad: (..., 3).
        """
        return _box_distance(np.asarray(points, float), self.box_center[b], self.box_rot[b], self.box_half[b])

    def surface_below(self, points: np.ndarray) -> np.ndarray:
        """Height of the highest static surface under each point (floor planes, tops of boxes).

        A plane counts everywhere (its height at the point's x, y; a vertical plane, a wall, has none).
        A box counts where the vertical line through the point crosses its top face (the face whose
        outward normal points most upward), with that face's height there: exact for a box rotated
        about z only (a level top) and for one tilted with a tilted floor (`runner.capture.scene_fit`). Beside
        a tilted box's edge its side wall leans out by up to its height times the tilt; a point over
        that band is over the floor here (a wall is no surface to stand on).

        Args:
            points: (..., 3) positions [m].
        Returns:
            (...,) surface height [m]; -inf where there is no surface at all.
        """
        pts = np.asarray(points, float)
        h = np.full(pts.shape[:-1], -np.inf)
        for p0, nrm in zip(self.plane_point, self.plane_normal):
            if abs(nrm[2]) < 1e-6:
                continue  # a vertical plane (a wall) has no height
            h = np.maximum(h, _plane_height(pts, p0, nrm))
        if len(self.box_center):
            h = np.maximum(h, self.box_tops_below(pts).max(axis=-1))
        return h

    def box_tops_below(self, points: np.ndarray) -> np.ndarray:
        """Height of each box's top face under each point (`surface_below`), -inf where it is not under it.

        Args:
            points: (..., 3) positions [m].
        Returns:
            (..., b) heights [m], boxes in `box_center` order.
        """
        pts = np.asarray(points, float)
        out = np.full(pts.shape[:-1] + (len(self.box_center),), -np.inf)
        for i, (c, rot, half) in enumerate(zip(self.box_center, self.box_rot, self.box_half)):
            a = int(np.argmax(np.abs(rot[2])))  # the box axis nearest to vertical
            n = rot[:, a] * np.sign(rot[2, a])  # outward normal of the top face
            z = _plane_height(pts, c + half[a] * n, n)
            on_top = np.concatenate([pts[..., :2], z[..., None]], axis=-1)
            local = (on_top - c) @ rot  # box coordinates of the point of the top face under the point
            inside = np.ones(z.shape, bool)
            for b in range(3):
                if b != a:
                    inside &= np.abs(local[..., b]) <= half[b]
            out[..., i] = np.where(inside, z, -np.inf)
        return out

    def height_above(self, points: np.ndarray) -> np.ndarray:
        """Height of points above the surface below them [m] (negative: inside or under it).

        The vertical distance to `surface_below`: the surface a point would land on, or the one it is in.

        Args:
            points: (..., 3) positions [m].
        Returns:
            (...,) heights [m]; +inf where nothing is below.
        """
        pts = np.asarray(points, float)
        return pts[..., 2] - self.surface_below(pts)


def _plane_height(pts: np.ndarray, p0: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """(...,) height [m] at the x, y of (..., 3) points of the plane through p0 with normal nrm (nrm[2] != 0)."""
    return p0[2] - (nrm[0] * (pts[..., 0] - p0[0]) + nrm[1] * (pts[..., 1] - p0[1])) / nrm[2]


def _box_parts(pts: np.ndarray, center: np.ndarray, rot: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, ...]:
    """(local, q, q+, |q+|, d) of (..., 3) points against one box (`_box_distance`): box coordinates, the
    excess over the half sizes, its positive part and that part's length, and the signed distance d."""
    local = (pts - center) @ rot
    q = np.abs(local) - half
    qo = np.maximum(q, 0.0)
    outside = np.sqrt((qo * qo).sum(-1))
    return local, q, qo, outside, outside + np.minimum(q.max(-1), 0.0)


def _box_distance(pts: np.ndarray, center: np.ndarray, rot: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The exact signed distance (...,) of (..., 3) points to one box (centre (3,), axes the columns of rot
    (3, 3), half sizes (3,)) and its gradient (..., 3) (`StaticSurfaces.signed_distances`)."""
    local, q, qo, outside, d = _box_parts(pts, center, rot, half)
    sign = np.where(local < 0, -1.0, 1.0)
    g_local = np.where((outside > 0)[..., None], qo / np.maximum(outside, 1e-300)[..., None], np.eye(3)[np.argmax(q, axis=-1)])
    return d, (g_local * sign) @ rot.T
