"""The one interface of a constraint: c(path) <= 0 at fixed (quadrature point, column) pairs, in a unit.

A constraint is what a user states as a limit: a foot on the floor, a knee within its range. Each is a
function of the path with its own unit, sampled at the quadrature points where it applies (its pairs:
a point and a column, e.g. a contact site or a joint), written as c = measure - limit <= 0 in SI units
(`measure` signed so that the bound is an upper one), with a tolerance in the same unit: a pair is met
when c <= tolerance. `values` gives c at every pair; `pull` adds g^T dc/d(path) for weights g at the
pairs to the evaluation's adjoints (`solver.path_state.PathState`). The method of multipliers
(`solver.lagrangian`) reads nothing else; a limit raised where the keyframes or the frames cannot meet
it is `limit` changed, nothing else.
"""
from __future__ import annotations

import numpy as np

from solver.path_state import PathState

__all__ = ["LIMIT", "RELATIVE", "RELATIVE_TOLERANCE", "REPRESENTATION", "SCHEDULE", "Constraint"]

#: [1] the tolerance of a bound set by a reference motion's own figure (the no-jolt peaks, the effort, the peak
#: ground force), relative to that bound: 5 %, one value for every such bound (a figure read off a
#: low-pass-filtered capture is not known more precisely than that)
RELATIVE_TOLERANCE = 0.05

#: `Constraint.priority` values, lowest first to give
REPRESENTATION, SCHEDULE, RELATIVE, LIMIT = range(4)


class Constraint:
    """Base class (module docstring).

    Subclasses set `name`, `unit` (as shown to users), `scale` (SI per shown unit: 1e-3 for mm),
    `tolerance` [SI] (a number or (p,)), `limit` (p,) [SI], `rows` (p,) the quadrature point of each pair
    and `labels` (p,) its column's name, and implement `measure` and `pull`.
    """

    name: str = "constraint"
    unit: str = ""
    scale: float = 1.0
    tolerance: float = 1.0
    rows: np.ndarray = np.zeros(0, int)
    labels: np.ndarray = np.zeros(0, object)
    #: the order in which limits give where the constraints cannot all be met (`solver.feasibility`: the
    #: least violation is found level by level from the highest). REPRESENTATION (0): a bound of the
    #: spline's own representation, not of the motion (unit quaternions between the frames); SCHEDULE (1):
    #: a wish of the contact schedule (a foot planted, a site clear), an estimate from the capture or the
    #: animator; RELATIVE (2): a bound set by what the reference motion's body does (no jolts beyond the
    #: capture's or the plain spline's peaks, their effort), which the feet's estimated schedule does not
    #: override (a jolt is seen at once, a foot sliding a millimetre is not); LIMIT (3): a limit of the body,
    #: the scene or physics (a foot in the floor, a knee bent backwards, a wrench in flight)
    priority: int = LIMIT

    @property
    def size(self) -> int:
        """p, the number of pairs."""
        return len(self.rows)

    def column_unit(self, label: str) -> str:
        """The unit shown for the column `label` (a site, a joint): the constraint's `unit`, unless its columns
        measure different quantities."""
        return self.unit

    def pair_weights(self, weights: np.ndarray) -> np.ndarray:
        """(p,) the time each pair stands for [s], from the quadrature weights (n,) [s]: a pointwise
        constraint's pair stands for its point's weight (the default); an integral constraint's pair for
        its interval's length. A knot's point (weight 0: it only adds a point where a pointwise bound is
        checked, `solver.quadrature.quadrature_points`) stands for one spacing of the rule, as its
        neighbours do, so its pairs are priced like theirs."""
        w = weights[self.rows]
        return np.where(w > 0, w, float(np.max(weights, initial=0.0)))

    def measure(self, state: PathState) -> np.ndarray:
        """(p,) the constrained quantity at the pairs [SI], signed so that the bound is measure <= limit."""
        raise NotImplementedError

    def values(self, state: PathState) -> np.ndarray:
        """(p,) c = measure - limit [SI] at the pairs (<= 0: met)."""
        return self.measure(state) - self.limit

    def excess(self, measure: np.ndarray, limit: np.ndarray, pairs: np.ndarray) -> np.ndarray:
        """(q,) how far the constrained quantity is beyond its limit at `pairs` (q,) [SI], from the measure
        and limit (p,): measure - limit, unless the measure is a smooth form of the quantity (then the
        subclass converts, e.g. `solver.constraints.acceleration`)."""
        return measure[pairs] - limit[pairs]

    def pull(self, state: PathState, g: np.ndarray) -> None:
        """Add sum_p g_p dc_p/d(path) to the state's adjoints. g: (p,)."""
        raise NotImplementedError

    def curvature(self, state: PathState, d1: np.ndarray, d2: np.ndarray) -> list:
        """The Gauss-Newton curvature of sum_p psi_p(c_p) at the state, psi_p'(c_p) = d1_p >= 0 and
        psi_p''(c_p) = d2_p >= 0 (p,): sum_p d2_p grad c_p grad c_p^T + d1_p (the Gauss-Newton part of c_p's own
        curvature), as `solver.curvature.Curvature` and `Outer` terms for the preconditioner
        (`solver.gauss_newton`). The default, []: a constraint the preconditioner leaves out; the stiff
        ones, the no-jolt bound and the slide, give theirs."""
        return []
