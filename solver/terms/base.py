"""The one small interface every objective term shares.

A term is an integrand f_j(Y, Y', Y'') of the objective E = sum_j lambda_j integral f_j dt (paper eq. 1),
evaluated at the quadrature points. It returns the per-point values and their gradients with respect
to Y, Y' and Y'' at the same points; the objective applies quadrature weights, term weights and the
chain rule through the spline (docs/design.md).
"""
from __future__ import annotations

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


class Term:
    """Base class of objective terms: the whole interface the objective and the solver use.

    Subclasses set `name` (the command-line name, e.g. "penetration") and `units`, and implement
    either `evaluate` (a term computed from the path arrays alone: the default `evaluate_in` calls it)
    or `evaluate_in` (a term that reads an engine's forward pass through the `PathContext`: the default
    `evaluate` calls it on a context of its own). `needs` tells the objective which spline derivatives
    to compute.
    """

    name: str = "term"
    units: str = ""
    needs: tuple[int, ...] = (0,)  # which of Y (0), Y' (1), Y'' (2) the term reads
    #: The Gauss-Newton curvature the preconditioner may assume (`solver.paper.precondition`, radial weight
    #: "auto"); 0 where the term says nothing. acceleration_curvature: d^2 f / d(y'')^2 of each component
    #: whose acceleration the term penalizes (|y''|^2: 2) [units of f s^4].
    acceleration_curvature: float = 0.0
    #: radial_curvature: d^2 f / dr^2 along each quaternion's radial direction q/|q| at |q| = 1, for the
    #: qpos slots `radial_slots` ((s, 4) indices) [units of f].
    radial_curvature: float = 0.0
    radial_slots: np.ndarray | None = None
    #: True if f and its gradients at a point depend only on that point's t, Y, Y', Y'' (no state kept
    #: across points or rounds, no deferred gradient): the objective may then evaluate the term on
    #: blocks of points (`solver.spline.BLOCK_DOUBLES`), which keeps a long clip's temporaries in cache.
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

    def prepare(self, t: np.ndarray, Y: np.ndarray, Y1: np.ndarray, Y2: np.ndarray) -> None:
        """Called by `Objective.prepare` at the start of each optimization round with the current path
        at the quadrature points. A term that holds something fixed during a round (the root
        residual's lagged flight indicator) sets it here; the default does nothing.

        Args:
            t: (n,) quadrature times [s]. Y, Y1, Y2: (n, nq) the path and its derivatives there.
        """

