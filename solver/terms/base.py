"""The one small interface every objective term shares.

A term is an integrand f_j(Y, Y', Y'') of the objective E = sum_j lambda_j integral f_j dt (paper eq. 1),
evaluated at the quadrature points. It returns the per-point values and their gradients with respect
to Y, Y' and Y'' at the same points; the objective applies quadrature weights, term weights and the
chain rule through the spline (docs/design.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class TermEval:
    """What a term returns at n quadrature points of an nq-dimensional state.

    Attributes:
        f: (n,) integrand values at the quadrature points (units: the term's docstring).
        dY, dY1, dY2: (n, nq) gradients of f with respect to Y, Y', Y''; None where f does not depend
            on that argument (saves the chain-rule product).
        deferred: from `evaluate_deferred` only: the rest of the gradient, not yet pulled back to
            (Y, Y', Y''), with `key`, `scaled(c)`, `plus(other, c)` and `pullback() -> (dY, dY1, dY2)`;
            the objective sums the deferred gradients with the same key (terms sharing an
            inverse-dynamics engine) and pulls the sum back once.
    """

    f: np.ndarray
    dY: np.ndarray | None = None
    dY1: np.ndarray | None = None
    dY2: np.ndarray | None = None
    deferred: object | None = None


class Term:
    """Base class of objective terms.

    Subclasses set `name` (the command-line name, e.g. "penetration") and `units`, and implement
    `evaluate(t, Y, Y1, Y2, grad)`. `needs` tells the objective which spline derivatives to compute.
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

    def evaluate(
        self, t: np.ndarray, Y: np.ndarray, Y1: np.ndarray | None, Y2: np.ndarray | None, grad: bool = True
    ) -> TermEval:
        """Integrand and gradients at the quadrature points.

        Args:
            t: (n,) quadrature times [s].
            Y, Y1, Y2: (n, nq) spline value, first and second time derivative at t (Y1, Y2 may be None
                when not in `needs`).
            grad: if False the gradients may be left None (value only).
        Returns:
            TermEval.
        """
        raise NotImplementedError

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
