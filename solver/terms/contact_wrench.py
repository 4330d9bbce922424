"""Friction-cone residual (docs/contacts.md "The contact terms"): during contact the feet must be able to supply the root wrench.

Inverse dynamics of the path (the machinery of `solver.terms.dynamics.RootResidual`) gives the free
root's generalized force: the world force F [N] and the torque T_loc [N m] about the root body's origin
x_r in its frame, i.e. the external wrench besides gravity that the motion needs. In flight it must be
zero (the `root` term); in contact the feet supply it, but only as contact forces can: pushing, not
pulling, inside the friction cone, with a centre of pressure on the support. `FrictionCone` (name
"cone", N^2) penalizes the part outside what the sites in contact can supply:

    A(t) = 1 - prod over sites (1 - a_k),  a_k = 1 - prod over the site's contacts (1 - w_c)
           (w_c: the contact windows of `solver.terms.contact.contact_window`, ramp `ramp`, default 0)
    n    = unit mean of the active sites' support normals (a_k-weighted; the surfaces under them)
    c    = sum a_k p_k / sum a_k   (the contact centroid, p_k the site positions)
    r    = sqrt(max_k |P_t (p_k - c)|^2 + r0^2)  (support radius: farthest active site from c along the
           surface, P_t = I - n n^T; r0 = `min_radius`, default 2 cm, the foot's own width)
    M    = R T_loc + (x_r - c) x F   (the wrench's moment about c, world frame; R the root rotation)
    f_n = n.F,  F_t = F - f_n n,   M_n = n.M,  M_t = M - M_n n

    e1 = max(-f_n, 0)                         pulling on the ground [N]
    e2 = max(|F_t| - mu f_n, 0)               tangential force outside the cone mu = 0.8 [N]
    e3 = max(|M_t| - r f_n, 0) / l            centre of pressure outside the disc of radius r about c
    e4 = max(|M_n| - mu r f_n, 0) / l         torsion beyond what friction at radius r can give

    f  = A (e1^2 + e2^2 + e3^2 + e4^2)  [N^2],   l = `torque_arm` (default the figure's radius of
                                                    gyration, as in `RootResidual`)

Which components and why: the three force components (e1, e2: the Coulomb cone of the summed contact
force; point forces at several sites on surfaces with one normal sum to a force in the same cone) and
the three moment components about the contact centroid. A normal force f_n applied at a point d of
the surface (relative to c) has a tangential moment of size f_n |d|, so e3 > 0 exactly when the centre
of pressure leaves the disc of radius r (the disc circumscribes the support polygon of the active
sites, grown by r0: a conservative test that never penalizes a supportable wrench, at the price of
allowing a centre of pressure beside the heel-toe line - which the real foot's width does anyway).
e4 bounds the twist about the normal by friction at the support radius. Moments are turned into
forces by the arm l so that all four parts are in N. e1 and e2 both grow when f_n < 0 (e2 then counts
mu |f_n| too); both are zero inside the cone. Each e is a hinge, so f is C1 in the wrench.

Gradients: F and T_loc through the inverse-dynamics engine's reverse pass (deferred, shared with the
other dynamics terms like `RootResidual`); the site positions p_k (c and r) through the engine's site
adjoints; R and x_r (the moment's lever) directly through the root's pose tangent (B^T). The surface
choice and n are piecewise constant (no gradient).

`cone_metrics` reports the residual outside the cone, sqrt(f) per sample [N]: RMS over the samples in
contact (A > 0) and the peak.
"""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.id_jacobian import tau_jacobian
from solver.kinematics import TangentMap
from solver.layout import CONTACT_SITES, StateLayout
from solver.path_context import EngineGradient, PathContext
from solver.surfaces import StaticSurfaces
from solver.terms.base import Residual, Term, TermEval
from solver.terms.contact_schedule import FULL, SupportSurfaces, _sample_times, check_contacts, contact_window
from solver.terms.dynamics import figure_radius_of_gyration, make_engine


