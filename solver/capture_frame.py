"""The levelled capture frame: the rigid transform that makes a fitted capture floor the plane z = 0.

A capture floor that is not level (`runner.capture.scene_fit`: a plane z = a + b x + c y) is a calibration
error of the capture volume: the real floor was level and gravity normal to it. `CaptureFrame.levelling`
is the rigid transform T: x' = R x + shift with R the shortest rotation taking the floor's upward
normal n to +z (Rodrigues' formula; the inverse of `FittedScene.rotation`) and shift = (0, 0, -a n_z),
which puts the floor's points at z' = 0 (a point p of the plane has n . p = a n_z, and (R p)_z = n . p).
Expressed in that frame, the reference's root position becomes R p + shift and its root orientation
R q (every other joint is local to its parent, unchanged), the floor is z = 0 and the boxes standing on
it are square to the world axes (docs/contacts.md, "Fitted scenes").

The scene MJCF records T as `<custom><numeric name="capture:frame" data="w x y z tx ty tz"/></custom>`
(`CaptureFrame.mjcf`, read back by `CaptureFrame.from_model`), so every step that loads the scene finds
it: the import of the clip applies T to the reference, the export onto the source skeleton applies T^-1.
A scene without it (a user's scene, the shipped ones) is the identity.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.errors import InputError
from solver.quaternion import conj, mul, normalize

#: the `<custom><numeric>` name of the transform in a scene MJCF
CAPTURE_FRAME = "capture:frame"


@dataclass(frozen=True)
class CaptureFrame:
    """The rigid transform from capture coordinates to the levelled frame: x' = R(quat) x + shift.

    Attributes:
        quat: (4,) unit quaternion w x y z of R.
        shift: (3,) [m] translation applied after the rotation.
    """

    quat: np.ndarray
    shift: np.ndarray

    @classmethod
    def identity(cls) -> CaptureFrame:
        """The identity transform (a scene without a recorded capture frame)."""
        return cls(np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3))

    @classmethod
    def levelling(cls, floor_z: float, floor_slope=(0.0, 0.0)) -> CaptureFrame:
        """T taking the plane z = floor_z + b x + c y [m] (floor_slope = (b, c) [m/m]) to z = 0 (module doc).

        R is the shortest rotation taking the plane's unit normal n = (-b, -c, 1) / |.| to +z: the axis
        n x z, the angle acos(n_z); the quaternion (1 + n_z, n x z) normalized (half-angle form).
        """
        b, c = (float(v) for v in floor_slope)
        n = np.array([-b, -c, 1.0]) / np.sqrt(1.0 + b * b + c * c)
        quat = normalize(np.r_[1.0 + n[2], n[1], -n[0], 0.0])  # n x z = (n_y, -n_x, 0)
        return cls(quat, np.array([0.0, 0.0, -float(floor_z) * n[2]]))

    @property
    def is_identity(self) -> bool:
        """True when the transform moves nothing (within 1e-12)."""
        return bool(abs(abs(self.quat[0]) - 1.0) < 1e-12 and np.all(np.abs(self.shift) < 1e-12))

    def matrix(self) -> np.ndarray:
        """(3, 3) the rotation R."""
        w, x, y, z = self.quat
        return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])

    def inverse(self) -> CaptureFrame:
        """T^-1: x = R^T (x' - shift)."""
        inv = conj(self.quat)
        return CaptureFrame(inv, -(self.matrix().T @ self.shift))

    def points(self, p) -> np.ndarray:
        """(..., 3) [m] points p (..., 3) in the new frame: R p + shift."""
        p = np.asarray(p, float)
        return p @ self.matrix().T + self.shift

    def root(self, qpos, adr: int = 0) -> np.ndarray:
        """A copy of (n, nq) or (nq,) qpos with the free root at qpos[adr:adr + 7] (position [m], unit
        quaternion w x y z) expressed in the new frame: position R p + shift, orientation R q."""
        out = np.array(qpos, float, copy=True)
        pos, quat = out[..., adr:adr + 3], out[..., adr + 3:adr + 7]
        out[..., adr:adr + 3] = self.points(pos)
        out[..., adr + 3:adr + 7] = mul(np.broadcast_to(self.quat, quat.shape), quat)
        return out

    def mjcf(self) -> str:
        """The `<custom>` element recording the transform in a scene MJCF (module doc)."""
        data = " ".join(f"{v:.12g}" for v in np.r_[self.quat, self.shift])
        return f'  <custom>\n    <numeric name="{CAPTURE_FRAME}" data="{data}"/>\n  </custom>\n'

    @classmethod
    def from_model(cls, model, where: str = "the scene") -> CaptureFrame:
        """The transform a scene's MjModel records (`CAPTURE_FRAME`), or the identity when it has none.
        `where` names the scene in the error (its file).

        Raises:
            InputError: the numeric has not 7 values, or its quaternion is not of unit length (1e-6).
        """
        import mujoco

        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, CAPTURE_FRAME)
        if i < 0:
            return cls.identity()
        adr, size = int(model.numeric_adr[i]), int(model.numeric_size[i])
        data = np.array(model.numeric_data[adr:adr + size], float)
        if size != 7 or not np.all(np.isfinite(data)) or abs(np.linalg.norm(data[:4]) - 1.0) > 1e-6:
            raise InputError(f'{where}: <numeric name="{CAPTURE_FRAME}"> is {data.tolist()}; it needs 7 values '
                             '"w x y z tx ty tz" with a unit quaternion (or remove it: no transform)')
        return cls(data[:4] / np.linalg.norm(data[:4]), data[4:])
