"""From the spline's `qpos` (unnormalized quaternions) to MuJoCo's tangent space (`qvel`).

MuJoCo normalizes every quaternion before kinematics, so a `qpos` sample Y describes the pose with
unit quaternions u = q / |q|. A change dY moves the pose by the tangent vector (docs/design.md, "The
objective": velocities for MuJoCo)

    dv = B(Y) dY,  with  B = 2 G(u) / |q|  on each quaternion block (G(u) p = vec(conj(u) p)),
                          B = I             on root position, hinge and slide components,

so the spline's `qvel` is B(Y) Y' (ball joints: angular velocity in the child's local frame; free joint:
world linear velocity, local angular velocity) and any gradient g_v of a function of the pose with
respect to a MuJoCo tangent perturbation (what `mj_jacSite` and `mjd_inverseFD` give) becomes
dY-gradient B(Y)^T g_v. Because G(u) u = 0, B ignores the scale of q, as MuJoCo does.

`TangentMap.motion(Y, Y', Y'')` adds `qacc` (the time derivative of qvel, what `mj_inverse` reads) and
the chain rule of qvel and qacc back to Y, Y', Y'' (`PathMotion`, paper appendix A eq. 14-20).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.layout import StateLayout
from solver.quaternion import vec_of_conj_product


def _gt(q: np.ndarray, g: np.ndarray) -> np.ndarray:
    """G(q)^T g = q * (0, g) (Hamilton product), component-first: (4, ...) q, (3, ...) g -> (4, ...)."""
    w, x, y, z = q
    a, b, c = g
    return np.stack(
        [-x * a - y * b - z * c, w * a - z * b + y * c, z * a + w * b - x * c, -y * a + x * b + w * c]
    )


def _gq(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """G(q) p = vec(conj(q) p), component-first: (4, ...) q and p -> (3, ...)."""
    w, x, y, z = q
    a, b, c, d = p
    return np.stack(
        [-x * a + w * b + z * c - y * d, -y * a - z * b + w * c + x * d, -z * a + y * b - x * c + w * d]
    )


@dataclass(frozen=True)
class PathMotion:
    """`qvel` and `qacc` of a path Y(t) and their Jacobians with respect to Y, Y', Y''.

    Built by `TangentMap.motion`. For each quaternion slot q (not unit; s = q.q), with G as in
    `solver.quaternion.vec_of_conj_product` (G(q) p = vec(conj(q) p), linear in q):

        omega = 2 G(q) q' / s                                   (= 2 vec(conj(u) u'), u = q/|q|)
        alpha = d omega/dt = 2 G(q) q'' / s - 4 (q.q') G(q) q' / s^2
                           (= 2 vec(conj(u) u''); vec(conj(q') q') = 0)

    which is the paper's appendix A eq. 19-20 (omega = 2 Q' Q^-1, omega' = 2 (Q'' Q^-1 + Q' (Q^-1)')) in
    the body frame (conj(q) on the left instead of Q^-1 on the right), with the derivatives of the
    inverse (eq. 14-17) folded into the 1/s factors. Root position, hinge and slide components:
    qvel = Y', qacc = Y''. With w = G(q) q', z = G(q) q'', a = q.q' and d(G(q) p)/dq = -G(p):

        d omega/dq'  = 2 G(q)/s  (= B)    d omega/dq = -2 G(q')/s - 4 w q^T/s^2
        d alpha/dq'' = 2 G(q)/s  (= B)    d alpha/dq' = -4 (w q^T + a G(q))/s^2
        d alpha/dq   = -2 G(q'')/s - 4 (z q^T + w q'^T - a G(q'))/s^2 + 16 a w q^T/s^3

    The per-slot arrays are stored component-first (that layout makes the vectorized products cheap).

    Attributes:
        qvel: (n, nv) [m/s, rad/s]; qacc: (n, nv) [m/s^2, rad/s^2], MuJoCo's convention (ball and free
            angular parts in the child's local frame, free linear part in the world frame). May be
            non-contiguous (transposed) views. qacc, q2 and z are None for a motion built without Y''.
        tmap: the TangentMap. q, q1, q2: (4, s, n) quaternion slots of Y, Y', Y''. ss: (s, n) q.q;
        a: (s, n) q.q'; w, z: (3, s, n) G(q) q', G(q) q''.
    """

    qvel: np.ndarray
    qacc: np.ndarray | None
    tmap: TangentMap
    q: np.ndarray
    q1: np.ndarray
    q2: np.ndarray
    ss: np.ndarray
    a: np.ndarray
    w: np.ndarray
    z: np.ndarray

    def vjp(
        self, g_v: np.ndarray | None, g_a: np.ndarray | None, g_pose: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pull gradients with respect to qvel, qacc (and the pose) back to Y, Y', Y'' in one pass.

        Args:
            g_v: (n, nv) d f / d qvel, or None (zero). g_a: (n, nv) d f / d qacc, or None.
            g_pose: (n, nv) d f / d pose in MuJoCo's tangent convention at fixed qvel and qacc (what
                `mjd_inverseFD`'s DfDq or `mj_jacSite` give), or None; adds B(Y)^T g_pose to dY, as
                `TangentMap.pullback` does.
        Returns:
            dY, dY1, dY2: (n, nq) each, g_v^T dqvel/dX + g_a^T dqacc/dX (+ g_pose^T B for X = Y).
        """
        tm = self.tmap
        n = self.qvel.shape[0]
        dY, dY1, dY2 = (np.zeros((tm.nq, n)) for _ in range(3))
        q, q1, q2, s, a, w, z = self.q, self.q1, self.q2, self.ss, self.a, self.w, self.z
        qv, qq = tm.quat_v.T, tm.quat_q.T
        c2 = 2.0 / s
        c4 = c2 * c2
        # gradients of the angular parts (3, s, n); zero where an argument is None
        zero = np.zeros(w.shape)
        gv = zero if g_v is None else g_v.T[qv]
        ga = None if g_a is None else g_a.T[qv]
        if g_v is not None:
            dY1[tm.lin_q] = g_v.T[tm.lin_v]
        if g_a is not None:
            if self.qacc is None:
                raise ValueError("this PathMotion has no qacc (built without Y''); pass g_a=None")
            dY2[tm.lin_q] = g_a.T[tm.lin_v]
            dY2[qq] = _gt(q, c2 * ga)
        wgv = (w * gv).sum(0)
        if g_a is None:  # d omega/dq' and d omega/dq only (also when the motion has no qacc)
            dY1[qq] = _gt(q, c2 * gv)
            gq = -_gt(q1, c2 * gv) - (c4 * wgv) * q
        else:
            wga = (w * ga).sum(0)
            zga = (z * ga).sum(0)
            c4a = c4 * a
            # d omega/dq' and d alpha/dq' (transposed, applied)
            dY1[qq] = _gt(q, c2 * gv - c4a * ga) - (c4 * wga) * q
            # d omega/dq and d alpha/dq (transposed, applied)
            gq = _gt(q1, c4a * ga - c2 * gv) - _gt(q2, c2 * ga)
            gq += (c4a * (2.0 * c2) * wga - c4 * (wgv + zga)) * q - (c4 * wga) * q1
        if g_pose is not None:
            gp = g_pose.T
            dY[tm.lin_q] = gp[tm.lin_v]
            gq += _gt(q, c2 * gp[qv])
        dY[qq] = gq
        return dY.T, dY1.T, dY2.T

    def jacobians(self) -> dict[str, np.ndarray]:
        """Dense Jacobians (for tests and inspection; the optimizer uses `vjp`).

        Returns:
            {"dv_dY", "dv_dY1", "da_dY", "da_dY1", "da_dY2"}: (n, nv, nq) arrays (d qvel / d Y'' = 0).
        """
        tm = self.tmap
        n = self.qvel.shape[0]
        out = {}
        eye = np.eye(tm.nv)
        # name: (g_v on, g_a on, which output)
        spec = {
            "dv_dY": (1, 0, 0), "dv_dY1": (1, 0, 1),
            "da_dY": (0, 1, 0), "da_dY1": (0, 1, 1), "da_dY2": (0, 1, 2),
        }
        for name, (gv_on, ga_on, k) in spec.items():
            J = np.zeros((n, tm.nv, tm.nq))
            for i in range(tm.nv):
                e = np.broadcast_to(eye[i], (n, tm.nv))
                J[:, i] = self.vjp(e if gv_on else None, e if ga_on else None)[k]
            out[name] = J
        return out


