"""Inverse-dynamics objective terms (paper sec. 6, appendix A): joint torques and the root residual.

Both read Y, Y', Y'' of the spline, turn them into MuJoCo's qpos, qvel, qacc (`TangentMap.motion`),
compute the generalized forces that produce that motion (`mj_inverse` without constraints; by default
the vectorized `solver.inverse_dynamics.InverseDynamics`, which matches it to rounding error) and chain
the gradient back: reverse pass of the inverse dynamics to (pose tangent, qvel, qacc), then
`PathMotion.vjp` to (Y, Y', Y'').

Terms built on one model share an engine (`engine=`): within an objective evaluation its forward pass
is computed once by the `solver.path_context.PathContext`, and the objective sums the terms' gradients
in the engine's variables and runs its reverse pass once.
"""
from __future__ import annotations

import numpy as np

from solver.contact_thresholds import FLIGHT_CLEARANCE
from solver.contacts import figure_sites
from solver.errors import InputError
from solver.inverse_dynamics import InverseDynamics, MujocoInverseDynamics
from solver.kinematics import TangentMap
from solver.layout import StateLayout
from solver.path_context import EngineGradient, PathContext
from solver.surfaces import StaticSurfaces
from solver.terms.base import Term, TermEval

__all__ = ["BACKENDS", "EngineGradient", "JointTorque", "RootResidual", "engine_forward", "make_engine"]

BACKENDS = {"analytic": InverseDynamics, "mujoco": MujocoInverseDynamics}


def make_engine(model, sites, backend: str = "analytic"):
    """An inverse-dynamics engine for `model` that also tracks `sites`, to share between terms.

    Args:
        model: MjModel. sites: site names (the figure's, `Figure.contact_sites`; () none).
        backend: "analytic" (vectorized recursive Newton-Euler, fast) or "mujoco" (`mj_inverse` +
            `mjd_inverseFD`, general, ~100x slower).
    Raises:
        InputError: unknown backend (lists the valid ones), unknown site, or a model the analytic
            backend does not support.
    """
    if backend not in BACKENDS:
        raise InputError(
            f"unknown inverse-dynamics backend {backend!r}; choose one of: {', '.join(BACKENDS)}"
        )
    return BACKENDS[backend](model, sites)


def engine_forward(engine, tmap: TangentMap, Y: np.ndarray, Y1: np.ndarray, Y2: np.ndarray | None):
    """(motion, engine result) of a path at its samples outside an objective evaluation (a query such
    as `JointTorque.torques`): `PathContext.forward` on a context of its own. Within an evaluation the
    terms share the context's pass instead.

    Args:
        engine: see `solver.path_context`. tmap: the model's `TangentMap`. Y, Y1, Y2: (n, nq) qpos and
            its time derivatives (Y2 unused if the engine does not read qacc).
    """
    return PathContext(None, Y, Y1, Y2).forward(engine, tmap)


def _free_joint(model, layout: StateLayout) -> int:
    """Id of the model's first free joint (the figure's root). Raises InputError if there is none."""
    free = [j for j in range(model.njnt) if model.jnt_type[j] == 0]  # mjJNT_FREE
    if not free:
        raise InputError(
            "the model has no free joint (the figure's root); joints are: " + ", ".join(layout.names)
        )
    return free[0]


