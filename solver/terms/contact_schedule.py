"""The contact schedule's geometry for the contact terms (`solver.terms.contact`): time windows of
contacts, swings and flights, the support surface under a site, and site positions and velocities with
the Jacobians their gradients need. The equations are in `solver.terms.contact`'s docstring."""
from __future__ import annotations

import mujoco
import numpy as np

from solver.contact_schedule import ContactSchedule
from solver.errors import InputError
from solver.kinematic_tree import KinematicTree
from solver.kinematics import TangentMap
from solver.layout import CONTACT_SITES, StateLayout, site_ids
from solver.surfaces import StaticSurfaces

FULL = 1.0 - 1e-9  # a window at least this is "fully weighted" (where `violation` looks)
#: [s] a keyframe this close to a contact's start or end is at it (keyframe files keep 6 decimals)
KEYFRAME_AT_END = 1e-6


# ---------------------------------------------------------------------------------------------------
# schedule helpers


def smoothstep(x: np.ndarray) -> np.ndarray:
    """3 x^2 - 2 x^3 on [0, 1], clipped outside."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def contact_window(t: np.ndarray, start: float, end: float, ramp: float) -> np.ndarray:
    """(n,) weight of a contact [start, end] at times t: 1 inside [start + r, end - r], 0 outside
    [start, end], smoothstep ramps between (r = min(ramp, (end - start)/2); r = 0: the closed box)."""
    t = np.asarray(t, float)
    r = min(float(ramp), 0.5 * (end - start))
    if r <= 0:
        return ((t >= start) & (t <= end)).astype(float)
    return smoothstep((t - start) / r) * smoothstep((end - t) / r)


def last_for_times(owner, attr: str, t, compute):
    """compute(t) (an array or a tuple of arrays, made read-only), remembered on `owner.attr` for the
    last t: a term's windows depend only on the times, and an objective evaluates at the same
    quadrature points every time."""
    t = np.asarray(t, float)
    key = (t.shape, t.tobytes())
    hit = getattr(owner, attr, None)
    if hit is not None and hit[0] == key:
        return hit[1]
    value = compute(t)
    for a in value if isinstance(value, tuple) else (value,):
        a.flags.writeable = False
    setattr(owner, attr, (key, value))
    return value


def gap_window(t: np.ndarray, a: float, b: float, core: float) -> np.ndarray:
    """(n,) weight over a gap (a, b): 0 at the ends, 1 on the central `core` fraction, smoothstep
    ramps over the outer (1 - core)/2 at each end (core = 1: the open box)."""
    t = np.asarray(t, float)
    L = b - a
    if L <= 0:
        return np.zeros(t.shape)
    r = 0.5 * (1.0 - float(core)) * L
    if r <= 0:
        return ((t > a) & (t < b)).astype(float)
    return smoothstep((t - a) / r) * smoothstep((b - t) / r)


def check_contacts(contacts, sites=CONTACT_SITES, surface_names=()) -> ContactSchedule:
    """The contacts as a `ContactSchedule` checked against the figure's sites and the scene's surface
    names (`ContactSchedule.of`; a schedule already checked so is returned as it is).

    Raises:
        InputError: naming the contact (its source and label), the field and the valid choices.
    """
    return ContactSchedule.of(contacts, sites, surface_names)


def flights(contacts) -> list[tuple[float, float]]:
    """Intervals between the first and the last contact of the schedule where no site is in contact
    (`ContactSchedule.flights`)."""
    return ContactSchedule.of(contacts).flights()


def swings(contacts, site: str) -> list[tuple[float, float]]:
    """Gaps between consecutive (merged) contacts of one site (`ContactSchedule.swings`)."""
    return ContactSchedule.of(contacts).swings(site)


# ---------------------------------------------------------------------------------------------------
# support surfaces


class SupportSurfaces:
    """Heights of points above the supporting face of each static surface (see module docstring).

    Args:
        surfaces: StaticSurfaces of the scene.
        footprint_margin: [m] a box supports a point whose projection is within this of its top face.
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

    def __init__(self, surfaces: StaticSurfaces, footprint_margin: float = 0.03, rounded_edges: bool = False):
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
            half2.append(h[others] + footprint_margin)
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


