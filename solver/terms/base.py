"""The one small interface every objective term shares.

A term is an integrand f_j(Y, Y', Y'') of the objective E = sum_j lambda_j integral f_j dt (paper eq. 1),
evaluated at the quadrature points. It returns the per-point values and their gradients with respect
to Y, Y' and Y'' at the same points; the objective applies quadrature weights, term weights and the
chain rule through the spline (docs/design.md). A term that is a sum of squares, f = |r|^2, may also
give its residuals r and their Jacobian (`Term.residual`), which a least-squares method uses
(Gauss-Newton: Nocedal & Wright, Numerical Optimization, 2nd ed., ch. 10).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from solver.path_context import EngineGradient, PathContext


@dataclass
class TermEval:
    """What a term returns at n quadrature points of an nq-dimensional state.

    Attributes:
        f: (n,) integrand values at the quadrature points (units: the term's docstring).
        dY, dY1, dY2: (n, nq) gradients of f with respect to Y, Y', Y''; None where f does not depend
            on that argument (saves the chain-rule product).
        deferred: from `Term.evaluate_in` only: the part of the gradient left in a shared engine's
            variables (`EngineGradient`), added to dY, dY1, dY2 by its `pullback`; the objective sums
            the deferred gradients of one engine and pulls the sum back once.
    """

    f: np.ndarray
    dY: np.ndarray | None = None
    dY1: np.ndarray | None = None
    dY2: np.ndarray | None = None
    deferred: EngineGradient | None = None

    def resolved(self) -> TermEval:
        """The same evaluation with the deferred part pulled back and added to dY, dY1, dY2."""
        if self.deferred is None:
            return self
        parts = []
        for own, pulled in zip((self.dY, self.dY1, self.dY2), self.deferred.pullback(), strict=True):
            parts.append(pulled if own is None else own if pulled is None else own + pulled)
        return TermEval(self.f, *parts)


@dataclass
class SiteRows:
    """How a term's residual columns read the contact sites of an engine: column j is a function of the
    position and velocity of site `site[j]`, with derivatives `dp[:, j]` and `dv[:, j]` (the Jacobian
    rows are then dp J_p + dv J_v, `solver.site_jacobian`, without a reverse pass per column).

    Attributes:
        ctx: the `PathContext` of the evaluation (its site Jacobians are computed once and shared).
        engine, result: the engine and its forward pass on ctx.
        site: (m,) engine site index of each residual column.
        dp: (n, m, 3) d r / d site position [units of r per m], or None.
        dv: (n, m, 3) d r / d site velocity [units of r per m/s], or None.
        signed: (n, m) for one-sided (hinge) columns r = max(0, signed): the value before the max, also
            where r is 0 (how far a clear site is from switching its column on), -inf where it has no
            linearization; None for columns that are not hinges.
        dsigned: (n, m, 3) d signed / d site position everywhere `signed` is finite, or None.
    """

    ctx: object
    engine: object
    result: object
    site: np.ndarray
    dp: np.ndarray | None = None
    dv: np.ndarray | None = None
    signed: np.ndarray | None = None
    dsigned: np.ndarray | None = None

    def blocks(self, nq: int) -> list[tuple]:
        """[(columns (m_g,), comps (c_g,), (J0, J1, None)), ...]: per site, the Jacobian blocks
        (n, m_g, c_g) of its columns over the qpos components that move it."""
        from solver.site_jacobian import cached_site_jacobians

        jac = cached_site_jacobians(self.ctx, self.engine, self.result)
        out = []
        for k in np.unique(self.site):
            cols = np.flatnonzero(self.site == k)
            comps, Jp, Jv = jac[k]
            J0 = J1 = None
            if self.dp is not None:
                J0 = np.einsum("nmi,nic->nmc", self.dp[:, cols], Jp)
            if self.dv is not None:
                if Jv is None:
                    raise ValueError("the engine's pass has no site velocities for a residual that reads them")
                dv = self.dv[:, cols]
                J0 = np.einsum("nmi,nic->nmc", dv, Jv) + (0.0 if J0 is None else J0)
                J1 = np.einsum("nmi,nic->nmc", dv, Jp)
            out.append((cols, comps, (J0, J1, None)))
        return out


@dataclass
class OneSided:
    """One-sided (hinge) columns of a term read from a few path components: r_j = +-max(0, signed_j)
    (so r_j^2 = max(0, signed_j)^2), as `SiteRows.signed` for site columns.

    Attributes:
        signed: (n, m) the value before the max, also where r is 0 (how far column j is from switching
            on at each point) [units of r].
        comps: (m, c) int: the qpos components column j's signed value reads (positions only).
        grad: grad(rows (p,), cols (p,)) -> (p, c): d signed / d Y[rows, comps[cols]] at those (point,
            column) pairs [units of r per unit qpos]; 0 where it is not differentiable.
    """

    signed: np.ndarray
    comps: np.ndarray
    grad: Callable


@dataclass
class Residual:
    """Residuals r of a term that is a sum of squares, f = |r|^2 at every point, and their Jacobian.

    Attributes:
        r: (n, m) residuals at the n quadrature points [sqrt of the term's units].
        blocks: (J0, J1, J2), each (n, m, nq) or None: dr/dY, dr/dY', dr/dY'' point by point (dense
            per-point blocks), or None when the term gives products only (`pull`).
        pull: g (n, m) -> (dY, dY1, dY2), each (n, nq) or None: the vector-Jacobian product
            sum_i g_i . dr_i / d(Y, Y', Y''), or None when `blocks` are given.
        sites: `SiteRows` (with `pull`): the columns as functions of site positions and velocities,
            from which `groups` and `jacobian` build the blocks through the engine's site Jacobians
            (`solver.site_jacobian`, a `KinematicTree` engine) instead of m reverse passes.
        compact: the Jacobian as `groups` gives it, [(columns, comps, (J0, J1, J2)), ...] (instead of
            `blocks`: a term whose columns each read a few components, e.g. one quaternion), with
            nq the state's width.
        one_sided: `OneSided` when the columns are hinges of a few components (the anatomy terms'
            limits), else None.
    """

    r: np.ndarray
    blocks: tuple | None = None
    pull: Callable | None = None
    sites: SiteRows | None = None
    compact: list | None = None
    nq: int | None = None
    one_sided: OneSided | None = None

    def _site_blocks(self):
        """`SiteRows.blocks`, or None if there are none or the engine's pass cannot give them."""
        from solver.site_jacobian import supports

        if self.sites is None or not supports(self.sites.engine):
            return None
        return self.sites.blocks(self.sites.ctx.Y.shape[1])

    def groups(self) -> list[tuple]:
        """The Jacobian in compact blocks: [(columns (m_g,), comps (c_g,), (J0, J1, J2)), ...], each J
        (n, m_g, c_g) or None: columns m_g of r depend only on the components c_g (any order, any
        point); columns that depend on nothing are left out. From `sites` where given, else grouped
        from the dense blocks (`jacobian`) by the components each column reads."""
        if self.compact is not None:
            return self.compact
        site = self._site_blocks()
        if site is not None:
            return site
        blocks = self.jacobian()
        support = None
        for J in blocks:
            if J is not None:
                z = np.any(J != 0, axis=0)  # (m, nq)
                support = z if support is None else support | z
        if support is None:
            return []
        pats, inv = np.unique(support, axis=0, return_inverse=True)
        inv = np.asarray(inv).reshape(-1)
        out = []
        for p in range(len(pats)):
            if pats[p].any():
                cols, comps = np.flatnonzero(inv == p), np.flatnonzero(pats[p])
                out.append((cols, comps, tuple(None if J is None else J[:, cols][:, :, comps] for J in blocks)))
        return out

    def vjp(self, g: np.ndarray) -> tuple:
        """(dY, dY1, dY2) = g^T J at each point, each (n, nq) or None; g: (n, m)."""
        if self.pull is not None:
            return self.pull(g)
        return tuple(None if J is None else np.einsum("nm,nmq->nq", g, J) for J in self.jacobian())

    def jvp(self, dY: np.ndarray | None, dY1: np.ndarray | None = None, dY2: np.ndarray | None = None) -> np.ndarray:
        """(n, m) J d: the change of r along a direction d = (dY, dY1, dY2) (each (n, nq) or None = 0),
        through the dense blocks (`jacobian`: for a term giving products only, m of them first)."""
        out = np.zeros(self.r.shape)
        for J, d in zip(self.jacobian(), (dY, dY1, dY2), strict=True):
            if J is not None and d is not None:
                out += np.einsum("nmq,nq->nm", J, d)
        return out

    def jacobian(self) -> tuple:
        """(J0, J1, J2) dense per-point blocks (n, m, nq) each (None where r does not depend on that
        argument): the given `blocks`, or m vector-Jacobian products with unit vectors."""
        if self.blocks is not None:
            return self.blocks
        n, m = self.r.shape
        site = self.compact if self.compact is not None else self._site_blocks()
        if site is not None:
            nq = self.nq if self.compact is not None else self.sites.ctx.Y.shape[1]
            out = [None, None, None]
            for cols, comps, Js in site:
                for k, J in enumerate(Js):
                    if J is not None:
                        if out[k] is None:
                            out[k] = np.zeros((n, m, nq))
                        out[k][:, cols[:, None], comps[None, :]] = J
            return tuple(out)
        cols = [self.vjp(np.broadcast_to(np.eye(m)[i], (n, m)).copy()) for i in range(m)]
        return tuple(None if cols[0][k] is None else np.stack([c[k] for c in cols], axis=1) for k in range(3))


class Term:
    """Base class of objective terms: the whole interface the objective and the solver use.

    Subclasses set `name` (the command-line name, e.g. "penetration") and `units`, and implement
    either `evaluate` (a term computed from the path arrays alone: the default `evaluate_in` calls it)
    or `evaluate_in` (a term that reads an engine's forward pass through the `PathContext`: the default
    `evaluate` calls it on a context of its own). `needs` tells the objective which spline derivatives
    to compute; a term that is a sum of squares may give `residual`.
    """

    name: str = "term"
    units: str = ""
    needs: tuple[int, ...] = (0,)  # which of Y (0), Y' (1), Y'' (2) the term reads
    #: The Gauss-Newton curvature the preconditioner may assume (`solver.precondition`, radial weight
    #: "auto"); 0 where the term says nothing. acceleration_curvature: d^2 f / d(y'')^2 of each component
    #: whose acceleration the term penalizes (|y''|^2: 2) [units of f s^4].
    acceleration_curvature: float = 0.0
    #: radial_curvature: d^2 f / dr^2 along each quaternion's radial direction q/|q| at |q| = 1, for the
    #: qpos slots `radial_slots` ((s, 4) indices) [units of f].
    radial_curvature: float = 0.0
    radial_slots: np.ndarray | None = None
    #: True if f and its gradients at a point depend only on that point's t, Y, Y', Y'' (no state kept
    #: across points or rounds, no deferred gradient): the objective may then evaluate the term on
    #: blocks of points (`solver.objective.BLOCK_DOUBLES`), which keeps a long clip's temporaries in cache.
    pointwise: bool = False
    #: True if the term keeps something per quadrature point (windows cached for fixed times, a
    #: round's lagged indicator): it needs the uniform rule's fixed points, not Gauss nodes that move
    #: with the frames (`solver.objective.Objective` refuses the combination).
    fixed_points: bool = False

    @property
    def single_quaternion(self) -> bool:
        """True if the term acts on one quaternion filling the whole state (qpos indices 0-3): the
        orientation problem, which `solver.objective` may evaluate in a fused pass. Default False."""
        return False

    def evaluate(
        self, t: np.ndarray, Y: np.ndarray, Y1: np.ndarray | None, Y2: np.ndarray | None, grad: bool = True
    ) -> TermEval:
        """Integrand and its whole gradient at the quadrature points.

        Args:
            t: (n,) quadrature times [s].
            Y, Y1, Y2: (n, nq) spline value, first and second time derivative at t (Y1, Y2 may be None
                when not in `needs`).
            grad: if False the gradients may be left None (value only).
        Returns:
            TermEval without a deferred part.
        Raises:
            NotImplementedError: a subclass that implements neither `evaluate` nor `evaluate_in`.
        """
        if type(self).evaluate_in is Term.evaluate_in:
            raise NotImplementedError(f"term {type(self).__name__} implements neither evaluate nor evaluate_in")
        return self.evaluate_in(PathContext(t, Y, Y1, Y2), grad).resolved()

    def evaluate_in(self, ctx: PathContext, grad: bool = True) -> TermEval:
        """Integrand and gradient on the path of an evaluation (the objective's call): the part of the
        gradient through a shared engine may be left in `TermEval.deferred`.

        Args:
            ctx: the evaluation's `PathContext` (t, Y, Y1, Y2 and the engines' forward passes).
            grad: compute the gradient.
        Returns:
            TermEval.
        """
        return self.evaluate(ctx.t, ctx.Y, ctx.Y1, ctx.Y2, grad)

    def residual(self, ctx: PathContext) -> Residual | None:
        """The residuals r with f = |r|^2 at every point, and their Jacobian, or None if the term is not
        a sum of squares (the default).

        Args:
            ctx: a `PathContext` of the path (t, Y and the derivatives in `needs`).
        Returns:
            Residual, or None.
        """
        return None

    def prepare(self, t: np.ndarray, Y: np.ndarray, Y1: np.ndarray, Y2: np.ndarray) -> None:
        """Called by `Objective.prepare` at the start of each optimization round with the current path
        at the quadrature points. A term that holds something fixed during a round (the root
        residual's lagged flight indicator) sets it here; the default does nothing.

        Args:
            t: (n,) quadrature times [s]. Y, Y1, Y2: (n, nq) the path and its derivatives there.
        """

    def knot_times(self) -> np.ndarray:
        """Times [s] where this term's integrand changes character within the path (e.g. a contact's
        touch-down and lift-off, where a foot goes from swinging to still): `solve` places variable
        frames there before the first round (`SolveOptions.term_knots`), so the spline can bend where
        the motion does. The default: none.

        Returns:
            (r,) times [s], any order.
        """
        return np.zeros(0)

    def violation(self, Y: np.ndarray) -> float | None:
        """How far a path breaks this soft constraint at its worst, in the term's natural unit
        (e.g. metres of penetration), or None if the term is not a constraint. Used for penalty
        continuation (`SolveOptions.limits`) and reports.

        Args:
            Y: (n, nq) qpos samples of the path.
        """
        return None