class JointTorque(Term):
    """f = sum over the joint DOFs i of w_i tau_i^2 [N^2 m^2]: squared joint torques (paper sec. 6).

    tau = M(q) qacc + c(q, qvel) - qfrc_passive at each quadrature point (`mj_inverse` without
    constraints), for every DOF except those of the free root (the root's 6 are the residual wrench,
    `RootResidual`): 33 of the figure's 39. Ball-joint torques are in the child body's frame; the sum of
    squares is frame-independent per joint.

    Args:
        model: MjModel (loaded once by the caller).
        weights: optional {joint name: w >= 0}; the weight applies to all DOFs of that joint, others
            weigh 1.
        engine: an engine from `make_engine` to share with other terms; default: a new one.
        backend: "analytic" or "mujoco" when no engine is given.
    Raises:
        InputError: unknown joint name in `weights` (lists the joints), a negative or non-finite
            weight, a weight on the free root, or an unsupported model (see `make_engine`).
    """

    name = "torque"
    units = "N^2 m^2"
    needs = (0, 1, 2)
    fixed_points = True  # an inverse-dynamics term (its forward pass is shared through the context)

    def __init__(
        self, model, weights: dict[str, float] | None = None, engine=None, backend: str = "analytic"
    ):
        self.layout = StateLayout.from_model(model)
        self.tmap = TangentMap.from_layout(self.layout)
        self.engine = engine if engine is not None else make_engine(model, (), backend)
        w = np.ones(int(model.nv))
        for j in self.layout.joints:
            if j.kind == "free":
                w[j.dofadr : j.dofadr + j.nv] = 0.0
        for name, value in (weights or {}).items():
            joint = self.layout.joint(name)
            if joint.kind == "free":
                raise InputError(
                    f"joint {name!r} is the free root; its forces are the 'root' term, not torques"
                )
            value = float(value)
            if not np.isfinite(value) or value < 0:
                raise InputError(
                    f"torque weight of joint {name!r} is {value}; weights must be finite and >= 0"
                )
            w[joint.dofadr : joint.dofadr + joint.nv] = value
        self.dof_weights = w

    def torques(self, Y: np.ndarray, Y1: np.ndarray, Y2: np.ndarray) -> np.ndarray:
        """(n, nv) generalized forces along the path [N, N m] (the free root's 6 included)."""
        return engine_forward(self.engine, self.tmap, Y, Y1, Y2)[1].tau

    def evaluate_in(self, ctx, grad=True) -> TermEval:
        """`Term.evaluate_in`: the gradient left as an `EngineGradient` (summed with other terms' by
        the objective and pulled back once)."""
        mo, res = ctx.forward(self.engine, self.tmap)
        wt = self.dof_weights * res.tau
        f = (wt * res.tau).sum(axis=1)
        if not grad:
            return TermEval(f)
        return TermEval(f, deferred=EngineGradient(self.engine, res, mo, 2.0 * wt))

def figure_radius_of_gyration(model, body: int) -> float:
    """sqrt(trace(I_c) / (3 m)) [m] of the subtree of `body` at `qpos0`: I_c its inertia about its
    centre of mass, m its mass (the root-mean-square radius of gyration over the three axes)."""
    import mujoco

    d = mujoco.MjData(model)
    mujoco.mj_kinematics(model, d)
    mujoco.mj_comPos(model, d)
    bodies = [b for b in range(model.nbody) if _in_subtree(model, b, body)]
    m = sum(float(model.body_mass[b]) for b in bodies)
    com = d.subtree_com[body]
    tr = 0.0
    for b in bodies:
        r = d.xipos[b] - com
        tr += float(model.body_inertia[b].sum()) + float(model.body_mass[b]) * 2.0 * float(r @ r)
    return float(np.sqrt(tr / (3.0 * m))) if m > 0 else 1.0


def _in_subtree(model, b: int, root: int) -> bool:
    while b > 0:
        if b == root:
            return True
        b = int(model.body_parentid[b])
    return root == 0


