"""The objective (solver/objective.py, paper eq. 1 and 7) against exact integrals and finite differences."""
import numpy as np
import pytest

from solver.errors import InputError
from solver.objective import NonFiniteError, Objective
from solver.terms.base import Term, TermEval

from conftest import fd_gradient


class Value(Term):
    """f = Y[:, 0] (exactly integrable on a straight path)."""

    name, needs = "value", (0,)

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        dY = np.zeros_like(Y)
        dY[:, 0] = 1.0
        return TermEval(Y[:, 0].copy(), dY=dY if grad else None)


class Wiggly(Term):
    """f = sum_i sin(Y_i) Y'_i^2 + (Y''_i)^2: reads all three derivatives, nonlinear."""

    name, needs = "wiggly", (0, 1, 2)

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        f = (np.sin(Y) * Y1**2 + Y2**2).sum(axis=1)
        if not grad:
            return TermEval(f)
        return TermEval(f, dY=np.cos(Y) * Y1**2, dY1=2 * np.sin(Y) * Y1, dY2=2 * Y2)


class Zero(Term):
    name, needs = "zero", (0,)

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        return TermEval(np.zeros(len(t)), dY=np.zeros_like(Y) if grad else None)


class Poison(Term):
    name, needs = "poison", (0,)

    def evaluate(self, t, Y, Y1, Y2, grad=True):
        return TermEval(np.full(len(t), np.nan), dY=np.zeros_like(Y) if grad else None)


def test_weighted_integral_of_a_linear_path_is_exact():
    """Midpoint quadrature integrates a linear integrand exactly: E = w (a (t1 - t0) + b (t1^2 - t0^2) / 2)."""
    a, b, t0, t1, w = 0.3, -1.7, 0.5, 2.25, 2.5
    knots = np.array([t0, 1.0, 1.6, t1])
    P = np.stack([a + b * knots, np.zeros(4)], axis=1)  # frames on a line: the natural spline is the line
    obj = Objective([Value()], np.array([w]), t0, t1, rate=200.0)
    ev = obj.evaluate(knots, P)
    exact = a * (t1 - t0) + b * (t1**2 - t0**2) / 2
    assert ev.integrals["value"] == pytest.approx(exact, rel=1e-12)
    assert pytest.approx(w * exact, rel=1e-12) == ev.E


def test_gauss_quadrature_integrates_a_cubic_integrand_exactly():
    """f = Y^3 - Y with Y linear is a cubic in t; two Gauss nodes per segment integrate it exactly."""

    class Cubic(Term):
        name, needs = "cubic", (0,)

        def evaluate(self, t, Y, Y1, Y2, grad=True):
            return TermEval(Y[:, 0] ** 3 - Y[:, 0], dY=(3 * Y**2 - 1) if grad else None)

    a, b, t0, t1 = 0.2, 0.9, 0.0, 1.3
    knots = np.array([t0, 0.4, t1])
    P = (a + b * knots)[:, None]
    obj = Objective([Cubic()], [1.0], t0, t1, quadrature="gauss", points=2)
    def F(t):  # antiderivative
        return (a + b * t) ** 4 / (4 * b) - (a + b * t) ** 2 / (2 * b)

    assert obj.evaluate(knots, P).integrals["cubic"] == pytest.approx(F(t1) - F(t0), rel=1e-13)


@pytest.mark.parametrize("quadrature", ["uniform", "gauss"])
def test_gradient_matches_finite_differences(quadrature):
    rng = np.random.default_rng(3)
    knots = np.array([0.0, 0.3, 0.7, 0.8, 1.2])
    P = rng.normal(size=(5, 3))
    obj = Objective([Wiggly(), Value()], [0.7, 1.3], 0.0, 1.2, rate=300.0, quadrature=quadrature)
    obj.scales = np.array([2.0, 0.5])  # as after renormalization: E = sum w_j I_j / s_j
    G = obj.evaluate(knots, P).grad
    G_fd = fd_gradient(lambda X: obj.evaluate(knots, X, grad=False).E, P)
    np.testing.assert_allclose(G, G_fd, rtol=1e-6, atol=1e-6)


def test_renormalized_terms_start_at_their_weights():
    """Eq. 7: after renormalize on a path, each term contributes its weight there; a term that is zero
    keeps scale 1 (and contributes 0)."""
    rng = np.random.default_rng(4)
    knots = np.array([0.0, 0.5, 1.0, 1.5])
    P = rng.normal(size=(4, 2)) + 3.0  # Value's integral is positive here
    obj = Objective([Wiggly(), Value(), Zero()], [0.25, 4.0, 9.0], 0.0, 1.5, rate=400.0)
    scales = obj.renormalize(knots, P)
    assert scales["zero"] == 1.0
    assert pytest.approx(0.25 + 4.0, rel=1e-12) == obj.evaluate(knots, P, grad=False).E


def test_invalid_weights_and_nonfinite_terms_are_named():
    with pytest.raises(InputError, match="'value'.*weights must be >= 0"):
        Objective([Value()], [-1.0], 0.0, 1.0)
    with pytest.raises(InputError, match="1 objective terms but 2 weights"):
        Objective([Value()], [1.0, 2.0], 0.0, 1.0)
    with pytest.raises(InputError, match="uniform quadrature needs rate="):
        Objective([Value()], [1.0], 0.0, 1.0)
    obj = Objective([Value(), Poison()], [1.0, 1.0], 0.0, 1.0, rate=400.0)
    with pytest.raises(NonFiniteError, match="'poison'") as e:
        obj.evaluate(np.array([0.0, 1.0]), np.zeros((2, 1)))
    assert e.value.term == "poison"


