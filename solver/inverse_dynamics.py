"""Inverse dynamics of the figure along a path: generalized forces and their gradients, vectorized.

The joint-torque and root-residual terms (paper sec. 6, appendix A) need, at every quadrature point,
the generalized forces that produce the motion (qpos, qvel, qacc) - MuJoCo's `mj_inverse` - and the
gradient of a scalar function of them with respect to the pose, qvel and qacc. This module gives two
interchangeable engines with the same interface:

`InverseDynamics` (the default): the recursive Newton-Euler algorithm written once in numpy over all
samples and all bodies at once, with a hand-written reverse pass (a vector-Jacobian product, so the
cost of the gradient does not grow with nv). It reproduces `mj_inverse` of the model with constraints
disabled to rounding error (checked at construction) for trees of free, ball and welded bodies, with
joint armature and damping. The pose enters through world rotations; every rotation adjoint is a
world 3-vector (delta R = [delta theta]x R), so the reverse pass of the kinematic chain is a subtree sum.

`MujocoInverseDynamics` (`solver.inverse_dynamics_mujoco`, re-exported here): the same interface
computed by MuJoCo, general but about 100x slower; the reference the tests compare against.

The equations (world frame, spatial vectors about the world origin; s_j = R_b v_j the joint's relative
angular velocity, A_j its anchor, "anc" = sum over the body's ancestors and itself):

    omega_b = anc(s)                nu_b = anc(A x s) + v_root     (velocity of the point at the origin)
    alpha_b = anc(R a + omega x s)  nudot_b = anc(A x R a + omega x (A x s) + nu x s) + a_root
    v_c = nu + omega x c,  a_c = nudot + alpha x c + omega x v_c       (c: the body's centre of mass)
    f = m (a_c - g),  n = I alpha + omega x I omega (I in world)      (Newton-Euler, appendix A eq. 21)
    F = (n + c x f, f) summed over each subtree;  tau_j = R_b^T (F_n - A_j x F_f)   (+ armature, damping)

Appendix A of the paper does the same with quaternions directly (eq. 13 positions, eq. 18-21 torque).
The generalized forces are MuJoCo's: a ball joint's 3 in the child's local frame [N m]; a free joint's
first 3 the world force [N], last 3 the torque about the body origin in the body frame [N m].

Both engines compute the contact-free inverse dynamics, tau = M(q) qacc + c(q, qvel) - qfrc_passive:
contacts and other constraints are not part of it (the root-residual term handles ground contact with
a flight indicator instead). An engine is not thread-safe; make one per thread.
"""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.inverse_dynamics_mujoco import InverseDynamicsResult, MujocoInverseDynamics, constraint_free_copy
from solver.layout import site_ids
from solver.spatial import cross, mtv, mv, qmat, qmul

__all__ = ["InverseDynamics", "InverseDynamicsResult", "MujocoInverseDynamics", "constraint_free_copy"]


