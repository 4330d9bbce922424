"""L-BFGS's first step scaled by the curvature along steepest descent (`solver.lagrangian.first_step_scale`,
Nocedal & Wright eq. 7.20), checked on quadratics whose curvature is known in closed form."""
import numpy as np
import pytest

from solver.lagrangian import first_step_scale
from solver.optimize import Status, minimize


class Identity:
    """A preconditioner that leaves the variables as they are (x = z)."""

    @staticmethod
    def apply(z):
        return z


def quadratic(H, b):
    """f(z) = z^T H z / 2 + b^T z with its gradient, as `first_step_scale` and `minimize` call it."""
    def fun(z, need_grad):
        Hz = H @ z
        return float(0.5 * z @ Hz + b @ z), (Hz + b if need_grad else None)
    return fun


@pytest.mark.parametrize("kappa", [4.0, 400.0, 3e7])
def test_scale_is_the_inverse_square_root_of_an_isotropic_curvature(kappa):
    n = 6
    c = first_step_scale(quadratic(kappa * np.eye(n), np.arange(1.0, n + 1)), Identity, n)
    # gamma = s^T y / y^T y = 1 / kappa exactly for a quadratic (y = H s)
    assert c == pytest.approx(1.0 / np.sqrt(kappa), rel=1e-6)


def test_scale_reads_the_curvature_along_the_gradient_only():
    H = np.diag([100.0, 1.0, 1.0])
    b = np.array([1.0, 0.0, 0.0])  # the gradient at 0 lies along the stiff axis
    c = first_step_scale(quadratic(H, b), Identity, 3)
    assert c == pytest.approx(0.1, rel=1e-6)


def test_curvature_below_the_preconditioned_one_leaves_the_variables_alone():
    c = first_step_scale(quadratic(0.25 * np.eye(3), np.ones(3)), Identity, 3)
    assert c == 1.0  # gamma = 4 > 1: the preconditioner's unit curvature is kept


def test_zero_gradient_and_no_variables():
    assert first_step_scale(quadratic(np.eye(2), np.zeros(2)), Identity, 2) == 1.0
    assert first_step_scale(quadratic(np.eye(0), np.zeros(0)), Identity, 0) == 1.0


def test_a_stiff_penalty_is_minimized_once_scaled():
    """|z|^2 / 2 + rho/4 (a.z - 1)^4 at rho = 1e6, a steep penalty of the kind a grown augmented Lagrangian
    holds (nlopt's L-BFGS from 0 unscaled stops with a generic failure: its first step is the gradient's
    length, 1e6). Scaled, it reaches the minimizer z* = t* a, t* the root of t + rho (t - 1)^3 (brentq)."""
    from scipy.optimize import brentq

    n, rho = 8, 1e6
    a = np.ones(n) / np.sqrt(n)

    def fun(z, need_grad):
        r = a @ z - 1.0
        return float(0.5 * z @ z + rho / 4 * r ** 4), (z + rho * r ** 3 * a if need_grad else None)

    c = first_step_scale(fun, Identity, n)
    res = minimize(lambda z, g: (fun(c * z, g)[0], None if not g else c * fun(c * z, g)[1]), np.zeros(n),
                   algorithm="lbfgs", ftol_rel=1e-12)
    t = brentq(lambda t: t + rho * (t - 1.0) ** 3, 0.0, 1.0, xtol=1e-14)
    assert res.status is Status.CONVERGED
    assert np.allclose(c * res.x, t * a, atol=1e-4)
