"""Forward kinematics of the figure's tree along a path, vectorized over samples, with its reverse pass.

The kinematic half of the recursive Newton-Euler algorithm (`solver.inverse_dynamics`), on its own:
world rotations, joint anchors, angular velocities and the velocity of the world origin's point of
every moving body, and the positions and velocities of tracked sites, at all samples at once (numpy
over samples and bodies), with a hand-written reverse pass (a vector-Jacobian product). In the
notation of `solver.inverse_dynamics` (world frame; s_j = R_b v_j, A_j the joint anchor, "anc" = sum
over the body's ancestors and itself):

    x_b = anc(e),  e = R_parent d - R jpos (child), const - R jpos (top), p (free);  A = x + R jpos
    omega_b = anc(s)                nu_b = anc(A x s) + v_root     (velocity of the point at the origin)
    y = x_b + R_b r,  ydot = nu_b + omega_b x y                     (a site at r in its body b)

which is the paper's appendix A eq. 13 (positions) and eq. 19 (angular velocity), with world
rotations in place of products of quaternions. Every rotation adjoint is a world 3-vector (delta R =
[delta theta]x R), so the reverse pass of the chain is a subtree sum.

`KinematicTree` is the shared base (the tree's index bookkeeping and the two passes);
`SiteKinematics` is the engine the kinematic terms (penetration, planted, clearance) share when no
dynamics term is on: the same interface as `InverseDynamics` (`solver.path_context`: `forward`,
`site_velocities`, `vjp`) without the accelerations and forces, about half its cost; without qvel its
`forward` is the positions alone (eq. 13) and its `vjp` the pose's reverse pass at the rows with a
gradient.
"""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.inverse_dynamics_mujoco import InverseDynamicsResult
from solver.kinematics import TangentMap
from solver.layout import StateLayout, site_ids
from solver.spatial import cross, mtv, mv, qmat, qmul