class InverseDynamics:
    """Vectorized recursive Newton-Euler inverse dynamics with a reverse-mode gradient.

    Supports kinematic trees whose moving bodies each have one free joint (child of a static body),
    one ball joint, or no joint (welded to the parent); joint armature and damping; gravity. Anything
    else (hinge or slide joints, springs, gravity compensation, fluid forces, tendons) raises InputError
    naming the feature; use `MujocoInverseDynamics` for such models.

    Args:
        model: MjModel (loaded once by the caller; not modified).
        sites: names of sites whose world positions `forward` also returns and whose gradients `vjp`
            accepts (e.g. the contact sites), default none.
    Raises:
        InputError: unsupported model features (listed), an unknown site name, or a mismatch with
            `mj_inverse` on a random state (a model feature this engine does not model).
    """

    def __init__(self, model, sites=()):
        import mujoco

        self.model = model
        self.nq, self.nv = int(model.nq), int(model.nv)
        self._check_supported(model)
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)

        nb = model.nbody
        parent = model.body_parentid
        has_joint = model.body_jntnum > 0
        moving = np.zeros(nb, bool)
        for b in range(1, nb):
            moving[b] = has_joint[b] or moving[parent[b]]
        bodies = np.flatnonzero(moving)
        index = {int(b): i for i, b in enumerate(bodies)}
        B = len(bodies)
        self.bodies = bodies
        par = np.array([index.get(int(parent[b]), -1) for b in bodies], int)
        kind = np.zeros(B, int)  # 0 weld, 1 ball, 2 free
        quat_q = np.zeros((B, 4), int)
        ang_v = np.zeros((B, 3), int)
        lin_q = np.zeros((B, 3), int)
        lin_v = np.zeros((B, 3), int)
        jpos = np.zeros((B, 3))
        for i, b in enumerate(bodies):
            if not has_joint[b]:
                continue
            j = int(model.body_jntadr[b])
            qa, da = int(model.jnt_qposadr[j]), int(model.jnt_dofadr[j])
            jpos[i] = model.jnt_pos[j]
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                kind[i] = 2
                lin_q[i], lin_v[i] = range(qa, qa + 3), range(da, da + 3)
                quat_q[i], ang_v[i] = range(qa + 3, qa + 7), range(da + 3, da + 6)
            else:
                kind[i] = 1
                quat_q[i], ang_v[i] = range(qa, qa + 4), range(da, da + 3)
        self.kind = kind
        rot = np.flatnonzero(kind > 0)
        # a slice when every moving body has a rotational joint (the figure): views, not gathers
        self._rs = slice(None) if len(rot) == B else rot
        free = np.flatnonzero(kind == 2)
        self._rot, self._free = rot, free
        self._quat_q, self._ang_v = quat_q[rot], ang_v[rot]
        self._lin_q, self._lin_v = lin_q[free], lin_v[free]

        # body frame relative to the parent (for top-level bodies: relative to the world, folding in the
        # static parent's pose); free bodies: their qpos is the world pose.
        bq = np.array(model.body_quat[bodies], float)
        bpos = np.array(model.body_pos[bodies], float)
        for i, b in enumerate(bodies):
            if par[i] < 0 and kind[i] != 2:
                p = parent[b]
                Rp = data.xmat[p].reshape(3, 3)
                bpos[i] = data.xpos[p] + Rp @ bpos[i]
                bq[i] = qmul(data.xquat[p][:, None], bq[i][:, None])[:, 0]
        bq /= np.linalg.norm(bq, axis=1, keepdims=True)
        Rbq = np.moveaxis(qmat(bq.T), -1, 0)  # (B, 3, 3)
        self._bq = bq.T[:, :, None]  # (4, B, 1)
        self._bq_identity = bool(np.allclose(bq, [1, 0, 0, 0]))
        # anchor offset in the parent frame: d = pos + Rbq jpos
        d = bpos + np.einsum("bij,bj->bi", Rbq, jpos)
        self._top = np.flatnonzero((par < 0) & (kind != 2))  # bodies hanging from a static parent
        self._child = np.flatnonzero(par >= 0)  # bodies with a moving parent
        self._par = par
        self._d_child = d[self._child].T[:, :, None]  # (3, c, 1)
        self._d_top = d[self._top].T[:, :, None]
        self._jpos = jpos.T[:, :, None]
        self._has_jpos = bool(np.any(jpos != 0))
        # tree matrices: anc[b, a] = 1 if a is b or an ancestor of b (moving bodies only)
        anc = np.zeros((B, B))
        for i in range(B):
            a = i
            while a >= 0:
                anc[i, a] = 1.0
                a = par[a]
        self._anc = anc
        self._desc = np.ascontiguousarray(anc.T)
        P = np.zeros((B, B))  # P[p, i] = 1 if p is the parent of i
        for i in self._child:
            P[par[i], i] = 1.0
        self._parent_mat = np.ascontiguousarray(P[:, self._child])
        depth = anc.sum(1).astype(int)
        self._levels = [np.flatnonzero(depth == k) for k in range(2, int(depth.max()) + 1)] if B else []
        # inertia: mass, com offset in the body frame, inertia about the com in the body frame
        self._mass = np.array(model.body_mass[bodies], float)[:, None]
        self._ipos = np.array(model.body_ipos[bodies], float).T[:, :, None]
        Ri = np.moveaxis(qmat(np.array(model.body_iquat[bodies], float).T), -1, 0)
        Ic = np.einsum("bij,bj,bkj->bik", Ri, np.array(model.body_inertia[bodies], float), Ri)
        self._Ic = np.moveaxis(Ic, 0, -1)[..., None]  # (3, 3, B, 1)
        flags = int(model.opt.disableflags)
        no_gravity = flags & int(mujoco.mjtDisableBit.mjDSBL_GRAVITY)
        self._gravity = np.zeros(3) if no_gravity else np.array(model.opt.gravity, float)
        self._armature = np.array(model.dof_armature, float)
        damp = np.array(model.dof_damping, float)
        self._damping = np.zeros(self.nv) if flags & int(mujoco.mjtDisableBit.mjDSBL_DAMPER) else damp
        # sites
        self.site_ids = site_ids(model, sites)
        sb = model.site_bodyid[self.site_ids]
        if not all(int(b) in index for b in sb):
            raise InputError("sites must be on moving bodies of the figure, not on a static body")
        self._site_body = np.array([index[int(b)] for b in sb], int)
        self._site_pos = np.array(model.site_pos[self.site_ids], float).T[:, :, None]  # (3, K, 1)
        S = np.zeros((B, len(self.site_ids)))
        S[self._site_body, np.arange(len(self.site_ids))] = 1.0
        self._site_mat = S
        self._cache: InverseDynamicsResult | None = None
        self._self_check(model)

    # -----------------------------------------------------------------------------------------------
    @staticmethod
    def _check_supported(model):
        import mujoco

        problems = []
        types = {int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_BALL)}
        for b in range(1, model.nbody):
            if model.body_jntnum[b] > 1:
                name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b)
                problems.append(f"body {name!r} has several joints")
        for j in range(model.njnt):
            if int(model.jnt_type[j]) not in types:
                name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
                problems.append(f"joint {name!r} is a hinge or slide joint (only free and ball are modelled)")
            elif model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE and np.any(model.jnt_pos[j] != 0):
                name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
                problems.append(f"free joint {name!r} has a nonzero pos")
        spring_off = int(model.opt.disableflags) & int(mujoco.mjtDisableBit.mjDSBL_SPRING)
        if not spring_off and np.any(model.jnt_stiffness != 0):
            problems.append("joint stiffness (springs)")
        if np.any(model.body_gravcomp != 0):
            problems.append("gravity compensation (body gravcomp)")
        if model.opt.density != 0 or model.opt.viscosity != 0:
            problems.append("fluid forces (option density/viscosity)")
        if model.ntendon:
            problems.append("tendons")
        if problems:
            raise InputError(
                "the analytic inverse dynamics does not model: " + "; ".join(problems)
                + ". Use MujocoInverseDynamics (backend='mujoco') for this model."
            )

    def _self_check(self, model):
        """Compare with mj_inverse (constraints disabled) at a random state; raise on mismatch."""
        import mujoco

        rng = np.random.default_rng(12345)
        m = constraint_free_copy(model)
        d = mujoco.MjData(m)
        qpos = np.array(model.qpos0, float)
        for i in range(len(self._quat_q)):
            q = rng.normal(size=4)
            qpos[self._quat_q[i]] = q / np.linalg.norm(q)
        qvel, qacc = rng.normal(size=self.nv), rng.normal(size=self.nv)
        d.qpos[:], d.qvel[:], d.qacc[:] = qpos, qvel, qacc
        mujoco.mj_inverse(m, d)
        tau = self.forward(qpos[None], qvel[None], qacc[None]).tau[0]
        self._cache = None
        err = np.abs(tau - d.qfrc_inverse).max()
        if not err <= 1e-8 * (1.0 + np.abs(d.qfrc_inverse).max()):
            raise InputError(
                f"the analytic inverse dynamics differs from mj_inverse by {err:.3g} on this model (a model "
                "feature it does not model); use MujocoInverseDynamics (backend='mujoco')"
            )

    # -----------------------------------------------------------------------------------------------
    def forward(self, qpos: np.ndarray, qvel: np.ndarray, qacc: np.ndarray) -> InverseDynamicsResult:
        """Generalized forces of the motion (qpos, qvel, qacc) at n samples, and site positions.

        The last result is cached (compared by value), so two terms sharing an engine pay once.

        Args:
            qpos: (n, nq) positions; quaternions need not be unit (normalized here, as MuJoCo does).
            qvel: (n, nv) [m/s, rad/s]. qacc: (n, nv) [m/s^2, rad/s^2].
        Returns:
            InverseDynamicsResult with tau (n, nv) [N, N m] and sites (n, k, 3) [m].
        """
        c = self._cache
        if c is not None and c.matches(qpos, qvel, qacc):
            return c
        n = qpos.shape[0]
        B = len(self.bodies)
        rot, free = self._rot, self._free
        qp, qv, qa = qpos.T, qvel.T, qacc.T

        # --- pose: world quaternions Q (4, B, n) down the tree, rotations R (3, 3, B, n)
        U = np.zeros((4, B, n))
        U[0] = 1.0
        q = qp[self._quat_q.T]  # (4, r, n)
        U[:, rot] = q / np.sqrt((q * q).sum(0))
        W = U if self._bq_identity else qmul(self._bq, U)
        if len(free) and not self._bq_identity:
            W[:, free] = U[:, free]
        Q = W.copy()
        for lvl in self._levels:
            Q[:, lvl] = qmul(Q[:, self._par[lvl]], W[:, lvl])
        R = qmat(Q)
        # positions: x = anc(e), e = R_parent d - R jpos (child), const - R jpos (top), p (free)
        e = np.zeros((3, B, n))
        ch = self._child
        Rpd = mv(R[:, :, self._par[ch]], self._d_child) if len(ch) else np.zeros((3, 0, n))
        e[:, ch] = Rpd
        if len(self._top):
            e[:, self._top] = self._d_top
        Rj = mv(R, self._jpos) if self._has_jpos else None
        if Rj is not None:
            e -= Rj
        e[:, free] = qp[self._lin_q.T]
        x = self._anc @ e
        A = x + Rj if Rj is not None else x
        cx = mv(R, self._ipos)
        com = x + cx

        # --- velocities and accelerations (spatial, about the world origin)
        vl = np.zeros((3, B, n))
        vl[:, rot] = qv[self._ang_v.T]
        al_loc = np.zeros((3, B, n))
        al_loc[:, rot] = qa[self._ang_v.T]
        s = mv(R, vl)
        om = self._anc @ s
        k = cross(A, s)
        lin = np.zeros((3, B, n))
        lin[:, free] = qv[self._lin_v.T]
        nu = self._anc @ (k + lin)
        as_ = mv(R, al_loc)
        al = self._anc @ (as_ + cross(om, s))
        lin = np.zeros((3, B, n))
        lin[:, free] = qa[self._lin_v.T]
        nud = self._anc @ (cross(A, as_) + cross(om, k) + cross(nu, s) + lin)
        vc = nu + cross(om, com)
        ac = nud + cross(al, com) + cross(om, vc)

        # --- Newton-Euler per body, wrenches about the origin, summed over subtrees
        f = self._mass * (ac - self._gravity[:, None, None])
        wl = mtv(R, om)
        all_ = mtv(R, al)
        Ic = self._Ic
        h = mv(Ic, wl)
        nl = mv(Ic, all_) + cross(wl, h)
        nw = mv(R, nl)
        Fn = self._desc @ (nw + cross(com, f))
        Ff = self._desc @ f
        Wt = Fn - cross(A, Ff)
        rs = self._rs
        tq = mtv(R[:, :, rs], Wt[:, rs])  # (3, r, n)
        tau = np.empty((self.nv, n))
        tau[self._ang_v.T] = tq
        tau[self._lin_v.T] = Ff[:, free]
        tau += self._armature[:, None] * qa + self._damping[:, None] * qv

        # --- sites
        sb = self._site_body
        ry = mv(R[:, :, sb], self._site_pos)
        ys = x[:, sb] + ry
        ysd = nu[:, sb] + cross(om[:, sb], ys)  # site velocities: nu is the velocity of the origin point

        saved = dict(
            R=R, x=x, A=A, cx=cx, com=com, Rpd=Rpd, Rj=Rj, s=s, om=om, k=k, nu=nu, as_=as_, al=al,
            vc=vc, f=f, wl=wl, h=h, nw=nw, Ff=Ff, Wt=Wt, ry=ry, ys=ys,
            site_vel=np.ascontiguousarray(ysd.transpose(2, 1, 0)),
        )
        res = InverseDynamicsResult(
            np.ascontiguousarray(tau.T), np.ascontiguousarray(ys.transpose(2, 1, 0)),
            qpos.copy(), qvel.copy(), qacc.copy(), saved,
        )
        self._cache = res
        return res

    @staticmethod
    def site_velocities(res: InverseDynamicsResult) -> np.ndarray:
        """(n, k, 3) world velocities [m/s] of the engine's sites at the samples of `forward`'s result
        (nu_b + omega_b x y: the velocity of the site's point of its body)."""
        return res.saved["site_vel"]

    def vjp(
        self, res: InverseDynamicsResult, g_tau: np.ndarray, g_sites: np.ndarray | None = None,
        g_site_vel: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Gradient of phi = sum g_tau . tau + sum g_sites . sites (+ sum g_site_vel . site velocities)
        with respect to pose, qvel, qacc.

        Reverse pass of `forward` (exact, not finite differences). The pose gradient is MuJoCo's
        tangent convention (the rows of `mjd_inverseFD`'s DfDq): free joint, world translation then
        a rotation in the body frame; ball joint, a rotation in the child frame. Map it to qpos
        components with `TangentMap.pullback` (or `PathMotion.vjp(..., g_pose=...)`).

        Args:
            res: the result of `forward` at the samples.
            g_tau: (n, nv) d phi / d tau. g_sites: (n, k, 3) d phi / d site position, or None.
            g_site_vel: (n, k, 3) d phi / d site velocity (`site_velocities`), or None.
        Returns:
            g_pose (n, nv), g_qvel (n, nv), g_qacc (n, nv). g_qacc = M(q) g_tau (M with armature).
        """
        sv = res.saved
        R, A, com, s, om = sv["R"], sv["A"], sv["com"], sv["s"], sv["om"]
        k, nu, as_, al = sv["k"], sv["nu"], sv["as_"], sv["al"]
        rot, free, rs = self._rot, self._free, self._rs
        n = g_tau.shape[0]
        B = len(self.bodies)
        anc, desc = self._anc, self._desc
        gT = g_tau.T
        Ga = self._armature[:, None] * gT
        Gv = self._damping[:, None] * gT
        Gq = np.zeros((self.nv, n))

        tbar = np.zeros((3, B, n))
        tbar[:, rot] = gT[self._ang_v.T]
        What = mv(R, tbar)
        gth = cross(What, sv["Wt"])
        Ffbar = cross(A, What)
        Ffbar[:, free] += gT[self._lin_v.T]
        Abar = cross(What, sv["Ff"])
        nbar = anc @ What  # wrench adjoint of each body: sum over its ancestors' joints
        fbar = anc @ Ffbar
        f = sv["f"]
        cbar = cross(f, nbar)
        fbar += cross(nbar, com)
        gth += cross(sv["nw"], nbar)
        nlbar = mtv(R, nbar)
        Ic = self._Ic
        wl = sv["wl"]
        albar_l = mv(Ic, nlbar)
        hbar = cross(nlbar, wl)
        wlbar = cross(sv["h"], nlbar) + mv(Ic, hbar)
        wbar = mv(R, wlbar)
        gth += cross(wbar, om)
        albar = mv(R, albar_l)
        gth += cross(albar, al)
        acbar = self._mass * fbar
        vc = sv["vc"]
        nudbar = acbar
        albar += cross(com, acbar)
        cbar += cross(acbar, al)
        wbar += cross(vc, acbar)
        vcbar = cross(acbar, om)
        nubar = vcbar
        if g_site_vel is not None and len(self._site_body):
            # ysd = nu_b + om_b x ys: nu_b += g, om_b += ys x g, ys += g x om_b
            gsv = np.swapaxes(np.moveaxis(g_site_vel, -1, 0), 1, 2)  # (3, K, n)
            ys_s = sv["ys"]
            nubar = nubar + self._site_mat @ gsv
            wbar = wbar + self._site_mat @ cross(ys_s, gsv)
            gys = cross(gsv, om[:, self._site_body])
            g_sites = gys.transpose(2, 1, 0) if g_sites is None else g_sites + gys.transpose(2, 1, 0)
        wbar += cross(com, vcbar)
        cbar += cross(vcbar, om)
        xbar = cbar
        gth += cross(sv["cx"], cbar)
        if g_sites is not None and len(self._site_body):
            ybar = np.moveaxis(g_sites, -1, 0)  # (3, n, K) -> want (3, K, n)
            ybar = np.swapaxes(ybar, 1, 2)
            Sm = self._site_mat
            xbar = xbar + Sm @ ybar
            gth += Sm @ cross(sv["ry"], ybar)
        # nudot = anc(z), z = A x as + om x k + nu x s + lin_acc
        zbar = desc @ nudbar
        Gl_a = zbar[:, free]
        Abar += cross(as_, zbar)
        asbar = cross(zbar, A)
        wbar += cross(k, zbar)
        kbar = cross(zbar, om)
        nubar = nubar + cross(s, zbar)
        sbar = cross(zbar, nu)
        # alpha = anc(as + om x s)
        rbar = desc @ albar
        asbar += rbar
        wbar += cross(s, rbar)
        sbar += cross(rbar, om)
        # as = R a_local
        Ga[self._ang_v.T] += mtv(R[:, :, rs], asbar[:, rs])
        gth += cross(as_, asbar)
        # nu = anc(k + lin_vel), k = A x s
        nubar = desc @ nubar
        Gl_v = nubar[:, free]
        kbar += nubar
        Abar += cross(s, kbar)
        sbar += cross(kbar, A)
        # omega = anc(s), s = R v_local
        sbar += desc @ wbar
        Gv[self._ang_v.T] += mtv(R[:, :, rs], sbar[:, rs])
        gth += cross(s, sbar)
        # A = x + R jpos
        xbar = xbar + Abar
        if sv["Rj"] is not None:
            gth += cross(sv["Rj"], Abar)
        # x = anc(e), e = R_parent d - R jpos (or p for free bodies)
        ebar = desc @ xbar
        Gq[self._lin_v.T] = ebar[:, free]
        ch = self._child
        if len(ch):
            gth += self._parent_mat @ cross(sv["Rpd"], ebar[:, ch])
        if sv["Rj"] is not None:
            gth -= cross(sv["Rj"], ebar)
        # rotations: R_b = R_parent L_b(q_b); world rotation adjoint of joint b = subtree sum
        theta = desc @ gth
        Gq[self._ang_v.T] = mtv(R[:, :, rs], theta[:, rs])
        Ga[self._lin_v.T] += Gl_a
        Gv[self._lin_v.T] += Gl_v
        return Gq.T, Gv.T, Ga.T