def _motion(tm: TangentMap, Y: np.ndarray, Y1: np.ndarray, Y2: np.ndarray) -> PathMotion:
    idx = tm.quat_q.T
    q, q1 = Y.T[idx], Y1.T[idx]  # (4, s, n)
    s = (q * q).sum(0)
    a = (q * q1).sum(0)
    w = _gq(q, q1)
    n = Y.shape[0]
    new = np.zeros if tm.partial else np.empty  # a partial map leaves the other components 0
    v = new((tm.nv, n))
    v[tm.lin_v] = Y1.T[tm.lin_q]
    c2 = 2.0 / s
    v[tm.quat_v.T] = c2 * w
    if Y2 is None:  # velocities only
        return PathMotion(v.T, None, tm, q, q1, None, s, a, w, None)
    q2 = Y2.T[idx]
    z = _gq(q, q2)
    acc = new((tm.nv, n))
    acc[tm.lin_v] = Y2.T[tm.lin_q]
    acc[tm.quat_v.T] = c2 * (z - (c2 * a) * w)
    return PathMotion(v.T, acc.T, tm, q, q1, q2, s, a, w, z)


@dataclass(frozen=True)
class TangentMap:
    """Index bookkeeping for B(Y): which qpos components map to which qvel components.

    Attributes:
        nq, nv: sizes of `qpos` and `qvel`.
        quat_q: (s, 4) qpos indices of each quaternion.
        quat_v: (s, 3) qvel indices of its angular velocity.
        lin_q, lin_v: (l,) matching qpos/qvel indices of the linear components.
        partial: the map covers only some joints (`subset`): `motion` leaves the other components of
            qvel and qacc 0, and its `vjp` gives 0 for them (what the full map gives for adjoints
            that are 0 there, up to the sign of those zeros).
    """

    nq: int
    nv: int
    quat_q: np.ndarray
    quat_v: np.ndarray
    lin_q: np.ndarray
    lin_v: np.ndarray
    partial: bool = False

    @classmethod
    def from_layout(cls, layout: StateLayout) -> TangentMap:
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

    def subset(self, dofs) -> TangentMap:
        """The map of only the joints whose qvel components are all in `dofs` (a quaternion slot by
        its 3, a linear component by its 1): for an engine that reads only those (the contact sites'
        kinematics reads the legs and the root, 7 of the figure's 12 quaternions), `motion` and its
        `vjp` skip the other joints' work. Each kept component is computed as by the full map, so
        bit for bit the same.

        Args:
            dofs: qvel indices.
        Returns:
            TangentMap with `partial` True (the full map itself if it keeps everything).
        """
        keep = {int(d) for d in np.ravel(dofs)}
        qs = [i for i, v in enumerate(self.quat_v) if all(int(d) in keep for d in v)]
        ls = [i for i, d in enumerate(self.lin_v) if int(d) in keep]
        if len(qs) == len(self.quat_v) and len(ls) == len(self.lin_v):
            return self
        return TangentMap(self.nq, self.nv, self.quat_q[qs].reshape(-1, 4), self.quat_v[qs].reshape(-1, 3),
                          self.lin_q[ls], self.lin_v[ls], partial=True)

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

    def motion(self, Y: np.ndarray, Y1: np.ndarray, Y2: np.ndarray | None) -> PathMotion:
        """`qvel` and `qacc` of the path at samples, with their Jacobians (see `PathMotion`).

        Args:
            Y, Y1, Y2: (n, nq) qpos and its first and second time derivatives [units/s, units/s^2].
                Y2 None: velocities only (qacc None; `vjp` then takes no g_a).
        Returns:
            PathMotion with qvel, qacc (n, nv) and `vjp` / `jacobians`. Quaternion slots must be
            nonzero (a zero quaternion gives inf/NaN; nothing is raised in this inner loop).
        """
        return _motion(self, Y, Y1, Y2)

    def acceleration(self, Y: np.ndarray, Y1: np.ndarray, Y2: np.ndarray) -> np.ndarray:
        """`qacc` of the path: the time derivative of `velocity(Y, Y')` (see `PathMotion`).

        Args:
            Y, Y1, Y2: (n, nq) qpos and its first and second time derivatives.
        Returns:
            (n, nv) qacc [m/s^2, rad/s^2] in MuJoCo's convention (what `mj_inverse` reads).
        """
        return _motion(self, Y, Y1, Y2).qacc


def mujoco_site_positions(model, data, site_ids, qpos: np.ndarray) -> np.ndarray:
    """(n, k, 3) world positions [m] of sites `site_ids` (k,) at qpos (n, nq), by MuJoCo's `mj_kinematics`
    (the reference the vectorized kinematics is checked against; `data` is overwritten)."""
    import mujoco

    out = np.empty((len(qpos), len(site_ids), 3))
    for i, y in enumerate(qpos):
        data.qpos[:] = y
        mujoco.mj_kinematics(model, data)
        out[i] = data.site_xpos[site_ids]
    return out
