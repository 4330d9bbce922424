"""The residual form of the terms that are sums of squares (`Term.residual`): |r|^2 is the integrand,
and the Jacobian (dense blocks or vector-Jacobian products) agrees with central finite differences of r."""

import numpy as np
import pytest

from solver.layout import StateLayout
from solver.path_context import PathContext
from solver.terms import (
    CovariantAcceleration,
    Hyperextension,
    NormalizedCovariantAcceleration,
    Penetration,
    Term,
    TermEval,
    UnitQuaternion,
)
from solver.terms.dynamics import JointTorque, RootResidual

from conftest import random_qpos

N = 12
HINGES = {"l_knee": (0, 1, 0), "r_knee": (0, -1, 0)}




def _path(layout, seed, height, spread=0.3):
    rng = np.random.default_rng(seed)
    Y = random_qpos(rng, layout, N, spread=spread)
    Y[:, 2] = height + 0.02 * rng.normal(size=N)
    return np.linspace(0.0, 1.0, N), Y, 0.5 * rng.normal(size=Y.shape), 0.5 * rng.normal(size=Y.shape)


# name -> (factory(model, layout), root height [m] of the test path: the feet inside or near surfaces)
CASES = {
    "penetration": (lambda m, lay: Penetration(m, margin=0.005), 0.93),
    "unit": (lambda m, lay: UnitQuaternion(lay.quat_slots), 1.0),
    "smooth": (lambda m, lay: CovariantAcceleration(lay.quat_slots, lay.linear_index), 1.0),
    "covariant_normalized": (lambda m, lay: NormalizedCovariantAcceleration(lay.quat_slots), 1.0),
    "bending": (lambda m, lay: Hyperextension(lay, HINGES, tolerance=-0.3), 1.0),
    "torque": (lambda m, lay: JointTorque(m, weights={"l_knee": 2.0}), 1.0),
    "root": (lambda m, lay: RootResidual(m), 0.98),
}


def _args(term, Y, Y1, Y2):
    return Y, (Y1 if 1 in term.needs else None), (Y2 if 2 in term.needs else None)


@pytest.mark.parametrize("name", list(CASES))
def test_residual_squares_to_the_integrand_and_its_jacobian_matches_central_differences(toy_model, name):
    """f = |r|^2 point by point (to 1e-12 relative), and for a random weighting g and a random
    direction D in (Y, Y', Y''): the vector-Jacobian product against the central difference of g.r
    along D (step 1e-6; to 1e-5 relative, or 1e-9 absolute), and the dense blocks against the product."""
    layout = StateLayout.from_model(toy_model)
    factory, height = CASES[name]
    term = factory(toy_model, layout)
    t, Y, Y1, Y2 = _path(layout, 3, height)
    args = _args(term, Y, Y1, Y2)
    res = term.residual(PathContext(t, *args))
    assert res is not None and res.r.shape[0] == N
    f = term.evaluate(t, *args, grad=False).f
    assert np.any(f > 0), "the term is zero on the test path: the check checks nothing"
    np.testing.assert_allclose((res.r * res.r).sum(1), f, rtol=1e-12, atol=1e-14 * f.max())

    rng = np.random.default_rng(4)
    g = rng.normal(size=res.r.shape)
    D = [rng.normal(size=Y.shape) if a is not None else None for a in args]
    h = 1e-6

    def gr(eps):
        moved = [None if a is None else a + eps * d for a, d in zip(args, D)]
        return float((g * term.residual(PathContext(t, *moved)).r).sum())

    fd = (gr(h) - gr(-h)) / (2 * h)
    pulled = res.vjp(g)
    an = sum(float((p * d).sum()) for p, d in zip(pulled, D) if p is not None and d is not None)
    assert abs(an) > 0, "the Jacobian is zero along D: the check checks nothing"
    assert abs(an - fd) <= max(1e-5 * abs(fd), 1e-9), f"{name}: J^T g . D {an:.9g}, central difference {fd:.9g}"
    blocks = res.jacobian()
    for k, (J, p) in enumerate(zip(blocks, pulled)):
        if J is None:
            assert p is None or not np.any(p), f"{name}: d r / d Y{k} has no block but a nonzero product"
            continue
        np.testing.assert_allclose(np.einsum("nm,nmq->nq", g, J), p, rtol=1e-10, atol=1e-12 * np.abs(p).max())
    assert float((g * res.jvp(*D)).sum()) == pytest.approx(an, rel=1e-10, abs=1e-14)  # g.(J D) = (J^T g).D


def test_a_term_that_is_not_a_sum_of_squares_has_no_residual(toy_model):
    """The default: `Term.residual` is None (a term that gives only its integrand)."""

    class Speed(Term):
        name, needs = "speed", (0, 1)

        def evaluate(self, t, Y, Y1, Y2, grad=True):
            return TermEval(np.abs(Y1).sum(1))

    layout = StateLayout.from_model(toy_model)
    t, Y, Y1, Y2 = _path(layout, 1, 1.0)
    assert Speed().residual(PathContext(t, Y, Y1, Y2)) is None