def _gt(q: np.ndarray, g: np.ndarray) -> np.ndarray:
    """G(q)^T g = q * (0, g) (Hamilton product), last-axis: (..., 4) q, (..., 3) g -> (..., 4)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    a, b, c = np.moveaxis(g, -1, 0)
    return np.stack(
        [-x * a - y * b - z * c, w * a - z * b + y * c, z * a + w * b - x * c, -y * a + x * b + w * c], -1
    )


class SiteMotion:
    """Positions, velocities and their gradients of sites along a path, by MuJoCo kinematics.

    Args:
        model: MjModel. sites: site names.
    """

    def __init__(self, model, sites=CONTACT_SITES):
        self.model = model
        self.data = mujoco.MjData(model)
        self.sites = site_ids(model, sites)
        self.names = tuple(sites)
        self.bodies = np.array(model.site_bodyid[self.sites], int)
        self.tmap = TangentMap.from_layout(StateLayout.from_model(model))
        try:  # the vectorized kinematics of the sites' bodies, for `dense_positions`
            self._tree = KinematicTree(model, sites, prune=True)
        except InputError:  # joints it does not model: MuJoCo's loop
            self._tree = None

    def dense_positions(self, Y: np.ndarray) -> np.ndarray:
        """(n, k, 3) site positions [m] at many samples (the terms' `violation`, 4000 per second of the
        path): from one vectorized pass (`KinematicTree.site_positions`, MuJoCo's to rounding error;
        35_17's planted and clearance checks 76 -> ~10 ms), or `positions` for joints the tree does
        not model. `positions` stays MuJoCo's: the keyframe checks set bands from it."""
        if self._tree is None:
            return self.positions(Y)
        return self._tree.site_positions(Y)[0]

    def positions(self, Y: np.ndarray) -> np.ndarray:
        """(n, k, 3) site positions [m] (MuJoCo's `mj_kinematics`, sample by sample)."""
        m, d = self.model, self.data
        out = np.empty((len(Y), len(self.sites), 3))
        for i, y in enumerate(Y):
            d.qpos[:] = y
            mujoco.mj_kinematics(m, d)
            out[i] = d.site_xpos[self.sites]
        return out

    def jacobians(self, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (n, k, 3) and translational site Jacobians (n, k, 3, nv) (tangent convention)."""
        m, d = self.model, self.data
        n, k = len(Y), len(self.sites)
        p = np.empty((n, k, 3))
        J = np.zeros((n, k, 3, m.nv))
        for i, y in enumerate(Y):
            d.qpos[:] = y
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            for j, s in enumerate(self.sites):
                mujoco.mj_jacSite(m, d, J[i, j], None, int(s))
            p[i] = d.site_xpos[self.sites]
        return p, J

    def motion(self, Y: np.ndarray, Y1: np.ndarray, mask: np.ndarray | None = None, grad: bool = True):
        """Positions, velocities and the Jacobians needed for gradients at n samples.

        Args:
            Y, Y1: (n, nq) the path and its time derivative. mask: optional (n, k) bool, the sites
                whose velocity (and Jacobians) are needed at each sample (others: v, J, Jdot left 0).
            grad: False: velocities only (`mj_objectVelocity`), J and Jdot None.
        Returns:
            p (n, k, 3) [m], v (n, k, 3) [m/s], J (n, k, 3, nv), Jdot (n, k, 3, nv) [1/s].
        """
        m, d = self.model, self.data
        n, k = len(Y), len(self.sites)
        if mask is None:
            mask = np.ones((n, k), bool)
        qvel = self.tmap.velocity(Y, Y1)
        p = np.empty((n, k, 3))
        v = np.zeros((n, k, 3))
        J = np.zeros((n, k, 3, m.nv)) if grad else None
        Jd = np.zeros((n, k, 3, m.nv)) if grad else None
        vel6 = np.zeros(6)
        site = int(mujoco.mjtObj.mjOBJ_SITE)
        sites, bodies = [int(s) for s in self.sites], [int(b) for b in self.bodies]
        kinematics, com_pos, com_vel = mujoco.mj_kinematics, mujoco.mj_comPos, mujoco.mj_comVel
        jac_site, jac_dot, object_velocity = mujoco.mj_jacSite, mujoco.mj_jacDot, mujoco.mj_objectVelocity
        xpos = d.site_xpos
        for i, need in enumerate(mask.tolist()):
            d.qpos[:] = Y[i]
            d.qvel[:] = qvel[i]
            kinematics(m, d)
            com_pos(m, d)
            com_vel(m, d)
            for j, on in enumerate(need):
                if not on:
                    continue
                s = sites[j]
                if grad:
                    jac_site(m, d, J[i, j], None, s)
                    jac_dot(m, d, Jd[i, j], None, xpos[s], bodies[j])
                else:
                    object_velocity(m, d, site, s, vel6, 0)
                    v[i, j] = vel6[3:]
            p[i] = xpos[sites]
        if grad:
            v = np.einsum("nkij,nj->nki", J, qvel)
        return p, v, J, Jd

    def pullback(self, Y, Y1, J, Jd, g_p, g_v):
        """Gradients of a function of site positions and velocities, pulled back to Y and Y'.

        Args:
            Y, Y1: (n, nq). J, Jd: from `motion`. g_p, g_v: (n, k, 3) d f / d p and d f / d v.
        Returns:
            dY, dY1: (n, nq); dY = B^T (J^T g_p + Jdot^T g_v) + Bdot^T J^T g_v, dY1 = B^T J^T g_v.
        """
        tm = self.tmap
        Jg = np.einsum("nkij,nki->nj", J, g_v)  # J^T g_v, (n, nv)
        pose = np.einsum("nkij,nki->nj", J, g_p) + np.einsum("nkij,nki->nj", Jd, g_v)
        B = tm.blocks(Y)
        dY = tm.pullback(Y, pose, B)
        dY1 = tm.pullback(Y, Jg, B)
        # Bdot^T x on each quaternion slot: G(q')^T (2x/s) - G(q)^T (4 a x / s^2), a = q.q'
        q, q1 = Y[:, tm.quat_q], Y1[:, tm.quat_q]  # (n, s, 4)
        s = (q * q).sum(-1)[..., None]
        a = (q * q1).sum(-1)[..., None]
        x = Jg[:, tm.quat_v]  # (n, s, 3)
        dY[:, tm.quat_q] += _gt(q1, 2.0 * x / s) - _gt(q, 4.0 * a * x / (s * s))
        return dY, dY1


# ---------------------------------------------------------------------------------------------------
# terms


def _engine_index(engine, model, names) -> np.ndarray:
    """Index in `engine.site_ids` of each named site (InputError if the engine does not track one)."""
    ids = site_ids(model, names)
    where = [np.flatnonzero(engine.site_ids == i) for i in ids]
    if any(len(w) == 0 for w in where):
        raise InputError(f"the inverse-dynamics engine does not track the contact sites {', '.join(names)}")
    return np.array([int(w[0]) for w in where], int)


def _engine_motion(term, Y, Y1, Y2):
    """(motion, engine result) of the shared engine's (cached) forward pass at the samples
    (`solver.terms.dynamics.engine_forward`)."""
    from solver.terms.dynamics import engine_forward

    return engine_forward(term.engine, term.kin.tmap, Y, Y1, Y2)


def _sample_times(Y, t, t_span):
    if t is not None:
        return np.asarray(t, float)
    if t_span is None:
        return None
    return np.linspace(float(t_span[0]), float(t_span[1]), len(Y))