class RootResidual(Term):
    """f = phi(Y) (|F|^2 + |T|^2 / l^2) [N^2]: the "hand of god" wrench on the root while in flight.

    (F, T) are the free root's 6 generalized forces from inverse dynamics: F the world force [N], T the
    torque about the root body's origin in its frame [N m]. They are the external wrench needed to
    produce the motion besides gravity. In flight only gravity acts, so the wrench should be zero; on
    the ground the feet provide it, which this term does not model, so it is switched off there by

        phi = prod over contact sites k and static surfaces j of S(c_kj),
        c_kj = clip(1 - depth_kj / d, 0, 1),   S(c) = 3 c^2 - 2 c^3 (smoothstep, C1),

    where depth_kj = `StaticSurfaces.penetration(site, margin=d)` is d minus the site's clearance above
    surface j (planes: its signed height; boxes grown by d: distance to the nearest face), floored at
    0. So phi = 1 when every site is at least d = `contact_distance` clear of every surface, 0 when any
    site touches or is inside one, smooth in between.

    The indicator is *lagged* by default (`flight="lagged"`): at the start of each optimization round
    (`prepare`, called by `solve`) phi_0 = phi(path) is recorded at the quadrature points, and during
    the round the term uses

        phi_eff = smax(phi_0, phi) = (phi_0 + phi + sqrt((phi - phi_0)^2 + e^2) - e) / 2,  e = 0.05,

    a smooth max (= phi at the round's start, >= 0, within e/2 of max(phi_0, phi)) whose gradient
    flows through phi only where phi exceeds phi_0. So lifting the feet into flight costs (the
    airborne wrench is penalized), but lowering them into the contact band does not pay: with phi
    alone (`flight="path"`) the cheapest way to lower the term was to end the flight, and on the
    run-and-step clip the optimizer kept the feet hovering 1-3 cm above the floor, where phi is
    small, so the flight phases shrank from 0.25 s to 0.02 s while the figure still floated. With phi
    held fixed during a round (no gradient at all) the opposite happened: making a flight ballistic
    lifts the body, the next round counts more samples as flight, and the flight grew to ~1 s with
    the feet 5-10 cm above the floor in support phases. The smooth max keeps the gait (0.23 s of
    flight against the plain spline's 0.25 s) and makes its flight ballistic. Until `prepare` has
    been called for the quadrature points being evaluated, phi_eff = phi ("path").

    Scaling: |T| / l with l the figure's radius of gyration (about 0.35 m for the 70 kg figure): a force
    F changes the centre-of-mass acceleration by F/m and a torque T the acceleration of the body's mass
    at its typical radius by T/(m l), so the two parts weigh equally in acceleration terms. Pass
    `torque_arm` to choose l [m] yourself.

    Args:
        model: MjModel of the scene (figure + static surfaces), loaded once by the caller.
        surfaces: StaticSurfaces of the scene; default `StaticSurfaces.from_model(model)`.
        contact_distance: d [m] > 0, the clearance above which a site counts as in the air.
        sites: contact site names (default the model's figure's, `solver.contacts.figure_sites`).
        torque_arm: l [m] > 0; default the radius of gyration of the root's subtree at qpos0.
        engine: an engine from `make_engine` (must track `sites`) to share; default a new one.
        backend: "analytic" or "mujoco" when no engine is given.
        flight: "lagged" (phi_eff = smax(phi at the round's start, phi), see above) or "path".
    Raises:
        InputError: no free joint, missing site (lists the model's sites), bad distance or arm, an
            engine that does not track the sites, an unsupported model, or an unknown `flight`.
    """

    FLIGHT_MODES = ("lagged", "path")
    LAG_SMOOTHING = 0.05  # [1] e of the smooth max in the lagged indicator phi (in [0, 1]): 5 % of its range

    name = "root"
    units = "N^2"
    needs = (0, 1, 2)
    fixed_points = True  # the lagged indicator is kept per quadrature point (`prepare`)

    def __init__(
        self,
        model,
        surfaces: StaticSurfaces | None = None,
        contact_distance: float = FLIGHT_CLEARANCE,
        sites=None,
        torque_arm: float | None = None,
        engine=None,
        backend: str = "analytic",
        flight: str = "lagged",
    ):
        import mujoco

        if flight not in self.FLIGHT_MODES:
            raise InputError(f"unknown flight mode {flight!r}; choose one of: {', '.join(self.FLIGHT_MODES)}")
        self.flight_mode = flight
        self._lagged: tuple[np.ndarray, np.ndarray] | None = None  # (t, phi) from `prepare`
        self.layout = StateLayout.from_model(model)
        self.tmap = TangentMap.from_layout(self.layout)
        root = _free_joint(model, self.layout)
        adr = int(model.jnt_dofadr[root])
        self.root_dofs = np.arange(adr, adr + 6)
        self.surfaces = StaticSurfaces.from_model(model) if surfaces is None else surfaces
        d = float(contact_distance)
        if not np.isfinite(d) or d <= 0:
            raise InputError(f"contact_distance is {contact_distance}; it must be a distance > 0 [m]")
        self.contact_distance = d
        sites = figure_sites(model, sites)
        self.engine = engine if engine is not None else make_engine(model, sites, backend)
        ids = []
        for name in sites:
            sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
            where = np.flatnonzero(self.engine.site_ids == sid)
            if sid < 0 or not len(where):
                have = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, k) for k in range(model.nsite)]
                raise InputError(
                    f"contact site {name!r} is not in the model or not tracked by the engine; the model's "
                    f"sites are: {', '.join(map(str, have)) or 'none'}"
                )
            ids.append(int(where[0]))
        self.site_index = np.array(ids, int)
        if torque_arm is None:
            torque_arm = figure_radius_of_gyration(model, int(model.jnt_bodyid[root]))
        arm = float(torque_arm)
        if not np.isfinite(arm) or arm <= 0:
            raise InputError(f"torque_arm is {torque_arm}; it must be a length > 0 [m]")
        self.torque_arm = arm
        self._scale = np.array([1.0, 1.0, 1.0] + [1.0 / arm**2] * 3)

    def flight(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The flight indicator phi and its gradient with respect to the site positions.

        Args:
            points: (n, k, 3) contact-site positions [m].
        Returns:
            phi (n,) in [0, 1]; dphi (n, k, 3) [1/m].
        """
        d = self.contact_distance
        depth, ddepth = self.surfaces.penetration(points, margin=d)  # (n,k,S), (n,k,S,3)
        c = np.clip(1.0 - depth / d, 0.0, 1.0)
        S = c * c * (3.0 - 2.0 * c)
        n = points.shape[0]
        phi = S.reshape(n, -1).prod(axis=1)
        # d phi / d S_kj = product of the other factors; where S_kj = 0, dS/dc = 0 as well (c = 0)
        safe = np.where(S > 0, S, 1.0)
        others = np.where(S > 0, phi[:, None, None] / safe, 0.0)
        dS = 6.0 * c * (1.0 - c) * (-1.0 / d)
        dphi = np.einsum("nks,nksi->nki", others * dS, ddepth)
        return phi, dphi

    def prepare(self, t, Y, Y1, Y2) -> None:
        """Lagged flight: record phi_0 at the quadrature points t from the path (Y, Y', Y'') there."""
        if self.flight_mode != "lagged":
            return
        mo, res = engine_forward(self.engine, self.tmap, Y, Y1, Y2)
        phi, _ = self.flight(res.sites[:, self.site_index])
        self._lagged = (np.array(t, float), phi)

    def _fixed_phi(self, t) -> np.ndarray | None:
        """The lagged phi if `prepare` was called for these quadrature points, else None."""
        lag = self._lagged
        if lag is None or t is None or np.shape(t) != lag[0].shape or not np.array_equal(t, lag[0]):
            return None
        return lag[1]

    def wrench(self, Y: np.ndarray, Y1: np.ndarray, Y2: np.ndarray) -> np.ndarray:
        """(n, 6) the root's generalized forces along the path: world force [N], local torque [N m]."""
        return engine_forward(self.engine, self.tmap, Y, Y1, Y2)[1].tau[:, self.root_dofs]

    def _indicator(self, t, res):
        """phi_eff (n,) and d phi_eff / d site positions (n, k, 3) (lagged smooth max, see the class)."""
        phi, dphi = self.flight(res.sites[:, self.site_index])
        phi0 = self._fixed_phi(t)
        if phi0 is not None:  # lagged: smooth max of the round's start value and the path's own
            e = self.LAG_SMOOTHING
            d = phi - phi0
            root = np.sqrt(d * d + e * e)
            phi = 0.5 * (phi0 + phi + root - e)
            dphi = (0.5 * (1.0 + d / root))[:, None, None] * dphi
        return phi, dphi

    def evaluate_in(self, ctx, grad=True) -> TermEval:
        """`Term.evaluate_in`: the gradient left as an `EngineGradient` (see `JointTorque`)."""
        mo, res = ctx.forward(self.engine, self.tmap)
        wr = res.tau[:, self.root_dofs]
        sw = self._scale * wr
        r = (sw * wr).sum(axis=1)
        phi, dphi = self._indicator(ctx.t, res)
        f = phi * r
        if not grad:
            return TermEval(f)
        g_tau = np.zeros(res.tau.shape)
        g_tau[:, self.root_dofs] = (2.0 * phi)[:, None] * sw
        g_sites = np.zeros(res.sites.shape)
        g_sites[:, self.site_index] = r[:, None, None] * dphi
        return TermEval(f, deferred=EngineGradient(self.engine, res, mo, g_tau, g_sites))

