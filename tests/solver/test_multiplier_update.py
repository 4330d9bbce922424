"""The method of multipliers' updates (`solver.lagrangian.AugmentedLagrangian.update`), by hand: the
first-order multiplier update lam <- max(0, lam + rho c/tol), V = max |min(-c/tol, lam/rho)| and Birgin &
Martinez's penalty rule (rho x GAMMA when V did not fall below TAU of its last value)."""
import numpy as np
import pytest

from solver.lagrangian import GAMMA, TAU, AugmentedLagrangian


def bare(lam, rho, V):
    """An AugmentedLagrangian with only the state `update` reads (no problem behind it)."""
    al = object.__new__(AugmentedLagrangian)
    al.lam, al.rho, al.V = [np.asarray(x, float) for x in lam], float(rho), float(V)
    return al


def test_multipliers_follow_the_first_order_update():
    al = bare([[0.0, 2.0, 1.0]], rho=4.0, V=np.inf)
    scaled = [np.array([0.5, -1.0, -0.1])]  # c/tol: broken by half a tolerance, inside, just inside
    v = al.update(scaled)
    assert np.allclose(al.lam[0], [2.0, 0.0, 0.6])  # max(0, lam + rho c/tol)
    # V = max |min(-c/tol, lam/rho)| with the multipliers before the update: 0.5, 0.5, 0.1
    assert v == pytest.approx(0.5) and v == al.V


@pytest.mark.parametrize("previous, worst, grows", [
    (10.0, 6.0, True),    # not halved: rho grows
    (10.0, 4.0, False),   # halved (below TAU of the last V): rho stays
    (0.9, 0.8, True),     # within the tolerances too: the rule is on V's decrease alone
    (0.9, 0.3, False),
])
def test_penalty_grows_when_the_infeasibility_did_not_halve(previous, worst, grows):
    al = bare([[0.0]], rho=2.0, V=previous)
    v = al.update([np.array([worst])])
    assert v == pytest.approx(worst)
    assert (worst > TAU * previous) == grows
    assert al.rho == pytest.approx(2.0 * GAMMA if grows else 2.0)
