"""The path context: one evaluation's path at the quadrature points and what the terms compute from it.

Every objective term reads the path (Y, Y', Y'' at the quadrature points, `solver.objective`), and the
kinematic and dynamic terms read the same things computed from it: the contact sites' positions and
velocities (paper appendix A eq. 13 and 19) and the inverse dynamics (appendix A eq. 18-21). A
`PathContext` holds the path of one evaluation and computes each engine's forward pass once, lazily,
on the first term that asks for it; the terms leave their gradients in the engine's variables
(`EngineGradient`), and the objective sums those of one engine and runs its reverse pass once
(docs/architecture.md, "Objective terms").

An engine is any object with this interface (`solver.kinematic_tree.SiteKinematics`,
`solver.inverse_dynamics.InverseDynamics`, `solver.inverse_dynamics_mujoco.MujocoInverseDynamics`,
`MujocoSitePositions` below):

    needs: the path derivatives its forward pass reads when the context has them (0 qpos, 1 qvel, 2 qacc)
    required: those it cannot do without (a kinematics engine computes positions alone from qpos)
    has_site_velocities: whether `site_velocities(result)` and `vjp(..., g_site_vel)` exist
    motion_map: a TangentMap of the joints it reads, or None (the term's own map is used)
    site_ids: (k,) MuJoCo ids of the sites it tracks
    forward(qpos, qvel, qacc) -> InverseDynamicsResult;  vjp(result, g_tau, g_sites[, g_site_vel])
    positions(qpos) -> (n, k, 3) site positions [m] (a query outside an evaluation)
"""
from __future__ import annotations

import numpy as np

from solver.errors import InputError
from solver.inverse_dynamics_mujoco import InverseDynamicsResult
from solver.kinematics import TangentMap
from solver.layout import site_ids


class PoseOnly:
    """The motion of a path without velocities (`PathContext.forward` when the context has no Y'): its
    `vjp` maps a pose gradient back to Y (`TangentMap.pullback`), only at the rows where it is nonzero.

    Args:
        tmap: TangentMap of the model. Y: (n, nq) qpos.
    """

    qvel = None
    qacc = None

    def __init__(self, tmap: TangentMap, Y: np.ndarray):
        self.tmap, self.Y = tmap, Y

    def vjp(self, g_v, g_a, g_pose):
        """(dY (n, nq), None, None) from g_pose (n, nv) d f / d pose (g_v, g_a must be None)."""
        if g_v is not None or g_a is not None:
            raise ValueError("a pose-only motion has no qvel or qacc to pull back")
        dY = np.zeros(self.Y.shape)
        rows = np.flatnonzero(np.any(g_pose != 0, axis=1))
        if rows.size:
            dY[rows] = self.tmap.pullback(self.Y[rows], g_pose[rows])
        return dY, None, None


class PathContext:
    """One evaluation's path at the quadrature points, with each engine's forward pass computed once.

    Args:
        t: (n,) quadrature times [s] (None for a query without times).
        Y, Y1, Y2: (n, nq) the path and its first and second time derivatives (Y1, Y2 None where no
            term of the evaluation reads them).
    """

    def __init__(self, t, Y: np.ndarray, Y1: np.ndarray | None = None, Y2: np.ndarray | None = None):
        self.t, self.Y, self.Y1, self.Y2 = t, Y, Y1, Y2
        self._passes: dict[int, tuple] = {}

    def forward(self, engine, tmap: TangentMap):
        """(motion, result) of `engine` on this path, computed on the first call and kept.

        motion is the path's `PathMotion` (qvel, and qacc if the engine reads it; `PoseOnly` when the
        context has no Y' and the engine does not require it); result the engine's
        `InverseDynamicsResult` (site positions, and velocities and forces where the engine has them).

        Args:
            engine: see the module docstring. tmap: the model's TangentMap (used unless the engine has
                its own `motion_map`).
        Raises:
            ValueError: the engine requires a derivative the context does not have (a term whose
                `needs` do not include its engine's `required`).
        """
        hit = self._passes.get(id(engine))
        if hit is not None:
            return hit[1], hit[2]
        Y1 = self.Y1 if 1 in engine.needs else None
        Y2 = self.Y2 if 2 in engine.needs else None
        for k, have in ((1, Y1), (2, Y2)):
            if k in engine.required and have is None:
                raise ValueError(f"the engine {type(engine).__name__} needs path derivative {k}, which this "
                                 "context lacks (the term's `needs` must include its engine's `required`)")
        tm = engine.motion_map if engine.motion_map is not None else tmap
        if Y1 is None:
            mo = PoseOnly(tmap, self.Y)
            res = engine.forward(self.Y, None, None)
        else:
            mo = tm.motion(self.Y, Y1, Y2)
            res = engine.forward(self.Y, mo.qvel, mo.qacc)
        self._passes[id(engine)] = (engine, mo, res)
        return mo, res


