"""Objective terms: each returns its integrand and gradients at the quadrature points (`Term`): the
weighted objective of the orientation problem (paper sec. 3, eq. 1) and the measures `solver.metrics`
reports."""
from solver.terms.base import Term, TermEval
from solver.terms.bending import Hyperextension
from solver.terms.covariant import CovariantAcceleration, NormalizedCovariantAcceleration
from solver.terms.dynamics import JointTorque, RootResidual, make_engine
from solver.terms.penetration import Penetration
from solver.terms.unit import UnitQuaternion

__all__ = [
    "Term", "TermEval", "Hyperextension", "CovariantAcceleration", "NormalizedCovariantAcceleration",
    "Penetration", "UnitQuaternion", "JointTorque", "RootResidual", "make_engine",
]