def _qrot(q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices of (n, 4) quaternions (normalized here)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _safe_norm(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """|x| over the last axis and x/|x| (0 where x = 0)."""
    r = np.linalg.norm(x, axis=-1)
    u = np.where(r[..., None] > 0, x / np.where(r > 0, r, 1.0)[..., None], 0.0)
    return r, u


class FrictionCone(Term):
    """f = A(t) (e1^2 + e2^2 + e3^2 + e4^2) [N^2]: the root wrench outside what the feet in contact can
    supply (see the module docstring).

    Args:
        model: MjModel of the scene (figure with a free root, static planes/boxes).
        contacts: objects with site, start, end, surface (`solver.terms.contact`).
        mu: friction coefficient (default 0.8).
        ramp: [s] contact-window ramp (default 0: the contact interval as given).
        min_radius: r0 [m] > 0.
        torque_arm: l [m] > 0; default the radius of gyration of the root's subtree.
        engine: an engine from `solver.terms.dynamics.make_engine` tracking the contact sites (share it
            with torque/root); default a new one. backend: when no engine is given.
        footprint_margin: see `SupportSurfaces`. t_span: see `solver.terms.contact.Planted`.
    Raises:
        InputError: bad contact, no free joint or surfaces, bad parameters, an engine without the sites.
    """

    name = "cone"
    units = "N^2"
    needs = (0, 1, 2)
    fixed_points = True  # an inverse-dynamics term with contact windows at the quadrature points

    def __init__(self, model, contacts, mu: float = 0.8, ramp: float = 0.0, min_radius: float = 0.02,
                 torque_arm: float | None = None, engine=None, backend: str = "analytic",
                 footprint_margin: float = 0.03, t_span=None):
        import mujoco

        surfaces = StaticSurfaces.from_model(model)
        if surfaces.count == 0:
            raise InputError("the scene has no static floor plane or box for the friction-cone term")
        self.support = SupportSurfaces(surfaces, footprint_margin)
        self.contacts = check_contacts(contacts, CONTACT_SITES, surfaces.names)
        for label, value, low in (("mu", mu, 0.0), ("ramp", ramp, 0.0)):
            if not np.isfinite(float(value)) or float(value) < low:
                raise InputError(f"{label} is {value}; it must be finite and >= {low}")
        if not np.isfinite(float(min_radius)) or float(min_radius) <= 0:
            raise InputError(f"min_radius is {min_radius}; it must be a length > 0 [m]")
        self.mu, self.ramp, self.min_radius, self.t_span = float(mu), float(ramp), float(min_radius), t_span
        free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        if not free:
            raise InputError("the model has no free joint (the figure's root) for the friction-cone term")
        root = free[0]
        adr, qadr = int(model.jnt_dofadr[root]), int(model.jnt_qposadr[root])
        self.root_dofs = np.arange(adr, adr + 6)
        self.root_pos = np.arange(qadr, qadr + 3)
        self.root_quat = np.arange(qadr + 3, qadr + 7)
        if torque_arm is None:
            torque_arm = figure_radius_of_gyration(model, int(model.jnt_bodyid[root]))
        if not np.isfinite(float(torque_arm)) or float(torque_arm) <= 0:
            raise InputError(f"torque_arm is {torque_arm}; it must be a length > 0 [m]")
        self.torque_arm = float(torque_arm)
        self.tmap = TangentMap.from_layout(StateLayout.from_model(model))
        self.engine = engine if engine is not None else make_engine(model, CONTACT_SITES, backend)
        idx = []
        for s in CONTACT_SITES:
            sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, s)
            where = np.flatnonzero(self.engine.site_ids == sid)
            if sid < 0 or not len(where):
                raise InputError(f"contact site {s!r} is not in the model or not tracked by the engine")
            idx.append(int(where[0]))
        self.site_index = np.array(idx, int)
        self._site_of = np.array([CONTACT_SITES.index(c.site) for c in self.contacts], int)
        self._surf = [self.support.index(c.surface) for c in self.contacts]

    # -----------------------------------------------------------------------------------------------
    def activity(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """a (n, K) per contact site and the contact index ruling each (n, K) (-1: none), at times t."""
        t = np.asarray(t, float)
        K = len(CONTACT_SITES)
        free = np.ones((len(t), K))
        rule = np.full((len(t), K), -1)
        best = np.zeros((len(t), K))
        for i, c in enumerate(self.contacts):
            w = contact_window(t, float(c.start), float(c.end), self.ramp)
            k = self._site_of[i]
            free[:, k] *= 1.0 - w
            better = w > best[:, k]
            rule[better, k] = i
            best[better, k] = w[better]
        return 1.0 - free, rule

    def _wrench(self, t, Y, res):
        """Forward quantities at the rows in contact (dict), or None if no row is."""
        a, rule = self.activity(t)
        A = 1.0 - np.prod(1.0 - a, axis=1)
        rows = np.flatnonzero(A > 0)
        if rows.size == 0:
            return None
        a, rule, A = a[rows], rule[rows], A[rows]
        p = res.sites[rows][:, self.site_index]  # (m, K, 3)
        nk = np.zeros(p.shape)
        for k in range(p.shape[1]):
            for i in np.unique(rule[:, k]):
                if i < 0:
                    continue
                sel = rule[:, k] == i
                _, nk[sel, k] = self.support.height(p[sel, k], self._surf[i])
        nsum = np.einsum("mk,mki->mi", a, nk)
        nrm = nsum / np.linalg.norm(nsum, axis=1, keepdims=True)
        asum = a.sum(1)
        c = np.einsum("mk,mki->mi", a, p) / asum[:, None]
        d = p - c[:, None]
        d_t = d - np.einsum("mki,mi->mk", d, nrm)[..., None] * nrm[:, None]
        dist2 = np.where(a > 0, (d_t * d_t).sum(-1), -1.0)
        kstar = np.argmax(dist2, axis=1)
        r = np.sqrt(np.maximum(dist2[np.arange(len(rows)), kstar], 0.0) + self.min_radius**2)
        tau = res.tau[rows]
        F = tau[:, self.root_dofs[:3]]
        T_loc = tau[:, self.root_dofs[3:]]
        R = _qrot(Y[rows][:, self.root_quat])
        T = np.einsum("mij,mj->mi", R, T_loc)
        lever = Y[rows][:, self.root_pos] - c
        M = T + np.cross(lever, F)
        fn = np.einsum("mi,mi->m", nrm, F)
        Ft = F - fn[:, None] * nrm
        Mn = np.einsum("mi,mi->m", nrm, M)
        Mt = M - Mn[:, None] * nrm
        ft, uft = _safe_norm(Ft)
        mt, umt = _safe_norm(Mt)
        l, mu = self.torque_arm, self.mu
        e = np.stack([
            np.maximum(-fn, 0.0),
            np.maximum(ft - mu * fn, 0.0),
            np.maximum(mt - r * fn, 0.0) / l,
            np.maximum(np.abs(Mn) - mu * r * fn, 0.0) / l,
        ], 1)
        return dict(rows=rows, a=a, A=A, p=p, nrm=nrm, asum=asum, c=c, d_t=d_t, kstar=kstar, r=r, F=F,
                    T_loc=T_loc, R=R, T=T, lever=lever, M=M, fn=fn, Mn=Mn, uft=uft, umt=umt, e=e)

    def components(self, t, Y, Y1, Y2) -> tuple[np.ndarray, np.ndarray]:
        """Per sample: A(t) (n,) and (e1, e2, e3, e4) (n, 4) [N] (0 off contact)."""
        _, res = PathContext(t, Y, Y1, Y2).forward(self.engine, self.tmap)
        A = np.zeros(len(Y))
        e = np.zeros((len(Y), 4))
        q = self._wrench(t, Y, res)
        if q is not None:
            A[q["rows"]] = q["A"]
            e[q["rows"]] = q["e"]
        return A, e

    def residual_norm(self, t, Y, Y1, Y2) -> tuple[np.ndarray, np.ndarray]:
        """Per sample: A(t) and the residual sqrt(e1^2 + ... + e4^2) outside the cone [N] (0 off contact)."""
        A, e = self.components(t, Y, Y1, Y2)
        return A, np.linalg.norm(e, axis=1)

    def evaluate_in(self, ctx, grad=True) -> TermEval:
        """`Term.evaluate_in`: the wrench and site gradients left to the engine's reverse pass (shared
        with the other dynamics terms); the root-pose lever part is returned in dY directly."""
        mo, res = ctx.forward(self.engine, self.tmap)
        f = np.zeros(len(ctx.Y))
        q = self._wrench(ctx.t, ctx.Y, res)
        if q is not None:
            f[q["rows"]] = q["A"] * (q["e"] ** 2).sum(1)
        if not grad:
            return TermEval(f)
        ge = None if q is None else 2.0 * q["A"][:, None] * q["e"]  # d f / d e (hinges: e = 0 gives 0)
        dY, deferred = self._pull(ctx.Y, q, ge, res, mo)
        return TermEval(f, dY=dY, deferred=deferred)

    def residual(self, ctx) -> Residual:
        """r = sqrt(A) (e1, e2, e3, e4) (n, 4) [N] (f = |r|^2); Jacobian-vector products through the
        engine's reverse pass and the root pose (each e a hinge: its derivative is 0 where it is 0)."""
        mo, res = ctx.forward(self.engine, self.tmap)
        r = np.zeros((len(ctx.Y), 4))
        q = self._wrench(ctx.t, ctx.Y, res)
        if q is not None:
            sA = np.sqrt(q["A"])[:, None]
            r[q["rows"]] = sA * q["e"]

        def pull(g):
            ge = None if q is None else sA * g[q["rows"]] * (q["e"] > 0)
            dY, deferred = self._pull(ctx.Y, q, ge, res, mo)
            pulled = deferred.pullback()
            return (dY + pulled[0], *pulled[1:])

        tj = tau_jacobian(ctx, self.engine, self.tmap)
        if tj is None or q is None:
            return Residual(r, pull=pull)
        cols = []  # the adjoints of each column (`_pull` with a unit weight on it)
        for c in range(r.shape[1]):
            unit = np.zeros((len(q["rows"]), r.shape[1]))
            unit[:, c] = sA[:, 0] * (q["e"][:, c] > 0)
            cols.append(self._pull(ctx.Y, q, unit, res, mo))
        g_tau = np.stack([eg.g_tau for _, eg in cols], axis=1)
        g_sites = np.stack([eg.g_sites for _, eg in cols], axis=1)
        direct = np.stack([dY for dY, _ in cols], axis=1)
        return Residual(r, blocks=tj.blocks(g_tau, g_sites, direct), pull=pull)

    def _pull(self, Y, q, ge, res, mo):
        """(dY (n, nq), EngineGradient) of sum ge . e over the contact rows of `_wrench`'s q: the
        root-pose lever part directly, the wrench and site parts left to the engine's reverse pass."""
        g_tau = np.zeros(res.tau.shape)
        g_sites = np.zeros(res.sites.shape)
        dY = np.zeros(Y.shape)
        if q is not None:
            rows, e, nrm, l, mu = q["rows"], q["e"], q["nrm"], self.torque_arm, self.mu
            fn, r = q["fn"], q["r"]
            ge = ge * (e > 0)  # hinges: no derivative where e = 0
            sgnMn = np.sign(q["Mn"])[:, None]
            # d f / d F, d M, d r
            gF = (-ge[:, 0, None] * nrm + ge[:, 1, None] * (q["uft"] - mu * nrm)
                  - (ge[:, 2] * r / l)[:, None] * nrm - (ge[:, 3] * mu * r / l)[:, None] * nrm)
            gM = (ge[:, 2, None] / l) * q["umt"] + (ge[:, 3, None] / l) * sgnMn * nrm
            gr = -(ge[:, 2] * fn + ge[:, 3] * mu * fn) / l
            # M = R T_loc + (x_r - c) x F
            gF += np.cross(gM, q["lever"])
            g_xr = np.cross(q["F"], gM)
            g_c = -g_xr
            g_Tloc = np.einsum("mji,mj->mi", q["R"], gM)
            g_theta = np.einsum("mji,mj->mi", q["R"], np.cross(q["T"], gM))
            # r = sqrt(|d_t*|^2 + r0^2), d_t* = P_t (p_k* - c)
            m = len(rows)
            g_p = np.zeros(q["p"].shape)
            gd = (gr / r)[:, None] * q["d_t"][np.arange(m), q["kstar"]]  # d f / d (p_k* - c) (P_t symmetric, idempotent)
            g_p[np.arange(m), q["kstar"]] += gd
            g_c -= gd
            g_p += (q["a"] / q["asum"][:, None])[..., None] * g_c[:, None]
            g_tau[rows[:, None], self.root_dofs[None, :3]] = gF
            g_tau[rows[:, None], self.root_dofs[None, 3:]] = g_Tloc
            g_sites[rows[:, None], self.site_index[None, :]] = g_p
            g_pose = np.zeros((m, self.tmap.nv))
            g_pose[:, self.root_dofs[:3]] = g_xr
            g_pose[:, self.root_dofs[3:]] = g_theta
            dY[rows] = self.tmap.pullback(Y[rows], g_pose)
        return dY, EngineGradient(self.engine, res, mo, g_tau, g_sites)

    def violation(self, Y: np.ndarray, t: np.ndarray | None = None) -> float | None:
        """Peak residual outside the cone [N] where the contact window is full; Y', Y'' by finite
        differences of the samples (times: `t`, else even on `t_span`; None if unknown)."""
        t = _sample_times(Y, t, self.t_span)
        if t is None or len(Y) < 3:
            return None
        Y1 = np.gradient(Y, t, axis=0)
        Y2 = np.gradient(Y1, t, axis=0)
        A, res = self.residual_norm(t, Y, Y1, Y2)
        full = A >= FULL
        return float(res[full].max()) if full.any() else None


def cone_metrics(term: FrictionCone, t, Y, Y1, Y2) -> dict[str, float]:
    """The friction-cone residual of a path as a report.

    Args:
        term: a FrictionCone. t: (n,) sample times [s]. Y, Y1, Y2: (n, nq) the path and its derivatives.
    Returns:
        {"cone_rms": RMS of sqrt(A) * residual over the samples in contact [N] (= sqrt(mean f)),
         "cone_peak": its largest value [N], "cone_samples": number of samples in contact}.
    """
    A, res = term.residual_norm(t, Y, Y1, Y2)
    on = A > 0
    if not on.any():
        return {"cone_rms": 0.0, "cone_peak": 0.0, "cone_samples": 0}
    r = np.sqrt(A[on]) * res[on]
    return {"cone_rms": float(np.sqrt(np.mean(r * r))), "cone_peak": float(r.max()), "cone_samples": int(on.sum())}
