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
from solver.kinematic_tree import KinematicTree
from solver.spatial import cross, mtv, mv, qmat

__all__ = ["InverseDynamics", "InverseDynamicsResult", "MujocoInverseDynamics", "constraint_free_copy"]


class InverseDynamics(KinematicTree):
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

    #: the path derivatives `forward` reads (qpos, qvel, qacc), all required (`solver.path_context`)
    needs = (0, 1, 2)
    required = (0, 1, 2)

    #: the engine computes generalized forces (`solver.path_state.PathState` passes it qacc)
    forces = True

    def __init__(self, model, sites=()):
        import mujoco

        self._check_supported(model)
        super().__init__(model, sites)
        bodies = self.bodies
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
        self._self_check(model)

    # -----------------------------------------------------------------------------------------------
    @classmethod
    def _check_supported(cls, model):
        import mujoco

        problems = cls._joint_problems(model)
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

        # --- pose and velocities (`KinematicTree`), then accelerations (spatial, about the world origin)
        pose = self._pose(qp)
        R, x, A = pose["R"], pose["x"], pose["A"]
        cx = mv(R, self._ipos)
        com = x + cx
        vel = self._velocity(R, A, qv)
        s, om, k, nu = vel["s"], vel["om"], vel["k"], vel["nu"]
        al_loc = np.zeros((3, B, n))
        al_loc[:, rot] = qa[self._ang_v.T]
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

        st = self._sites(R, x, nu, om)
        saved = dict(
            **pose, **vel, **st, cx=cx, com=com, as_=as_, al=al, vc=vc, f=f, wl=wl, h=h, nw=nw, Ff=Ff, Wt=Wt,
            site_vel=np.ascontiguousarray(st["ysd"].transpose(2, 1, 0)),
        )
        res = InverseDynamicsResult(
            np.ascontiguousarray(tau.T), np.ascontiguousarray(st["ys"].transpose(2, 1, 0)),
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
            g_tau: (n, nv) d phi / d tau, or None (zero). g_sites: (n, k, 3) d phi / d site position, or None.
            g_site_vel: (n, k, 3) d phi / d site velocity (`site_velocities`), or None.
        Returns:
            g_pose (n, nv), g_qvel (n, nv), g_qacc (n, nv) (None when g_tau is None: the forces' reverse
            pass is skipped, the sites' alone made). g_qacc = M(q) g_tau (M with armature).
        """
        sv = res.saved
        if g_tau is None:
            return (*self._sites_vjp(sv, res.qpos.shape[0], g_sites, g_site_vel), None)
        gT = g_tau.T
        Ga = self._armature[:, None] * gT
        Gv = self._damping[:, None] * gT
        Gq = np.zeros((self.nv, gT.shape[1]))
        gth, Abar, cbar, wbar, albar, nudbar, nubar = self._force_adjoints(sv, gT)
        sx, snu, sw, sth = self._site_adjoints(sv, sv["om"], g_sites, g_site_vel)
        xbar = cbar + sx
        nubar = nubar + snu
        wbar += sw
        gth += sth
        Abar, wbar, kbar, nubar, sbar, gth, Gl_a = self._acceleration_adjoints(
            sv, nudbar, albar, Abar, wbar, nubar, gth, Ga)
        # velocities and pose (`KinematicTree._reverse`)
        self._reverse(sv, nubar, kbar, Abar, sbar, wbar, xbar, gth, Gq, Gv)
        Ga[self._lin_v.T] += Gl_a
        return Gq.T, Gv.T, Ga.T

    def _force_adjoints(self, sv: dict, gT: np.ndarray) -> tuple:
        """Reverse pass of `forward`'s backward (force) sweep and of the bodies' momentum rates, for
        `vjp`: from d phi / d tau (nv, n) to the adjoints (3, B, n) of the joint rotations (gth), the
        joint axes' world motion (Abar), the bodies' COM positions (cbar), angular velocities (wbar),
        angular and linear accelerations (albar, nudbar) and linear velocities (nubar)."""
        R, A, com, om = sv["R"], sv["A"], sv["com"], sv["om"]
        rot, free, anc = self._rot, self._free, self._anc
        tbar = np.zeros((3, len(self.bodies), gT.shape[1]))
        tbar[:, rot] = gT[self._ang_v.T]
        What = mv(R, tbar)
        gth = cross(What, sv["Wt"])
        Ffbar = cross(A, What)
        Ffbar[:, free] += gT[self._lin_v.T]
        Abar = cross(What, sv["Ff"])
        nbar = anc @ What  # wrench adjoint of each body: sum over its ancestors' joints
        fbar = anc @ Ffbar
        cbar = cross(sv["f"], nbar)
        fbar += cross(nbar, com)
        gth += cross(sv["nw"], nbar)
        nlbar = mtv(R, nbar)
        Ic = self._Ic
        albar_l = mv(Ic, nlbar)
        hbar = cross(nlbar, sv["wl"])
        wlbar = cross(sv["h"], nlbar) + mv(Ic, hbar)
        wbar = mv(R, wlbar)
        gth += cross(wbar, om)
        albar = mv(R, albar_l)
        gth += cross(albar, sv["al"])
        acbar = self._mass * fbar
        nudbar = acbar
        albar += cross(com, acbar)
        cbar += cross(acbar, sv["al"])
        wbar += cross(sv["vc"], acbar)
        vcbar = cross(acbar, om)
        nubar = vcbar
        wbar += cross(com, vcbar)
        cbar += cross(vcbar, om)
        gth += cross(sv["cx"], cbar)
        return gth, Abar, cbar, wbar, albar, nudbar, nubar

    def _acceleration_adjoints(self, sv, nudbar, albar, Abar, wbar, nubar, gth, Ga) -> tuple:
        """Reverse pass of `forward`'s acceleration sweep, for `vjp`: adds the joint accelerations'
        part to Ga (nv, n) in place and returns the updated adjoints and the free joints' linear
        acceleration adjoint Gl_a."""
        R, A, om = sv["R"], sv["A"], sv["om"]
        k, nu, s, as_ = sv["k"], sv["nu"], sv["s"], sv["as_"]
        desc, rs = self._desc, self._rs
        # nudot = anc(z), z = A x as + om x k + nu x s + lin_acc
        zbar = desc @ nudbar
        Gl_a = zbar[:, self._free]
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
        return Abar, wbar, kbar, nubar, sbar, gth, Gl_a