class EngineGradient:
    """A term's gradient left in an engine's variables (`TermEval.deferred`).

    d f / d tau (n, nv), d f / d site positions and velocities (n, k, 3) at one forward pass of one
    engine. The objective sums those of the terms sharing the engine (they share its forward pass
    through the `PathContext`) and pulls the sum back to (Y, Y', Y'') once: one reverse pass of the
    engine and of the tangent map (`PathMotion.vjp`) instead of one per term. Both are linear in the
    adjoints, so the result is the sum of the terms' gradients.
    """

    __slots__ = ("engine", "result", "motion", "g_tau", "g_sites", "g_site_vel")

    def __init__(self, engine, result, motion, g_tau=None, g_sites=None, g_site_vel=None):
        self.engine, self.result, self.motion = engine, result, motion
        self.g_tau, self.g_sites, self.g_site_vel = g_tau, g_sites, g_site_vel

    @property
    def key(self):
        """What identifies the forward pass: gradients with the same key may be summed."""
        return (id(self.engine), id(self.result))

    def scaled(self, c: float) -> EngineGradient:
        """c * self (a new object)."""
        return EngineGradient(
            self.engine, self.result, self.motion, *(None if g is None else c * g
                                                     for g in (self.g_tau, self.g_sites, self.g_site_vel)))

    def plus(self, other: EngineGradient, c: float) -> EngineGradient:
        """self + c * other (a new object; same key)."""

        def add(a, b):
            if b is None:
                return a
            return c * b if a is None else a + c * b

        return EngineGradient(
            self.engine, self.result, self.motion, add(self.g_tau, other.g_tau), add(self.g_sites, other.g_sites),
            add(self.g_site_vel, other.g_site_vel),
        )

    def pullback(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """(dY, dY1, dY2), each (n, nq) or None where the motion has no such derivative."""
        if self.g_site_vel is None:
            g_pose, g_v, g_a = self.engine.vjp(self.result, self.g_tau, self.g_sites)
        else:
            g_pose, g_v, g_a = self.engine.vjp(self.result, self.g_tau, self.g_sites, self.g_site_vel)
        if self.motion.qacc is None:
            g_a = None
        return self.motion.vjp(g_v, g_a, g_pose)


def engine_sites(engine, model, names) -> np.ndarray | slice:
    """Index into `engine.site_ids` of each named site: a slice when they are consecutive (the figure's).

    Raises:
        InputError: the engine does not track one of the sites (names them).
    """
    from solver.layout import index_run

    ids = site_ids(model, names)
    where = [np.flatnonzero(engine.site_ids == i) for i in ids]
    if any(len(w) == 0 for w in where):
        raise InputError(f"the engine does not track the contact sites {', '.join(names)}")
    return index_run([int(w[0]) for w in where])


class MujocoSitePositions:
    """Site positions by MuJoCo (`mj_kinematics` point by point) and their reverse pass (`mj_jacSite`):
    the site engine of models the vectorized tree does not cover (hinge or slide joints). Positions
    only (no velocities, no forces). See the module docstring for the interface.

    Args:
        model: MjModel (not modified). sites: site names.
    """

    needs = (0,)
    required = (0,)
    has_site_velocities = False
    motion_map = None

    def __init__(self, model, sites=()):
        import mujoco

        self.model, self.data = model, mujoco.MjData(model)
        self.nv = int(model.nv)
        self.site_ids = site_ids(model, sites)
        self._jac = np.zeros((3, self.nv))

    def positions(self, qpos: np.ndarray) -> np.ndarray:
        """(n, k, 3) world positions [m] of the sites at qpos (n, nq)."""
        from solver.kinematics import mujoco_site_positions

        return mujoco_site_positions(self.model, self.data, self.site_ids, qpos)

    def forward(self, qpos, qvel=None, qacc=None) -> InverseDynamicsResult:
        """The sites' positions at qpos (n, nq) (qvel, qacc ignored); tau is an empty (n, 0)."""
        empty = np.zeros((len(qpos), 0))
        return InverseDynamicsResult(empty, self.positions(qpos), np.array(qpos, float), empty, empty)

    def vjp(self, res, g_tau=None, g_sites=None):
        """(g_pose (n, nv), None, None): the gradient of sum g_sites . sites in MuJoCo's tangent convention."""
        import mujoco

        m, d = self.model, self.data
        G = np.zeros((len(res.qpos), self.nv))
        if g_sites is None:
            return G, None, None
        for i in np.flatnonzero(np.any(g_sites != 0, axis=(1, 2))):
            d.qpos[:] = res.qpos[i]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            for k, sid in enumerate(self.site_ids):
                mujoco.mj_jacSite(m, d, self._jac, None, int(sid))
                G[i] += g_sites[i, k] @ self._jac
        return G, None, None


def site_engine(model, sites, velocities: bool = True):
    """The engine of a kinematic term that is given none: the vectorized `SiteKinematics`, or, for a
    model it does not cover and a term that reads positions only, `MujocoSitePositions`.

    Args:
        model: MjModel. sites: site names. velocities: the term reads site velocities.
    Raises:
        InputError: the model has joints the vectorized kinematics does not model and velocities are
            needed (names them), or an unknown site.
    """
    from solver.kinematic_tree import SiteKinematics

    try:
        return SiteKinematics(model, sites)
    except InputError:
        if velocities:
            raise
        return MujocoSitePositions(model, sites)