class KinematicTree:
    """Index bookkeeping of a tree of free, ball and welded bodies, and its vectorized kinematic passes.

    The engines built on it (`SiteKinematics`, `solver.inverse_dynamics.InverseDynamics`) have the
    interface of `solver.path_context` (forward, vjp, site velocities, `positions`).

    Args:
        model: MjModel (loaded once by the caller; not modified).
        sites: names of sites whose positions and velocities the passes track.
        prune: keep only the sites' bodies and their ancestors (a site moves with those alone; the
            gradients of the other joints are zero).
    Raises:
        InputError: a body with several joints, a hinge or slide joint, a free joint with a nonzero
            pos (named), an unknown site or a site on a static body.
    """

    #: the engine interface of `solver.path_context`: site velocities are computed; no narrower map
    has_site_velocities = True
    motion_map = None

    def __init__(self, model, sites=(), prune: bool = False):
        import mujoco

        self.model = model
        self.nq, self.nv = int(model.nq), int(model.nv)
        self._check_joints(model)
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)

        parent = model.body_parentid
        moving = _moving(model, sites, prune)
        bodies = np.flatnonzero(moving)
        index = {int(b): i for i, b in enumerate(bodies)}
        B = len(bodies)
        self.bodies = bodies
        par = np.array([index.get(int(parent[b]), -1) for b in bodies], int)
        kind, quat_q, ang_v, lin_q, lin_v, jpos = _joint_slots(model, bodies)
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
        self._anc, self._parent_mat, self._levels = _tree_matrices(par, self._child)
        self._desc = np.ascontiguousarray(self._anc.T)
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

    @staticmethod
    def _joint_problems(model) -> list[str]:
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
        return problems

    @classmethod
    def _check_joints(cls, model):
        problems = cls._joint_problems(model)
        if problems:
            raise InputError("the analytic site kinematics does not model: " + "; ".join(problems))

    # -----------------------------------------------------------------------------------------------
    def _pose(self, qp: np.ndarray) -> dict:
        """World rotations R (3, 3, B, n), origins x and joint anchors A (3, B, n) of the bodies at the
        samples qp (nq, n) (quaternions normalized here, as MuJoCo does), with what the reverse needs."""
        n = qp.shape[1]
        B = len(self.bodies)
        rot, free = self._rot, self._free
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
        return dict(R=R, x=x, A=A, Rpd=Rpd, Rj=Rj)

    def _velocity(self, R: np.ndarray, A: np.ndarray, qv: np.ndarray) -> dict:
        """Joint axes' world angular velocities s, body angular velocities om and origin-point
        velocities nu (3, B, n), and k = A x s, at qvel qv (nv, n)."""
        n = qv.shape[1]
        vl = np.zeros((3, len(self.bodies), n))
        vl[:, self._rot] = qv[self._ang_v.T]
        s = mv(R, vl)
        om = self._anc @ s
        k = cross(A, s)
        lin = np.zeros(vl.shape)
        lin[:, self._free] = qv[self._lin_v.T]
        nu = self._anc @ (k + lin)
        return dict(s=s, om=om, k=k, nu=nu)

    def _site_points(self, R, x) -> tuple[np.ndarray, np.ndarray]:
        """Site offsets ry = R_b r and positions ys = x_b + ry (3, K, n) of the sites' bodies b."""
        sb = self._site_body
        ry = mv(R[:, :, sb], self._site_pos)
        return ry, x[:, sb] + ry

    def _sites(self, R, x, nu, om) -> dict:
        """Site offsets ry, positions ys and velocities ysd (3, K, n)."""
        ry, ys = self._site_points(R, x)
        ysd = nu[:, self._site_body] + cross(om[:, self._site_body], ys)  # nu: velocity of the origin point
        return dict(ry=ry, ys=ys, ysd=ysd)

    def site_positions(self, qpos: np.ndarray) -> tuple[np.ndarray, dict]:
        """World positions of the tracked sites at n samples, by the forward pass of the pose alone
        (eq. 13; no velocities): the same as MuJoCo's `mj_kinematics` to rounding error.

        Args:
            qpos: (n, nq) (quaternions need not be unit: normalized here, as MuJoCo does).
        Returns:
            (n, k, 3) positions [m], and the saved pose that `site_positions_vjp` reads.
        """
        pose = self._pose(np.asarray(qpos, float).T)
        pose["ry"], ys = self._site_points(pose["R"], pose["x"])
        return np.ascontiguousarray(ys.transpose(2, 1, 0)), pose

    def positions(self, qpos: np.ndarray) -> np.ndarray:
        """(n, k, 3) world positions [m] of the tracked sites at qpos (n, nq) (`site_positions` without
        the saved pose)."""
        return self.site_positions(qpos)[0]

    def site_positions_vjp(self, pose: dict, g_sites: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Gradient of sum g_sites . site positions with respect to the pose (MuJoCo's tangent
        convention, as `SiteKinematics.vjp`), at the samples `rows` of a `site_positions` call.

        Args:
            pose: the saved pose of `site_positions`. g_sites: (r, k, 3), d phi / d site position.
            rows: (r,) sample indices into that call (default: all of them).
        Returns:
            (r, nv) gradient (zero for joints that do not move a site).
        """
        sv = pose if rows is None else {k: None if v is None else v[..., rows] for k, v in pose.items()}
        xbar, _, _, gth = self._site_adjoints(sv, None, g_sites, None)
        Gq = np.zeros((self.nv, g_sites.shape[0]))
        self._reverse_pose(sv, xbar, gth, Gq)
        return Gq.T

    def _site_adjoints(self, sv, om, g_sites, g_site_vel):
        """The sites' adjoints as body adjoints: (xbar, nubar, wbar, gth) parts, each (3, B, n) or 0.
        ysd = nu_b + om_b x ys: nu_b += g, om_b += ys x g, ys += g x om_b; ys = x_b + R_b r."""
        xbar = nubar = wbar = gth = 0.0
        if not len(self._site_body):
            return xbar, nubar, wbar, gth
        Sm = self._site_mat
        if g_site_vel is not None:
            gsv = np.swapaxes(np.moveaxis(g_site_vel, -1, 0), 1, 2)  # (n, K, 3) -> (3, K, n)
            nubar = Sm @ gsv
            wbar = Sm @ cross(sv["ys"], gsv)
            gys = cross(gsv, om[:, self._site_body])
            g_sites = gys.transpose(2, 1, 0) if g_sites is None else g_sites + gys.transpose(2, 1, 0)
        if g_sites is not None:
            ybar = np.swapaxes(np.moveaxis(g_sites, -1, 0), 1, 2)
            xbar = Sm @ ybar
            gth = Sm @ cross(sv["ry"], ybar)
        return xbar, nubar, wbar, gth

    def _reverse(self, sv, nubar, kbar, Abar, sbar, wbar, xbar, gth, Gq, Gv):
        """Reverse of `_velocity` and `_pose`: adds to Gq, Gv (nv, n) the gradients with respect to the
        pose (MuJoCo's tangent convention) and qvel, from the adjoints of nu (before the ancestor sum),
        k, A, s, om (before the ancestor sum), x, and the world rotation adjoints gth (3, B, n)."""
        R, A, s = sv["R"], sv["A"], sv["s"]
        free, rs, desc = self._free, self._rs, self._desc
        # nu = anc(k + lin_vel), k = A x s
        nubar = desc @ nubar
        Gv[self._lin_v.T] += nubar[:, free]
        kbar = kbar + nubar
        Abar = Abar + cross(s, kbar)
        sbar = sbar + cross(kbar, A)
        # omega = anc(s), s = R v_local
        sbar += desc @ wbar
        Gv[self._ang_v.T] += mtv(R[:, :, rs], sbar[:, rs])
        gth = gth + cross(s, sbar)
        # A = x + R jpos
        xbar = xbar + Abar
        if sv["Rj"] is not None:
            gth += cross(sv["Rj"], Abar)
        self._reverse_pose(sv, xbar, gth, Gq)

    def _reverse_pose(self, sv, xbar, gth, Gq):
        """Reverse of `_pose` from the adjoints of the body origins x and the world rotation adjoints
        gth (3, B, n) (gth is added to in place): writes the pose gradient into Gq (nv, n)."""
        R, free, rs, desc = sv["R"], self._free, self._rs, self._desc
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

    def _sites_vjp(self, sv: dict, n: int, g_sites, g_site_vel) -> tuple[np.ndarray, np.ndarray]:
        """(g_pose (n, nv), g_qvel (n, nv)): the reverse pass of the site positions and velocities alone
        (a `forward` with velocities saved `sv`; g_sites, g_site_vel (n, k, 3) or None)."""
        Gq, Gv = np.zeros((self.nv, n)), np.zeros((self.nv, n))
        xbar, nubar, wbar, gth = self._site_adjoints(sv, sv["om"], g_sites, g_site_vel)
        z = np.zeros((3, len(self.bodies), n))
        zs = [z if isinstance(a, float) else a for a in (nubar, wbar, xbar, gth)]
        self._reverse(sv, zs[0], z, z, z.copy(), zs[1], zs[2], zs[3], Gq, Gv)
        return Gq.T, Gv.T


class SiteKinematics(KinematicTree):
    """The sites' positions and velocities along a path and their reverse pass: the engine the kinematic
    terms share when no dynamics term needs the forces (`InverseDynamics`' interface, tau all zero;
    positions alone when `forward` gets no qvel).

    Args:
        model: MjModel (loaded once by the caller; not modified). sites: site names to track.
    Raises:
        InputError: as `KinematicTree`, or a mismatch with MuJoCo's site positions and velocities
            (`mj_kinematics`, `mj_objectVelocity`) at a random state.
    """

    #: the path derivatives `forward` reads (qpos and qvel; qacc is ignored), and those it cannot do
    #: without (without qvel: the positions alone, eq. 13)
    needs = (0, 1)
    required = (0,)

    #: no generalized forces (`InverseDynamics.forces`)
    forces = False

    def __init__(self, model, sites=()):
        super().__init__(model, sites, prune=True)  # the figure's four contact sites: 9 of its 20 bodies
        #: the tangent map of the joints this engine reads (`engine_forward` computes qvel with it)
        self.motion_map = TangentMap.from_layout(StateLayout.from_model(model)).subset(
            np.concatenate([self._ang_v.ravel(), self._lin_v.ravel()]))
        self._self_check(model)

    def _self_check(self, model):
        import mujoco

        rng = np.random.default_rng(12345)
        d = mujoco.MjData(model)
        qpos = np.array(model.qpos0, float)
        for i in range(len(self._quat_q)):
            q = rng.normal(size=4)
            qpos[self._quat_q[i]] = q / np.linalg.norm(q)
        qvel = rng.normal(size=self.nv)
        d.qpos[:], d.qvel[:] = qpos, qvel
        mujoco.mj_forward(model, d)
        res = self.forward(qpos[None], qvel[None])
        self._cache = None
        vel = np.zeros(6)
        err = 0.0
        for j, sid in enumerate(self.site_ids):
            mujoco.mj_objectVelocity(model, d, mujoco.mjtObj.mjOBJ_SITE, int(sid), vel, 0)
            err = max(err, np.abs(res.sites[0, j] - d.site_xpos[sid]).max(),
                      np.abs(res.saved["site_vel"][0, j] - vel[3:]).max())
        if not err <= 1e-8 * (1.0 + np.abs(qvel).max()):
            raise InputError(f"the analytic site kinematics differs from MuJoCo's by {err:.3g} on this model")

    def forward(self, qpos: np.ndarray, qvel: np.ndarray | None, qacc: np.ndarray | None = None) -> InverseDynamicsResult:
        """Site positions and velocities at n samples (the last result is cached, compared by value).

        Args:
            qpos: (n, nq) (quaternions need not be unit). qvel: (n, nv) [m/s, rad/s], or None: the
                positions alone (the forward pass of the pose, eq. 13; no `site_velocities`). qacc: ignored.
        Returns:
            InverseDynamicsResult with sites (n, k, 3) [m], tau zeros (n, nv), qacc an empty (n, 0);
            qvel an empty (n, 0) without velocities.
        """
        c = self._cache
        empty = np.zeros((qpos.shape[0], 0))
        key_v = empty if qvel is None else qvel
        if c is not None and c.matches(qpos, key_v, empty):
            return c
        if qvel is None:
            ys, pose = self.site_positions(qpos)
            res = InverseDynamicsResult(np.zeros((qpos.shape[0], self.nv)), ys, qpos.copy(), empty, empty, pose)
            self._cache = res
            return res
        pose = self._pose(qpos.T)
        vel = self._velocity(pose["R"], pose["A"], qvel.T)
        st = self._sites(pose["R"], pose["x"], vel["nu"], vel["om"])
        saved = {**pose, **vel, **st, "site_vel": np.ascontiguousarray(st["ysd"].transpose(2, 1, 0))}
        res = InverseDynamicsResult(np.zeros((qpos.shape[0], self.nv)), np.ascontiguousarray(st["ys"].transpose(2, 1, 0)),
                                    qpos.copy(), qvel.copy(), empty, saved)
        self._cache = res
        return res

    @staticmethod
    def site_velocities(res: InverseDynamicsResult) -> np.ndarray:
        """(n, k, 3) world velocities [m/s] of the sites at the samples of `forward`'s result."""
        return res.saved["site_vel"]

    def vjp(self, res: InverseDynamicsResult, g_tau=None, g_sites: np.ndarray | None = None,
            g_site_vel: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, None]:
        """Gradient of phi = sum g_sites . sites + sum g_site_vel . site velocities (g_tau is ignored:
        the forces are not computed) with respect to the pose (MuJoCo's tangent convention, as
        `InverseDynamics.vjp`) and qvel.

        Args:
            res: `forward`'s result. g_sites, g_site_vel: (n, k, 3) or None.
        Returns:
            g_pose (n, nv), g_qvel (n, nv) (None for a `forward` without qvel), None (no qacc dependence).
        """
        sv = res.saved
        n = res.qpos.shape[0]
        if "s" not in sv:  # positions only: the pose's reverse pass at the rows with a gradient
            Gq = np.zeros((n, self.nv))
            if g_sites is not None:
                rows = np.flatnonzero(np.any(g_sites != 0, axis=(1, 2)))
                if rows.size:
                    Gq[rows] = self.site_positions_vjp(sv, g_sites[rows], rows)
            return Gq, None, None
        return (*self._sites_vjp(sv, n, g_sites, g_site_vel), None)


def _moving(model, sites, prune: bool) -> np.ndarray:
    """(nbody,) bool: bodies that move (a joint on them or an ancestor); with `prune`, only the sites'
    bodies and their ancestors (the figure's feet: the legs and the root)."""
    nb = model.nbody
    parent = model.body_parentid
    has_joint = model.body_jntnum > 0
    moving = np.zeros(nb, bool)
    for b in range(1, nb):
        moving[b] = has_joint[b] or moving[parent[b]]
    if prune:
        needed = np.zeros(nb, bool)
        for b in model.site_bodyid[site_ids(model, sites)]:
            b = int(b)
            while b > 0:
                needed[b] = True
                b = int(parent[b])
        moving &= needed
    return moving


def _joint_slots(model, bodies: np.ndarray):
    """Per moving body: kind (B,) (0 weld, 1 ball, 2 free), its quaternion's qpos indices (B, 4), angular
    dof indices (B, 3), the free joint's position qpos and dof indices (B, 3) each, joint anchor (B, 3)."""
    import mujoco

    B = len(bodies)
    kind = np.zeros(B, int)
    quat_q, ang_v = np.zeros((B, 4), int), np.zeros((B, 3), int)
    lin_q, lin_v = np.zeros((B, 3), int), np.zeros((B, 3), int)
    jpos = np.zeros((B, 3))
    for i, b in enumerate(bodies):
        if model.body_jntnum[b] == 0:
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
    return kind, quat_q, ang_v, lin_q, lin_v, jpos


def _tree_matrices(par: np.ndarray, child: np.ndarray):
    """anc (B, B): anc[b, a] = 1 if a is b or an ancestor of b; the parent matrix restricted to the
    bodies with a moving parent (B, c); the bodies by depth, from depth 2 down (a list of index arrays)."""
    B = len(par)
    anc = np.zeros((B, B))
    for i in range(B):
        a = i
        while a >= 0:
            anc[i, a] = 1.0
            a = par[a]
    P = np.zeros((B, B))  # P[p, i] = 1 if p is the parent of i
    for i in child:
        P[par[i], i] = 1.0
    depth = anc.sum(1).astype(int)
    levels = [np.flatnonzero(depth == k) for k in range(2, int(depth.max()) + 1)] if B else []
    return anc, np.ascontiguousarray(P[:, child]), levels
