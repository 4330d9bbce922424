"""From the spline's `qpos` (unnormalized quaternions) to MuJoCo's tangent space (`qvel`).

MuJoCo normalizes every quaternion before kinematics, so a `qpos` sample Y describes the pose with
unit quaternions u = q / |q|. A change dY moves the pose by the tangent vector (DESIGN.md, "Velocities
for MuJoCo")

    dv = B(Y) dY,  with  B = 2 G(u) / |q|  on each quaternion block (G(u) p = vec(conj(u) p)),
                          B = I             on root position, hinge and slide components,

so the spline's `qvel` is B(Y) Y' (ball joints: angular velocity in the child's local frame; free joint:
world linear velocity, local angular velocity) and any gradient g_v of a function of the pose with
respect to a MuJoCo tangent perturbation (what `mj_jacSite` and `mjd_inverseFD` give) becomes
dY-gradient B(Y)^T g_v. Because G(u) u = 0, B ignores the scale of q, as MuJoCo does.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.layout import StateLayout
from solver.quaternion import vec_of_conj_product


@dataclass(frozen=True)
class TangentMap:
    """Index bookkeeping for B(Y): which qpos components map to which qvel components.

    Attributes:
        nq, nv: sizes of `qpos` and `qvel`.
        quat_q: (s, 4) qpos indices of each quaternion.
        quat_v: (s, 3) qvel indices of its angular velocity.
        lin_q, lin_v: (l,) matching qpos/qvel indices of the linear components.
    """

    nq: int
    nv: int
    quat_q: np.ndarray
    quat_v: np.ndarray
    lin_q: np.ndarray
    lin_v: np.ndarray

    @classmethod
    def from_layout(cls, layout: StateLayout) -> "TangentMap":
        qq, qv, lq, lv = [], [], [], []
        for j in layout.joints:
            if j.kind == "free":
                lq += range(j.qposadr, j.qposadr + 3)
                lv += range(j.dofadr, j.dofadr + 3)
                qq.append(range(j.qposadr + 3, j.qposadr + 7))
                qv.append(range(j.dofadr + 3, j.dofadr + 6))
            elif j.kind == "ball":
                qq.append(range(j.qposadr, j.qposadr + 4))
                qv.append(range(j.dofadr, j.dofadr + 3))
            else:
                lq.append(j.qposadr)
                lv.append(j.dofadr)
        nv = sum(j.nv for j in layout.joints)
        return cls(
            layout.nq,
            nv,
            np.array(qq, int).reshape(-1, 4),
            np.array(qv, int).reshape(-1, 3),
            np.array(lq, int),
            np.array(lv, int),
        )

    def blocks(self, Y: np.ndarray) -> np.ndarray:
        """The quaternion blocks 2 G(u) / |q| of B(Y).

        Args:
            Y: (n, nq) qpos samples.
        Returns:
            (n, s, 3, 4) blocks, one per quaternion slot.
        """
        q = Y[:, self.quat_q]  # (n, s, 4)
        r = np.linalg.norm(q, axis=-1)
        return vec_of_conj_product(q / r[..., None]) * (2.0 / r)[..., None, None]

    def velocity(self, Y: np.ndarray, Ydot: np.ndarray, blocks: np.ndarray | None = None) -> np.ndarray:
        """`qvel` of the path: B(Y) Y'.

        Args:
            Y, Ydot: (n, nq) qpos and its time derivative [units/s].
            blocks: optional precomputed `blocks(Y)`.
        Returns:
            (n, nv) qvel [m/s, rad/s] in MuJoCo's convention.
        """
        B = self.blocks(Y) if blocks is None else blocks
        v = np.zeros((Y.shape[0], self.nv))
        v[:, self.lin_v] = Ydot[:, self.lin_q]
        v[:, self.quat_v] = np.einsum("nsij,nsj->nsi", B, Ydot[:, self.quat_q])
        return v

    def pullback(self, Y: np.ndarray, g_v: np.ndarray, blocks: np.ndarray | None = None) -> np.ndarray:
        """B(Y)^T g_v: a gradient with respect to a tangent (qvel-space) perturbation of the pose,
        as a gradient with respect to the qpos components.

        Args:
            Y: (n, nq) qpos samples.
            g_v: (n, nv) or (n, k, nv) gradients (k stacked functions).
        Returns:
            (n, nq) or (n, k, nq).
        """
        B = self.blocks(Y) if blocks is None else blocks
        squeeze = g_v.ndim == 2
        G = g_v[:, None, :] if squeeze else g_v
        out = np.zeros(G.shape[:2] + (self.nq,))
        out[:, :, self.lin_q] = G[:, :, self.lin_v]
        out[:, :, self.quat_q] = np.einsum("nsij,nksi->nksj", B, G[:, :, self.quat_v])
        return out[:, 0] if squeeze else out