class PointwiseWiggly(Wiggly):
    name, pointwise = "wiggly_pointwise", True


class PointwiseValue(Value):
    name, pointwise = "value_pointwise", True


@pytest.mark.parametrize("quadrature", ["uniform", "gauss"])
def test_blocked_pointwise_terms_give_the_same_bits_and_a_checked_gradient(quadrature, monkeypatch):
    """Pointwise terms on a long path are evaluated on blocks of points (`BLOCK_DOUBLES`), a run of
    them at a time between terms that are not pointwise: E, gradient and integrals are the same bits
    as whole-path evaluation, and the gradient matches finite differences."""
    import solver.objective as objective_module

    rng = np.random.default_rng(5)
    knots = np.linspace(0.0, 1.2, 70)
    P = np.sin(knots[:, None] * [1.0, 2.0, 3.0]) + 0.01 * rng.normal(size=(70, 3))
    terms = [PointwiseWiggly(), PointwiseValue(), Wiggly(), PointwiseValue(), Value()]
    obj = Objective(terms, [0.7, 1.3, 0.2, 0.0, 0.5], 0.0, 1.2, rate=300.0, quadrature=quadrature)
    obj.scales = np.array([2.0, 0.5, 1.5, 1.0, 3.0])
    whole = obj.evaluate(knots, P)
    n = len(obj.basis(knots).t)
    monkeypatch.setattr(objective_module, "BLOCK_DOUBLES", 1)  # the smallest blocks: 64 points
    assert n > 4 * 64 and n % 64
    blocked = obj.evaluate(knots, P)
    assert blocked.E == whole.E and blocked.integrals == whole.integrals
    np.testing.assert_array_equal(blocked.grad, whole.grad)
    G_fd = fd_gradient(lambda X: obj.evaluate(knots, X, grad=False).E, P)
    np.testing.assert_allclose(blocked.grad, G_fd, rtol=1e-6, atol=1e-6)


def test_fused_orientation_objective_matches_the_two_terms():
    """The orientation objective (unit + normalized covariant acceleration of one quaternion, Gauss)
    takes the fused pass (`unit_and_normalized`); it gives the per-term path's E, integrals and
    gradient, with weights, scales and a zero weight."""
    from solver.terms import NormalizedCovariantAcceleration, UnitQuaternion

    slots = np.arange(4).reshape(1, 4)
    rng = np.random.default_rng(3)
    knots = np.cumsum(rng.uniform(0.2, 1.0, 9))
    P = rng.normal(size=(9, 4))
    for weights in ((0.3, 1.0), (0.0, 2.0), (5.0, 0.0)):
        fused = Objective([UnitQuaternion(slots), NormalizedCovariantAcceleration(slots)], weights,
                          knots[0], knots[-1], quadrature="gauss", points=4)
        fused.scales = np.array([0.7, 1.9])
        plain = Objective([UnitQuaternion(slots), NormalizedCovariantAcceleration(slots)], weights,
                          knots[0], knots[-1], quadrature="gauss", points=4)
        plain.scales = fused.scales.copy()
        plain._fused = False
        assert fused._fused
        a, b = fused.evaluate(knots, P), plain.evaluate(knots, P)
        assert abs(a.E - b.E) <= 1e-13 * abs(b.E)
        assert a.integrals == pytest.approx(b.integrals, rel=1e-13)
        np.testing.assert_allclose(a.grad, b.grad, rtol=1e-12, atol=1e-12 * np.abs(b.grad).max())


class Held(Value):
    """A term that keeps something per quadrature point (`Term.fixed_points`)."""

    name, fixed_points = "held", True


def test_the_objective_reads_terms_through_their_declared_interface():
    """`needs` is the union of the terms' (sorted), `blame` names the non-finite term (the gradient of
    a path where only one is NaN), and Gauss quadrature refuses a term with `fixed_points`."""
    obj = Objective([Value(), Wiggly(), Poison()], [1.0, 1.0, 1.0], 0.0, 1.0, rate=20.0)
    assert obj.needs == (0, 1, 2)
    basis = obj.basis(np.array([0.0, 1.0]))
    Y = np.zeros((len(basis.t), 1))
    assert obj.blame(basis, Y, Y, Y) == "poison"
    assert Objective([Value()], [1.0], 0.0, 1.0, quadrature="gauss").needs == (0,)
    with pytest.raises(InputError, match="'held' keeps per-point state"):
        Objective([Held()], [1.0], 0.0, 1.0, quadrature="gauss")


def test_a_term_implements_evaluate_or_evaluate_in():
    """The base class turns either into the other: `evaluate_in` defaults to `evaluate` on the
    context's arrays; `evaluate` defaults to `evaluate_in` on a context of its own with the deferred
    part pulled back; a term with neither says so."""
    from solver.path_context import PathContext

    class ViaContext(Term):
        name, needs = "via_context", (0,)

        def evaluate_in(self, ctx, grad=True):
            return TermEval(2.0 * ctx.Y[:, 0], dY=np.full(ctx.Y.shape, 2.0))

    Y = np.arange(6.0).reshape(3, 2)
    np.testing.assert_array_equal(ViaContext().evaluate(None, Y, None, None).f, 2.0 * Y[:, 0])
    np.testing.assert_array_equal(Value().evaluate_in(PathContext(None, Y)).f, Y[:, 0])

    class Neither(Term):
        name = "neither"

    with pytest.raises(NotImplementedError, match="implements neither evaluate nor evaluate_in"):
        Neither().evaluate(None, Y, None, None)
